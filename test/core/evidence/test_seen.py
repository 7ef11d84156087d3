"""Free space from real scans (core/evidence/seen.py) with known answers: a beam that returned
at r saw nothing up to r less the margin, at most the reach; a beam near one with no return,
or near the end of the fan, claims nothing; the points are placed by the laser's pose."""

from __future__ import annotations

import math

import numpy as np
import pytest

from multi_robot_mapper.core.evidence.seen import SEEN_SPREAD, scan_free_points
from multi_robot_mapper.core.scan import LaserScanData

STEP = math.radians(1.0)


def fan(ranges: list[float] | np.ndarray) -> LaserScanData:
    """Beams a degree apart from bearing 0, counter-clockwise."""
    ranges = np.asarray(ranges, dtype=np.float64)
    return LaserScanData(ranges, 0.0, STEP * (len(ranges) - 1), STEP, 0.1, 30.0)


def test_a_wall_at_five_metres_leaves_free_space_up_to_the_margin_before_it() -> None:
    points = scan_free_points([fan([5.0] * 40)], np.zeros(3), 1.0)
    distance = np.hypot(points[:, 0], points[:, 1])
    # Steps 1, 2, 3, 4 m (5 m less the 0.5 m margin), none at the wall, of every beam but the
    # SEEN_SPREAD at each end of the fan (what lies beside them was not seen).
    inner = np.arange(SEEN_SPREAD, 40 - SEEN_SPREAD)
    assert len(points) == len(inner) * 4
    np.testing.assert_allclose(np.unique(np.round(distance, 9)), [1.0, 2.0, 3.0, 4.0])
    bearings = np.unique(np.round(np.arctan2(points[:, 1], points[:, 0]), 9))
    np.testing.assert_allclose(bearings, STEP * inner, atol=1e-9)


def test_the_reach_bounds_free_space_and_a_nearer_neighbour_bounds_each_beam() -> None:
    far = scan_free_points([fan([25.0] * 20)], np.zeros(3), 1.0, reach=3.5)
    assert len(far) == (20 - 2 * SEEN_SPREAD) * 3
    assert np.hypot(far[:, 0], far[:, 1]).max() == pytest.approx(3.0)  # steps below the reach
    # One beam returns at 2 m in a fan at 10 m: it and the beams within SEEN_SPREAD of it see
    # only 1 m (a gap beside a near return is not seen through); the others 7 m.
    ranges = np.full(41, 10.0)
    ranges[20] = 2.0
    points = scan_free_points([fan(ranges)], np.zeros(3), 1.0)
    beam = np.round(np.arctan2(points[:, 1], points[:, 0]) / STEP).astype(int)
    reach = {b: np.hypot(*points[beam == b].T).max() for b in np.unique(beam)}
    assert all(reach[b] == pytest.approx(1.0) for b in range(20 - SEEN_SPREAD, 21 + SEEN_SPREAD))
    assert reach[20 - SEEN_SPREAD - 1] == reach[21 + SEEN_SPREAD] == pytest.approx(7.0)


def test_a_beam_without_a_return_claims_nothing_around_it() -> None:
    ranges = np.full(41, 5.0)
    ranges[20] = np.inf  # glass or an open door: nothing is known beyond the other walls
    points = scan_free_points([fan(ranges)], np.zeros(3), 1.0)
    beam = set(np.round(np.arctan2(points[:, 1], points[:, 0]) / STEP).astype(int).tolist())
    inner = set(range(SEEN_SPREAD, 41 - SEEN_SPREAD))
    assert beam == inner - set(range(20 - SEEN_SPREAD, 21 + SEEN_SPREAD))
    assert len(scan_free_points([fan([np.nan] * 10)], np.zeros(3), 1.0)) == 0


def test_the_points_are_where_the_lasers_pose_puts_them() -> None:
    scan = fan([5.0] * 30)
    here = scan_free_points([scan], np.zeros(3), 0.5)
    pose = np.array([3.0, -2.0, math.pi / 2])
    there = scan_free_points([scan, scan], np.vstack([np.zeros(3), pose]), 0.5)
    assert len(there) == 2 * len(here)
    turned = np.column_stack((-here[:, 1], here[:, 0])) + pose[:2]
    np.testing.assert_allclose(there[len(here) :], turned, atol=1e-9)
