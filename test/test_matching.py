"""INTEGRATE with known answers: rigid copies are recovered, unrelated places are refused."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import ExtractionConfig, extract_scan
from multi_robot_mapper.core.matching import (
    HEURISTICS,
    IntegrateConfig,
    distinct_hypotheses,
    integrate,
    seen_through,
)
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import ROUTES, WORLDS, LaserModel, simulate_scan

CONFIG = IntegrateConfig()
LASER = LaserModel(beams=361, range_noise=0.005, dropout=0.0)


def scan(
    world: str, pose: tuple[float, float, float], seed: int = 0
) -> tuple[np.ndarray, LaserScanData]:
    data = simulate_scan(WORLDS[world](), pose, LASER, np.random.default_rng(seed))
    return extract_scan(data, ExtractionConfig())[0].segments, data


ROOM, ROOM_VIEW = scan("office", (8.0, 3.0, 0.3))


@settings(max_examples=25, deadline=None)
@given(
    theta=st.floats(-np.pi, np.pi),
    distance=st.floats(0.0, 5.0),
    direction=st.floats(-np.pi, np.pi),
)
def test_a_rigidly_moved_copy_is_recovered_exactly(
    theta: float, distance: float, direction: float
) -> None:
    T_1_2 = se2.matrix_from_pose(distance * np.cos(direction), distance * np.sin(direction), theta)
    moved = se2.transform_segments(se2.invert(T_1_2), ROOM)  # ROOM seen from frame 2
    result = integrate(ROOM, moved, CONFIG)
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
    assert np.hypot(dx, dy) < 1e-6 and abs(dtheta) < 1e-6
    assert result.valid and result.fraction > 0.99


def test_the_next_scan_of_a_drive_is_matched_within_centimetres() -> None:
    pose1, pose2 = (8.0, 3.0, 0.3), (8.7, 3.2, 0.45)
    s2, view2 = scan("office", pose2, seed=1)
    result = integrate(ROOM, s2, CONFIG, views=(ROOM_VIEW, view2))
    T_1_2 = se2.invert(se2.matrix_from_pose(*pose1)) @ se2.matrix_from_pose(*pose2)
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
    assert np.hypot(dx, dy) < 0.03 and abs(dtheta) < np.radians(0.5)
    assert result.valid


@pytest.mark.parametrize(("world", "stop"), [("corridors", 0), ("corridors", 2), ("rooms", 1)])
def test_a_scan_of_an_unrelated_place_is_refused(world: str, stop: int) -> None:
    x, y = ROUTES[world][stop]
    other, view = scan(world, (x, y, 0.5 * stop))
    result = integrate(ROOM, other, CONFIG, views=(ROOM_VIEW, view))
    assert not result.valid, f"fraction {result.fraction:.2f}"


def test_each_heuristic_that_proposes_anything_finds_a_rigid_copy() -> None:
    T_1_2 = se2.matrix_from_pose(1.0, -2.0, 2.0)
    moved = se2.transform_segments(se2.invert(T_1_2), ROOM)
    found = []
    for heuristic in HEURISTICS:
        result = integrate(ROOM, moved, CONFIG, heuristics=(heuristic,))
        if result.hypotheses == 0:
            continue  # e.g. no two consecutive long segments at a usable angle in this scan
        dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
        assert np.hypot(dx, dy) < 1e-6 and abs(dtheta) < 1e-6, heuristic
        found.append(heuristic)
    assert len(found) >= 4, found


def test_one_wall_or_a_bare_corridor_is_not_a_valid_match() -> None:
    corridor = np.array([[0.0, 1.0, 6.0, 1.0], [0.0, -1.0, 6.0, -1.0]])
    shifted = corridor - np.array([0.4, 0.0, 0.4, 0.0])
    assert not integrate(corridor, shifted, CONFIG, ordered=(False, False)).valid
    assert not integrate(corridor[:1], corridor[:1], CONFIG).valid


def test_an_empty_set_gives_an_invalid_result() -> None:
    assert not integrate(np.zeros((0, 4)), ROOM, CONFIG).valid
    assert not integrate(ROOM, np.zeros((0, 4)), CONFIG).valid


def test_seen_through_marks_points_in_front_of_a_return() -> None:
    view = LaserScanData(np.full(181, 2.0), -np.pi / 2, np.pi / 2, np.pi / 180, 0.1, 10.0)
    points = np.array([[1.0, 0.0], [1.9, 0.0], [3.0, 0.0], [-1.0, 0.0]])
    np.testing.assert_array_equal(seen_through(view, points, 0.15), [True, False, False, False])


def test_distinct_hypotheses_merge_cells_and_count_votes() -> None:
    raw = np.array([[0.1, 1.0, 2.0], [0.1001, 1.001, 2.0], [1.0, 0.0, 0.0]])
    unique, votes = distinct_hypotheses(raw, np.radians(0.5), 0.02, 10)
    assert len(unique) == 2 and list(votes) == [2, 1]
