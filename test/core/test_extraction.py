"""Scan points to segments: synthetic rooms whose true walls and corners are known exactly."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_segments
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.geometry import point_segment_distance
from multi_robot_mapper.core.simulation import raycast
from multi_robot_mapper.core.worlds import polygon

ROOM = polygon([(-2.0, -1.5), (3.0, -1.5), (3.0, 2.5), (-2.0, 2.5)])
CORNERS = ROOM[:, :2]
DEFAULT = ExtractionConfig()
FOV_270 = np.radians(270.0)


def room_scan(pose=(-1.0, 0.4, 0.05), beams=1081, fov=FOV_270, noise=0.0, seed=0, walls=ROOM):
    angles = -fov / 2 + fov / (beams - 1) * np.arange(beams)
    r = raycast(walls, pose, angles, 30.0)
    r = r + np.random.default_rng(seed).normal(0.0, noise, r.shape)
    ok = np.isfinite(r)
    pts = np.column_stack((r * np.cos(angles), r * np.sin(angles)))[ok]
    return pts, se2.matrix_from_pose(*pose)


def line_distance(point: np.ndarray, wall: np.ndarray) -> float:
    a, b = wall[:2], wall[2:]
    d = (b - a) / np.linalg.norm(b - a)
    v = point - a
    return float(abs(v[0] * d[1] - v[1] * d[0]))


def max_covered_distance(result) -> float:
    worst = 0.0
    for (first, last), seg in zip(result.point_span, result.segments, strict=True):
        q = result.points[first : last + 1]
        d = point_segment_distance(q[:, 0], q[:, 1], *(np.full(len(q), v) for v in seg))
        worst = max(worst, float(d.max()))
    return worst


def test_noise_free_room_gives_one_segment_per_visible_wall_with_exact_corners() -> None:
    points, T_world_laser = room_scan()
    result = extract_segments(points, DEFAULT)
    # 270 deg from inside: the wall behind is seen in two pieces, so 5 segments in one chain.
    assert len(result) == 5
    np.testing.assert_array_equal(result.joined_to_next, [True, True, True, True, False])
    world = se2.transform_segments(T_world_laser, result.segments)
    # The corner scan point is fitted by both of its segments, which tilts each line by well
    # under a millimetre at this beam spacing (0.25 deg).
    for seg in world:
        assert min(max(line_distance(seg[:2], w), line_distance(seg[2:], w)) for w in ROOM) < 1e-3
    shared = world[:-1, 2:]
    for corner in shared:
        assert np.min(np.hypot(*(CORNERS - corner).T)) < 2e-3
    assert result.dropped_points == 0


def test_segments_run_counter_clockwise_in_scan_order() -> None:
    points, _ = room_scan()
    result = extract_segments(points, DEFAULT)
    start_angles = np.arctan2(result.segments[:, 1], result.segments[:, 0])
    assert np.all(np.diff(np.unwrap(start_angles)) > 0)


def test_a_gap_wider_than_tau_starts_a_new_cluster_and_tiny_clusters_are_dropped() -> None:
    wall_a = np.column_stack((np.linspace(0, 1, 21), np.full(21, 2.0)))
    wall_b = np.column_stack((np.linspace(1.5, 2.5, 21), np.full(21, 2.0)))
    speck = np.array([[3.0, 2.0], [3.01, 2.0], [3.02, 2.0]])
    lone = np.array([[4.0, 2.0]])
    result = extract_segments(np.vstack((wall_a, wall_b, speck, lone)), DEFAULT)
    assert len(result) == 3  # the default keeps every cluster that can make a segment
    assert not result.joined_to_next.any()
    assert result.dropped_points == 1
    np.testing.assert_allclose(result.segments[:2], [[0, 2, 1, 2], [1.5, 2, 2.5, 2]], atol=1e-12)
    stricter = extract_segments(
        np.vstack((wall_a, wall_b, speck, lone)), ExtractionConfig(min_cluster_points=4)
    )
    assert len(stricter) == 2 and stricter.dropped_points == 4


def test_merge_keeps_a_noisy_straight_wall_in_one_segment() -> None:
    rng = np.random.default_rng(3)
    x = np.linspace(-3, 3, 600)
    points = np.column_stack((x, 2.0 + rng.normal(0, 0.005, x.size)))
    result = extract_segments(points, DEFAULT)
    assert len(result) == 1
    assert abs(result.segments[0, 1] - 2.0) < 0.005 and abs(result.segments[0, 3] - 2.0) < 0.005


def test_corner_is_kept_under_noise() -> None:
    points, T = room_scan(noise=0.005, seed=4)
    result = extract_segments(points, DEFAULT)
    world = se2.transform_segments(T, result.segments)
    corners = world[:-1, 2:][result.joined_to_next[:-1]]
    for true_corner in CORNERS:
        assert np.min(np.hypot(*(corners - true_corner).T)) < 0.02


def test_dce_simplifier_finds_the_same_walls() -> None:
    points, T = room_scan(noise=0.002, seed=5)
    result = extract_segments(points, ExtractionConfig(simplifier="dce", dce_threshold=0.01))
    world = se2.transform_segments(T, result.segments)
    long = world[np.hypot(world[:, 2] - world[:, 0], world[:, 3] - world[:, 1]) > 0.5]
    assert 5 <= len(long) <= 7
    for seg in long:
        assert min(max(line_distance(seg[:2], w), line_distance(seg[2:], w)) for w in ROOM) < 0.02


def test_empty_and_all_tiny_inputs_give_no_segments() -> None:
    assert len(extract_segments(np.zeros((0, 2)), DEFAULT)) == 0
    tiny = extract_segments(np.array([[1.0, 0.0], [5.0, 0.0]]), DEFAULT)
    assert len(tiny) == 0 and tiny.dropped_points == 2


def test_points_too_far_for_float_precision_still_end_the_refit() -> None:
    # A corrupt range puts a cluster 4e11 m out, where a double resolves about 0.1 mm and
    # rounding alone leaves points off their fitted line: the refit used to split the same
    # two-point segment for ever (found by test_fuzz.py).
    far = np.array(
        [
            [4.2661671935988483e11, 9.9187375346118933e-03],
            [4.2661671936002716e11, -8.4569439816774436e-02],
            [4.2661671936007391e11, -3.3866818081813119e-02],
            [4.2661671936013739e11, -2.6238155437957475e-02],
            [4.2661671936026160e11, -6.0291812138139042e-02],
            [4.2661671936032294e11, -2.6060714524581835e-03],
        ]
    )
    room = np.array([[0.0, 1.0], [0.05, 1.05], [0.1, 1.0]])
    segments = extract_segments(np.vstack((far, room)), ExtractionConfig()).segments
    assert np.isfinite(segments).all()
    near = segments[np.abs(segments).max(axis=1) < 10.0]
    assert len(near) == 2  # the room's corner, fitted as usual


def test_duplicate_points_do_not_break_the_fit() -> None:
    points = np.repeat(np.array([[1.0, 1.0], [1.0, 1.1], [1.0, 1.2]]), 3, axis=0)
    result = extract_segments(points, DEFAULT)
    assert np.all(np.isfinite(result.segments))


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-0.8, 1.8),
    y=st.floats(-0.8, 1.8),
    th=st.floats(-np.pi, np.pi),
    noise=st.floats(0.0, 0.01),
    seed=st.integers(0, 2**16),
)
def test_every_covered_point_is_within_kappa_plus_1cm(x, y, th, noise, seed) -> None:
    points, _ = room_scan(pose=(x, y, th), noise=noise, seed=seed)
    result = extract_segments(points, DEFAULT)
    assert max_covered_distance(result) <= DEFAULT.split_tolerance + 0.01


@settings(max_examples=30, deadline=None)
@given(
    tx=st.floats(-20, 20),
    ty=st.floats(-20, 20),
    th=st.floats(-np.pi, np.pi),
    seed=st.integers(0, 2**16),
)
def test_extraction_commutes_with_rigid_motion(tx, ty, th, seed) -> None:
    points, _ = room_scan(noise=0.004, seed=seed)
    T = se2.matrix_from_pose(tx, ty, th)
    moved = extract_segments(se2.transform_points(T, points), DEFAULT)
    base = extract_segments(points, DEFAULT)
    assert len(moved) == len(base)
    np.testing.assert_allclose(moved.segments, se2.transform_segments(T, base.segments), atol=1e-6)


@pytest.mark.parametrize("simplifier", ["split", "dce"])
def test_point_spans_tile_each_cluster(simplifier: str) -> None:
    points, _ = room_scan(noise=0.003, seed=9)
    result = extract_segments(points, ExtractionConfig(simplifier=simplifier))
    span = result.point_span
    assert np.all(span[:, 1] > span[:, 0])
    joined = result.joined_to_next[:-1]
    gap = span[1:, 0][joined] - span[:-1, 1][joined]
    assert np.all((gap == 0) | (gap == 1))
