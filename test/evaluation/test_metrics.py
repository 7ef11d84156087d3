"""The evaluator on cases with known answers (``mrm evaluate`` end to end, with a fake bag
reader: test/cli/test_evaluate.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.worlds import polygon
from multi_robot_mapper.evaluation.metrics import (
    RobotTrack,
    align_se2,
    evaluate,
    pair_errors,
    point_segment_distances,
    sample_segments,
)

T_MAP_WORLD = se2.matrix_from_pose(3.0, -7.0, 2.5)  # the method's map frame, arbitrary
ROOM = polygon([(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)])  # 4 walls of 4 m


def move_poses(T: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Poses (N, 3) expressed in frame b -> frame a with T_a_b."""
    xy = se2.transform_points(T, poses[:, :2])
    theta = se2.wrap_angle(poses[:, 2] + np.arctan2(T[1, 0], T[0, 0]))
    return np.column_stack((xy, theta))


def circle_path(cx: float, cy: float, n: int = 40, radius: float = 0.5) -> np.ndarray:
    """n poses equally spaced on a circle (centroid exactly the centre), heading along it."""
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.column_stack(
        (cx + radius * np.cos(a), cy + radius * np.sin(a), se2.wrap_angle(a + np.pi / 2))
    )


def track(reference: np.ndarray, estimate: np.ndarray) -> RobotTrack:
    return RobotTrack(100.0 + 0.025 * np.arange(len(reference)), reference, estimate)


def wall_points(walls: np.ndarray, step: float = 0.01) -> np.ndarray:
    """Points every ``step`` along each wall, at (k + 1/2) * step, so none sits in a corner."""
    return sample_segments(walls, step, midpoints=True)[0]


# ------------------------------------------------------------------------------ alignment, ATE


def test_trajectory_moved_by_a_known_se2_scores_zero() -> None:
    reference = circle_path(1.0, 2.0, n=60, radius=1.3)
    reference[:, 0] += np.linspace(0, 4, 60)  # not a pure circle: a drifting loop
    estimate = move_poses(T_MAP_WORLD, reference)
    m = evaluate({"robot1": track(reference, estimate)}, np.zeros((0, 4)), np.zeros((0, 2)))
    assert m.ate_rmse_m < 1e-9
    assert m.ate_all_rmse_m < 1e-9
    assert m.robots["robot1"].ate_own_frame_m < 1e-9
    assert m.robots["robot1"].rmse_m < 1e-9
    assert m.pair_success == 1.0 and m.pair_success_strict == 1.0
    assert m.median_translation_error_m < 1e-12 and m.median_rotation_error_rad < 1e-12
    assert (m.robots_merged, m.robots_total) == (1, 1)
    np.testing.assert_allclose(m.T_ref_map, se2.invert(T_MAP_WORLD), atol=1e-12)


@pytest.mark.parametrize("theta", [np.pi - 1e-3, -np.pi / 2, 0.0, 3.0])
def test_planar_alignment_is_a_rotation_never_a_reflection(theta: float) -> None:
    # Collinear positions: a 3-D fit could as well flip them about their own line.
    reference = np.column_stack((np.linspace(0, 5, 20), np.full(20, 1.0), np.zeros(20)))
    T = se2.matrix_from_pose(-2.0, 4.0, theta)
    T_ref_est = align_se2(move_poses(T, reference), reference)
    assert np.linalg.det(T_ref_est[:2, :2]) == pytest.approx(1.0)
    np.testing.assert_allclose(T_ref_est, se2.invert(T), atol=1e-9)


def test_alignment_without_position_spread_uses_headings() -> None:
    reference = np.array([[1.0, 2.0, 0.3]] * 5)  # a robot that never moved
    T = se2.matrix_from_pose(0.5, -1.0, 1.2)
    np.testing.assert_allclose(align_se2(move_poses(T, reference), reference), se2.invert(T))
    one = np.array([[4.0, -3.0, -2.0]])
    np.testing.assert_allclose(align_se2(move_poses(T, one), one), se2.invert(T), atol=1e-12)


