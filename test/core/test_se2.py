"""SE(2) helpers: known answers and round trips."""

from __future__ import annotations

import warnings

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import quaternion_from_yaw, yaw_from_quaternion

coord = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-10, 10, allow_nan=False)


def test_quarter_turn_maps_x_axis_to_y_axis() -> None:
    T = se2.matrix_from_pose(1.0, 2.0, np.pi / 2)
    np.testing.assert_allclose(
        se2.transform_points(T, np.array([[1.0, 0.0]])), [[1.0, 3.0]], atol=1e-12
    )


@given(coord, coord, angle)
def test_invert_composes_to_identity_and_pose_round_trips(x: float, y: float, th: float) -> None:
    T = se2.matrix_from_pose(x, y, th)
    np.testing.assert_allclose(T @ se2.invert(T), np.eye(3), atol=1e-9)
    x2, y2, th2 = se2.pose_from_matrix(T)
    np.testing.assert_allclose([x2, y2], [x, y], atol=1e-9)
    assert abs(se2.wrap_angle(th2 - th)) < 1e-9


def test_transform_segments_moves_both_ends() -> None:
    T = se2.matrix_from_pose(0.0, 1.0, 0.0)
    np.testing.assert_allclose(
        se2.transform_segments(T, np.array([[0.0, 0, 1, 0]])), [[0, 1, 1, 1]]
    )


def test_matrices_from_poses_are_matrix_from_pose_each() -> None:
    poses = np.array([[1.0, -2.0, 0.3], [0.0, 0.0, -3.0], [5.5, 2.0, 3.1]])
    stacked = se2.matrices_from_poses(poses)
    for pose, T in zip(poses, stacked, strict=True):
        np.testing.assert_allclose(T, se2.matrix_from_pose(*pose), atol=1e-12)
    assert se2.matrices_from_poses(np.zeros((0, 3))).shape == (0, 3, 3)


@given(st.lists(st.tuples(coord, coord, angle, coord, coord, angle), min_size=1, max_size=8))
def test_between_each_is_between_row_by_row(pairs: list[tuple[float, ...]]) -> None:
    rows = np.array(pairs)
    got = se2.between_each(rows[:, :3], rows[:, 3:])
    for row, (x, y, th) in zip(rows, got, strict=True):
        want = se2.between(row[:3], row[3:])
        np.testing.assert_allclose([x, y], want[:2], atol=1e-9)
        assert abs(se2.wrap_angle(th - want[2])) < 1e-9


def test_rigid_fit_recovers_the_motion_between_two_frames() -> None:
    T_to_from = se2.matrix_from_pose(3.0, -1.0, 2.5)
    poses = np.array([[0.0, 0.0, 0.1], [2.0, 1.0, 0.5], [4.0, -3.0, -1.0], [1.0, 5.0, 3.0]])
    moved = np.array([se2.pose_from_matrix(T_to_from @ se2.matrix_from_pose(*p)) for p in poses])
    np.testing.assert_allclose(se2.rigid_fit(poses, moved), T_to_from, atol=1e-9)
    # One pose (or all at one point): exactly onto it, heading included.
    np.testing.assert_allclose(se2.rigid_fit(poses[:1], moved[:1]), T_to_from, atol=1e-9)


@given(
    yaw=st.floats(-np.pi + 1e-6, np.pi - 1e-6),
    scale=st.floats(1e-300, 1e300),
)
def test_yaw_of_a_quaternion_does_not_depend_on_its_scale(yaw: float, scale: float) -> None:
    # A sender's quaternion need not be unit (1e300 components reach the merger's boundary,
    # which refuses them only after reading the yaw): the yaw is the same, with no overflow.
    x, y, z, w = quaternion_from_yaw(yaw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = float(yaw_from_quaternion(x * scale, y * scale, z * scale, w * scale))
    assert abs(se2.wrap_angle(found - yaw)) < 1e-9


@given(
    x=st.floats(-10.0, 10.0),
    y=st.floats(-10.0, 10.0),
    theta=st.floats(-np.pi, np.pi),
)
def test_fit_points_recovers_the_motion_of_a_point_set(x: float, y: float, theta: float) -> None:
    points = np.array([[0.0, 0.0], [2.0, 0.5], [-1.0, 3.0], [4.0, -2.0]])
    T_to_from = se2.matrix_from_pose(x, y, theta)
    moved = se2.transform_points(T_to_from, points)
    np.testing.assert_allclose(se2.fit_points(points, moved), T_to_from, atol=1e-9)
