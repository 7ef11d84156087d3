"""FFS bodies with known answers: segments resampled at the spacing, regions of interest at the
corners, walls that face their sensor."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core.merging.ffs import (
    FfsConfig,
    facing_sensor,
    make_bodies,
    resample,
)
from multi_robot_mapper.core.merging.ffs.bodies import corner_points, placed
from multi_robot_mapper.core.merging.ffs.simulation import force_field


def test_segments_are_resampled_at_the_spacing_with_their_direction() -> None:
    points, directions, owner = resample(np.array([[0.0, 0.0, 1.0, 0.0], [0, 0, 0, 0.25]]), 0.1)
    assert np.bincount(owner).tolist() == [11, 4]  # ends included; 0.25 m in 3 equal steps
    assert np.allclose(points[:11, 0], np.linspace(0.0, 1.0, 11)) and np.allclose(points[:11, 1], 0)
    assert np.allclose(np.diff(points[11:, 1]), 0.25 / 3)
    assert np.allclose(directions[:11], [1.0, 0.0]) and np.allclose(directions[11:], [0.0, 1.0])


def test_regions_of_interest_are_the_room_corners() -> None:
    square = np.array([[0, 0, 2, 0], [2, 0, 2, 2], [2, 2, 0, 2], [0, 2, 0, 0]], dtype=float)
    points, _, owner = resample(square, 0.05)
    inside = corner_points(square, points, owner, 0.06)
    corners = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=float)
    near = np.hypot(*(points[:, None] - corners[None]).transpose(2, 0, 1)).min(axis=1) <= 0.06
    assert np.array_equal(inside, near) and inside.sum() >= 8
    # Two walls at 45 deg make no corner (FFS 3.4: 80-100 deg only).
    slanted = np.array([[0, 0, 2, 0], [0, 0, 1.4, 1.4]], dtype=float)
    p, _, o = resample(slanted, 0.05)
    assert not corner_points(slanted, p, o, 0.06).any()


def test_walls_face_their_sensor_and_back_to_back_faces_do_not_attract() -> None:
    # A wall 2 m ahead, given either way round, runs with the sensor on its left.
    wall = np.array([[2.0, 1.0, 2.0, -1.0], [2.0, -1.0, 2.0, 1.0]])
    assert np.allclose(facing_sensor(wall), [[2.0, -1.0, 2.0, 1.0]] * 2)
    # The two faces of a 0.1 m thick wall, seen from the rooms on either side: no force.
    config = FfsConfig()
    faces = [facing_sensor(np.array([[-1.0, 0.0, 1.0, 0.0]]) - [0, y, 0, y]) for y in (1, -1)]
    bodies = make_bodies(faces, 0.1, 0.0, 1.0)
    poses = np.array([[0.0, 1.0, 0.0], [0.0, -1.1, 0.0]])  # sensors 1 m either side
    points, directions = placed(bodies, poses)
    field = force_field(points, directions, bodies, poses[:, :2], 0.1, config.cutoff)
    assert field.pairs > 0 and np.allclose(field.force, 0.0) and field.potential == 0.0