# --------------------------------------------------------------------------- merged robots


def three_robots(offset_robot3: float) -> dict[str, RobotTrack]:
    """Three robots around the global centroid; robot3's frame is off by ``offset`` m in x."""
    refs = {
        "robot1": circle_path(0.0, 2.0),
        "robot2": circle_path(0.0, -2.0),
        "robot3": circle_path(3.0, 0.0),
    }
    T_off = se2.matrix_from_pose(offset_robot3, 0.0, 0.0)  # robot3's own frame misplaced
    tracks = {}
    for name, ref in refs.items():
        T = T_MAP_WORLD @ T_off if name == "robot3" else T_MAP_WORLD
        tracks[name] = track(ref, move_poses(T, ref))
    return tracks


def test_one_robot_offset_by_1m_is_unmerged_and_the_others_stay_merged() -> None:
    m = evaluate(three_robots(1.0), np.zeros((0, 4)), np.zeros((0, 2)))
    assert (m.robots_merged, m.robots_total) == (2, 3)
    assert m.merged_robots == ["robot1", "robot2"]
    assert m.ate_rmse_m < 1e-9
    assert m.robots["robot1"].rmse_m < 1e-9 and m.robots["robot2"].rmse_m < 1e-9
    assert m.robots["robot3"].rmse_m == pytest.approx(1.0, abs=1e-9)
    assert not m.robots["robot3"].merged
    assert m.robots["robot3"].ate_own_frame_m < 1e-9  # fine in its own frame
    # One fit of all scans: robot3's centroid lies along its offset from the global centroid,
    # so the best rotation is exact and only a shift of f = 1/3 m remains:
    # RMSE = sqrt(f (1 - f)) * 1 m.
    assert m.ate_all_rmse_m == pytest.approx(math.sqrt(2.0) / 3.0, abs=1e-9)
    assert m.pair_success == 1.0  # a misplaced frame moves no scan relative to its neighbour
    np.testing.assert_allclose(m.T_ref_map, se2.invert(T_MAP_WORLD), atol=1e-9)


def test_all_three_merged_without_the_offset() -> None:
    m = evaluate(three_robots(0.0), np.zeros((0, 4)), np.zeros((0, 2)))
    assert m.robots_merged == 3
    assert m.ate_rmse_m < 1e-9 and m.ate_all_rmse_m < 1e-9


def test_a_robot_reported_unmerged_is_not_counted_even_if_aligned() -> None:
    frames = {"robot1": (0.0, 0.0, 0.0), "robot2": None, "robot3": (1.0, 0.0, 0.0)}
    m = evaluate(three_robots(1.0), np.zeros((0, 4)), np.zeros((0, 2)), frames)
    assert m.robots_merged == 1
    assert m.merged_robots == ["robot1"]
    assert m.robots["robot2"].reported_unmerged and not m.robots["robot2"].merged
    assert m.robots["robot2"].rmse_m < 1e-9  # it does align; it just was not claimed merged


# ---------------------------------------------------------------------------------- pairs


def test_unposed_scans_fail_their_pairs_and_are_counted() -> None:
    reference = circle_path(0.0, 0.0, n=10)
    estimate = reference.copy()
    estimate[[3, 7]] = np.nan
    m = evaluate({"robot1": track(reference, estimate)}, np.zeros((0, 4)), np.zeros((0, 2)))
    # 9 pairs; (2,3), (3,4), (6,7), (7,8) touch an unposed scan.
    assert m.robots["robot1"].pairs == 9
    assert m.pair_success == pytest.approx(5 / 9)
    assert m.pair_success_strict == pytest.approx(5 / 9)
    assert (m.scans_total, m.scans_unposed) == (10, 2)
    assert m.robots["robot1"].scans_unposed == 2
    assert m.median_translation_error_m < 1e-12  # over the 5 posed pairs
    assert m.ate_rmse_m < 1e-12


