"""Wolter's shape-based matching (core/matching/shape.py): DCE, tangent-space similarity, the
order-preserving correspondence, and alignment with no pose information, on geometry with a
known answer."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching import shape as shape_matching
from multi_robot_mapper.core.matching.shape import (
    Shape,
    correspond,
    discrete_curve_evolution,
    match_scans,
    match_shapes,
    relevance,
    shape_of_points,
    similarity,
)
from multi_robot_mapper.core.matching.shape_config import ShapeConfig
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.core.worlds import WORLDS

CONFIG = ShapeConfig()


def _line(a: tuple[float, float], b: tuple[float, float], step: float = 0.05) -> np.ndarray:
    n = int(np.ceil(np.hypot(b[0] - a[0], b[1] - a[1]) / step))
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    return np.asarray(a) + t * (np.asarray(b) - np.asarray(a))


def _chain(*corners: tuple[float, float]) -> np.ndarray:
    """Points every 5 cm along the polyline through ``corners`` (no point twice)."""
    parts = [_line(a, b)[:-1] for a, b in itertools.pairwise(corners)]
    return np.vstack([*parts, np.asarray(corners[-1])[None, :]])


def _shape(*polylines: np.ndarray) -> Shape:
    """A shape whose polylines are exactly these vertex lists (no grouping, no DCE)."""
    sizes = np.array([len(p) for p in polylines])
    start = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    return Shape(np.vstack(polylines), start.astype(np.int64), (start + sizes - 1).astype(np.int64))


# A scan-like shape: polylines in counter-clockwise order around the origin, with corners.
ROOM_POLYLINES = (
    np.array([[3.0, -2.0], [3.0, 1.0], [2.0, 1.0], [2.0, 2.0]]),  # a wall with a recess
    np.array([[1.0, 3.0], [-1.5, 3.0], [-1.5, 1.5]]),  # a corner
    np.array([[-3.0, 0.5], [-3.0, -1.0], [-2.0, -1.0], [-2.0, -2.5]]),  # a step
    np.array([[-0.5, -3.0], [1.5, -3.0], [1.5, -2.5]]),  # a short corner
)


def test_relevance_is_the_detour_through_a_vertex() -> None:
    # Wolter Eq. 1: d(u,v) + d(v,w) - d(u,w); 0 on a straight line.
    points = np.array([[0.0, 0.0], [3.0, 4.0], [6.0, 0.0], [9.0, 0.0]])
    assert relevance(points) == pytest.approx([5.0 + 5.0 - 6.0, 5.0 + 3.0 - np.hypot(6.0, 4.0)])
    assert relevance(_line((0, 0), (2, 1))) == pytest.approx(0.0, abs=1e-12)


def test_dce_keeps_the_corners_and_ends_and_drops_the_noise() -> None:
    rng = np.random.default_rng(1)
    l_shape = _chain((0.0, 0.0), (2.0, 0.0), (2.0, 1.5))
    noisy = l_shape + rng.normal(0.0, 0.005, l_shape.shape)
    straight = _line((5.0, 0.0), (5.0, 3.0))
    points = np.vstack((noisy, straight))
    first = np.array([0, len(noisy)])
    last = np.array([len(noisy) - 1, len(points) - 1])
    kept = np.flatnonzero(discrete_curve_evolution(points, first, last, 0.05))
    corner = int(np.argmin(np.hypot(*(noisy - [2.0, 0.0]).T)))
    assert kept.tolist() == [0, corner, len(noisy) - 1, len(noisy), len(points) - 1]
    # Threshold 0: nothing is removed but exact collinear points (relevance 0 is not below 0).
    assert discrete_curve_evolution(points, first, last, 0.0).sum() == len(points)


def test_scan_points_are_grouped_at_gaps_and_simplified() -> None:
    wall = _chain((1.0, -1.0), (1.0, 1.0), (0.0, 1.0))
    post = _line((-1.0, 0.5), (-1.0, 0.6))
    lonely = np.array([[-2.0, -2.0]])  # one return: no shape
    shape = shape_of_points(np.vstack((wall, post, lonely)), CONFIG)
    assert len(shape) == 2
    np.testing.assert_allclose(shape.polyline(0), [[1.0, -1.0], [1.0, 1.0], [0.0, 1.0]])
    np.testing.assert_allclose(shape.polyline(1), [[-1.0, 0.5], [-1.0, 0.6]])


def test_similarity_ignores_where_a_polyline_is_and_how_it_is_turned() -> None:
    # Eq. 2-3: a polyline and a moved copy are identical (0); a straight wall of the same
    # length differs from an L by the variance of a quarter turn over half the length.
    l_shape = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    moved = se2.transform_points(se2.matrix_from_pose(3.0, -1.0, 2.0), l_shape)
    straight = np.array([[0.0, 0.0], [2.0, 0.0]])
    longer = np.array([[0.0, 0.0], [3.0, 0.0]])
    big_l = np.array([[0.0, 0.0], [1.5, 0.0], [1.5, 1.5]])
    singles = dataclasses.replace(CONFIG, max_group=1)
    groups_a = shape_matching._groups(_shape(l_shape), shape_matching.grouping(singles))
    groups_b = shape_matching._groups(
        _shape(moved, straight, longer, big_l), shape_matching.grouping(singles)
    )
    s = similarity(groups_a, groups_b)[0]
    assert s[0] == pytest.approx(0.0, abs=1e-12)
    assert s[1] == pytest.approx((np.pi / 4) ** 2)  # T steps 0 -> pi/2 halfway: variance
    # Straight lines are alike in tangent space whatever their direction (lengths 2 and 3
    # differ, but the variance is 0); a straight wall (2 m) against a larger L (3 m): the
    # L's variance times 1 + (2 - 3)^2.
    straight_groups = shape_matching._groups(_shape(straight), shape_matching.grouping(singles))
    s = similarity(straight_groups, groups_b)[0]
    assert s[2] == pytest.approx(0.0, abs=1e-12)
    assert s[3] == pytest.approx(2.0 * (np.pi / 4) ** 2)


def test_correspondence_keeps_the_order_and_groups_a_split_polyline() -> None:
    # The perceived shape sees the first room polyline split in two (a person in front of
    # its middle) and misses the third: 1-to-many for the first, a skip for the third.
    first = ROOM_POLYLINES[0]
    split = (
        np.array([[3.0, -2.0], [3.0, 0.0]]),
        np.array([[3.0, 0.2], [3.0, 1.0], [2.0, 1.0], [2.0, 2.0]]),
    )
    perceived = _shape(*split, ROOM_POLYLINES[1], ROOM_POLYLINES[3])
    reference = _shape(first, *ROOM_POLYLINES[1:])
    groups_1 = shape_matching._groups(reference, shape_matching.grouping(CONFIG))
    groups_2 = shape_matching._groups(perceived, shape_matching.grouping(CONFIG))
    theta, translation = shape_matching.induced_alignments(groups_1, groups_2)
    scale = (CONFIG.alignment_distance, CONFIG.alignment_angle)
    deviation = shape_matching._deviation(theta, translation, groups_2, (0.0, 0.0, 0.0), scale)
    skips = groups_1.penalty[:, None] + groups_2.penalty[None, :]
    cost = similarity(groups_1, groups_2) + skips * np.minimum(deviation, 1.0)
    _, pairs = correspond(cost, groups_1, groups_2)
    matched = [
        (
            (int(groups_1.first[a]), int(groups_1.count[a])),
            (int(groups_2.first[b]), int(groups_2.count[b])),
        )
        for a, b in pairs
    ]
    assert matched == [((0, 1), (0, 2)), ((1, 1), (2, 1)), ((3, 1), (3, 1))]


@settings(max_examples=25, deadline=None)
@given(
    x=st.floats(-1.5, 1.5),
    y=st.floats(-1.5, 1.5),
    theta=st.floats(-np.pi / 3, np.pi / 3),
)
def test_a_rigidly_moved_copy_is_aligned_exactly(x: float, y: float, theta: float) -> None:
    # The perceived shape is the reference seen from (x, y, theta): matching recovers that
    # motion with no guess, whatever it is.
    reference = _shape(*ROOM_POLYLINES)
    T_1_2 = se2.matrix_from_pose(x, y, theta)
    perceived = _shape(*(se2.transform_points(se2.invert(T_1_2), p) for p in ROOM_POLYLINES))
    found = match_shapes(reference, perceived, CONFIG)
    assert found.valid and len(found.correspondences) == len(ROOM_POLYLINES)
    np.testing.assert_allclose(found.T_1_2, (x, y, theta), atol=1e-6)
    assert found.rms < 1e-6


def test_simulated_office_scans_are_matched_with_no_guess() -> None:
    # Two noisy scans of the built-in office, up to 0.5 m and 17 deg apart, matched from
    # their shapes alone; the office's scans have corners, so nearly all must be right
    # (0.30 m / 5 deg) and most within 0.10 m / 2 deg.
    walls = WORLDS["office"]()
    laser = LaserModel(beams=361, range_noise=0.01)
    rng = np.random.default_rng(0)
    here = (2.0, 2.0, 0.3)
    right = close = 0
    trials = 20
    for _ in range(trials):
        motion = (rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3))
        there = se2.compose(here, motion)
        found = match_scans(
            simulate_scan(walls, here, laser, rng), simulate_scan(walls, there, laser, rng)
        )
        dx, dy, dtheta = se2.between(motion, found.T_1_2)
        right += np.hypot(dx, dy) < 0.30 and abs(dtheta) < np.radians(5)
        close += np.hypot(dx, dy) < 0.10 and abs(dtheta) < np.radians(2)
    assert right >= trials - 2 and close >= trials // 2


def test_nothing_to_match_gives_an_invalid_identity() -> None:
    empty = Shape(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    found = match_shapes(empty, _shape(*ROOM_POLYLINES), CONFIG)
    assert not found.valid and found.T_1_2 == (0.0, 0.0, 0.0) and found.correspondences == ()
    assert len(shape_of_points(np.zeros((1, 2)), CONFIG)) == 0