def test_pair_thresholds_loose_and_strict() -> None:
    reference = np.column_stack((0.5 * np.arange(12.0), np.zeros(12), np.zeros(12)))
    estimate = reference.copy()
    estimate[4:, 0] += 0.2  # pair (3,4): 0.2 m off -> loose ok, strict fails
    estimate[8:, 2] += math.radians(3.0)  # pair (7,8): 3 deg off -> loose ok, strict fails
    estimate[10:, 1] += 0.5  # pair (9,10): 0.5 m off -> fails both
    both, translation, rotation = pair_errors(track(reference, estimate))
    assert both.all()
    assert translation[3] == pytest.approx(0.2)
    assert rotation[7] == pytest.approx(math.radians(3.0))
    m = evaluate({"r": track(reference, estimate)}, np.zeros((0, 4)), np.zeros((0, 2)))
    assert m.pair_success == pytest.approx(10 / 11)
    assert m.pair_success_strict == pytest.approx(8 / 11)


def test_pair_errors_equal_evo_rpe() -> None:
    from evo.core import metrics as evo_metrics
    from evo.core.trajectory import PoseTrajectory3D

    rng = np.random.default_rng(7)
    reference = np.cumsum(rng.normal(0, 0.2, (30, 3)), axis=0)
    estimate = reference + rng.normal(0, 0.05, (30, 3))

    def to_evo(poses: np.ndarray) -> PoseTrajectory3D:
        half = poses[:, 2] / 2
        quat_wxyz = np.column_stack((np.cos(half), 0 * half, 0 * half, np.sin(half)))
        xyz = np.column_stack((poses[:, :2], np.zeros(len(poses))))
        return PoseTrajectory3D(xyz, quat_wxyz, np.arange(len(poses), dtype=float))

    _, translation, rotation = pair_errors(track(reference, estimate))
    for relation, ours in (
        (evo_metrics.PoseRelation.translation_part, translation),
        (evo_metrics.PoseRelation.rotation_angle_rad, rotation),
    ):
        rpe = evo_metrics.RPE(relation, delta=1, delta_unit=evo_metrics.Unit.frames)
        rpe.process_data((to_evo(reference), to_evo(estimate)))
        np.testing.assert_allclose(ours, rpe.error, atol=1e-9)


# ------------------------------------------------------------------------------------- map


def room_track() -> dict[str, RobotTrack]:
    reference = circle_path(2.0, 2.0, radius=1.0)
    return {"robot1": track(reference, move_poses(T_MAP_WORLD, reference))}


def test_the_right_map_scores_perfectly() -> None:
    points = wall_points(ROOM)
    m = evaluate(room_track(), se2.transform_segments(T_MAP_WORLD, ROOM), points)
    assert m.map_error_m < 1e-9
    assert m.map_coverage == 1.0
    assert m.map_precision == 1.0
    assert m.reference_points == 1600


def test_a_map_missing_a_wall_loses_coverage() -> None:
    points = wall_points(ROOM)  # 400 points per wall at s = 0.005, 0.015, ... 3.995 m
    m = evaluate(room_track(), se2.transform_segments(T_MAP_WORLD, ROOM[1:]), points)
    # The missing wall's points are covered only within 0.10 m of the two perpendicular walls
    # (10 at each end): 380 of 1600 points lose coverage.
    assert m.map_coverage == pytest.approx(1.0 - 380 / 1600)
    s = 0.005 + 0.01 * np.arange(400)
    assert m.map_error_m == pytest.approx(np.minimum(s, 4.0 - s).sum() / 1600, abs=1e-9)
    assert m.map_precision == 1.0  # what is there is right


def test_a_spurious_wall_loses_precision() -> None:
    points = wall_points(ROOM)
    spurious = np.array([[10.0, 0.0, 12.0, 0.0]])  # 2 m of wall nobody saw
    map_world = np.vstack((ROOM, spurious))
    m = evaluate(room_track(), se2.transform_segments(T_MAP_WORLD, map_world), points)
    assert m.map_precision == pytest.approx(16.0 / 18.0, abs=1e-12)
    assert m.map_coverage == 1.0
    assert m.map_error_m < 1e-9


def test_point_segment_distances_are_exact_on_a_sparse_map() -> None:
    rng = np.random.default_rng(11)
    segments = rng.uniform(-5, 5, (60, 4))
    segments[:5, 2:] = segments[:5, :2]  # degenerate (point) segments too
    points = rng.uniform(-6, 6, (3000, 2))
    brute = brute_distances(points, segments)
    np.testing.assert_allclose(point_segment_distances(points, segments), brute, atol=1e-12)


def brute_distances(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    a, b = segments[None, :, :2], segments[None, :, 2:]
    d = b - a
    t = np.clip(
        np.sum((points[:, None] - a) * d, axis=2) / np.maximum(np.sum(d * d, axis=2), 1e-300),
        0,
        1,
    )
    return np.asarray(np.linalg.norm(points[:, None] - a - t[..., None] * d, axis=2).min(axis=1))


def test_point_segment_distances_stay_within_half_a_step_where_segments_overlap() -> None:
    rng = np.random.default_rng(5)
    wall = np.array([0.0, 0.0, 3.0, 0.0])
    segments = wall + rng.normal(0, 0.003, (300, 4))  # 300 copies of one wall, as a raw map
    points = np.column_stack((rng.uniform(-0.5, 3.5, 2000), rng.uniform(-0.3, 0.3, 2000)))
    got = point_segment_distances(points, segments)
    brute = brute_distances(points, segments)
    assert np.all(got >= brute - 1e-12)
    assert np.all(got <= brute + 0.01)  # step / 2


def test_segment_samples_are_dense_enough() -> None:
    segments = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.05]])
    points, owner, _ = sample_segments(segments, 0.02)
    assert np.count_nonzero(owner == 0) == 51 and np.count_nonzero(owner == 1) == 4
    gaps = np.linalg.norm(np.diff(points[owner == 0], axis=0), axis=1)
    assert gaps.max() <= 0.02 + 1e-12 and points[owner == 0][-1, 0] == 1.0
    mids, _, weight = sample_segments(segments, 0.02, midpoints=True)
    assert weight.sum() == pytest.approx(1.05)
    assert len(mids) == 53


def test_metrics_to_dict_is_json() -> None:
    tracks = three_robots(1.0)
    tracks["robot3"].estimate[:] = np.nan  # a robot with nothing posed: NaN figures -> null
    m = evaluate(tracks, np.zeros((0, 4)), wall_points(ROOM))
    data = json.loads(json.dumps(m.to_dict(), allow_nan=False))
    assert data["robots"]["robot3"]["rmse_m"] is None
    assert data["robots"]["robot3"]["pair_success"] == 0.0
    assert data["map_error_m"] is None and data["map_coverage"] == 0.0
    assert data["robots_merged"] == 2 and data["scans_unposed"] == 40


# ---------------------------------------------------------------------- mrm evaluate (CLI)


def test_aligned_rmse_is_zero_for_a_moved_copy_and_the_offset_of_a_shifted_point() -> None:
    from multi_robot_mapper.core import se2 as _se2
    from multi_robot_mapper.evaluation.metrics import aligned_rmse

    reference = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 3.0, 1.0], [0.0, 3.0, 2.0]])
    moved = _se2.compose_each(np.tile([2.0, -1.0, 0.7], (4, 1)), reference)
    assert aligned_rmse(moved, reference) < 1e-9
    # Two of four points 0.1 m off, in opposite directions: no rigid fit takes that away, and
    # the fit is never worse than none (RMS 0.1 / sqrt(2) as they stand).
    shifted = reference.copy()
    shifted[0, 0] += 0.1
    shifted[2, 0] -= 0.1
    assert 0.01 < aligned_rmse(shifted, reference) <= 0.1 / np.sqrt(2.0) + 1e-12
