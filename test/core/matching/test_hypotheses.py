"""Hypotheses of INTEGRATE: landmarks thinned within the budget, distinct hypotheses by cell."""

from __future__ import annotations

import dataclasses

import numpy as np
from test_integrate import CONFIG, ROOM

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import lines_of
from multi_robot_mapper.core.matching import (
    HEURISTICS,
    distinct_hypotheses,
    integrate,
    landmarks,
)
from multi_robot_mapper.core.matching.hypotheses import (
    PAIRS_PER_KEPT_HYPOTHESIS,
    _within_comparison_budget,
    landmark_settings,
)


def _cluttered(segments: np.ndarray, count: int, seed: int) -> np.ndarray:
    """``segments`` with ``count`` short pieces of clutter (0.15-0.3 m) inside their extent,
    along and across the longest wall (thousands of perpendicular landmarks)."""
    rng = np.random.default_rng(seed)
    lines = lines_of(segments)
    heading = lines.angle[np.argmax(lines.length)] + rng.choice([0.0, np.pi / 2], count)
    low, high = segments.reshape(-1, 2).min(axis=0), segments.reshape(-1, 2).max(axis=0)
    start = rng.uniform(low, high, (count, 2))
    length = rng.uniform(0.15, 0.3, count)
    end = start + length[:, None] * np.column_stack((np.cos(heading), np.sin(heading)))
    return np.vstack((segments, np.hstack((start, end))))


def test_landmarks_of_a_cluttered_place_are_thinned_to_the_strongest() -> None:
    # A room and 150 pieces of clutter: all-pairs-like landmark counts (the histogram
    # heuristic pairs every piece along with every piece across). Compared within the budget,
    # the walls' own corners kept, and the rigid copy still found exactly.
    config = dataclasses.replace(CONFIG, max_hypotheses=100)
    budget = PAIRS_PER_KEPT_HYPOTHESIS * config.max_hypotheses
    cluttered = _cluttered(ROOM, 150, seed=3)
    marks = landmarks(
        cluttered, HEURISTICS, landmark_settings(config), False, np.random.default_rng(0)
    )
    assert len(marks.angle) ** 2 > 10 * budget
    thin, _ = _within_comparison_budget(cluttered, marks, cluttered, marks, config.max_hypotheses)
    assert len(thin.angle) ** 2 <= budget
    walls = {tuple(p) for p in np.column_stack((marks.first, marks.second)) if max(p) < len(ROOM)}
    long_walls = lines_of(ROOM).length >= 1.0
    corners = {p for p in walls if long_walls[p[0]] and long_walls[p[1]]}
    assert corners and corners <= {tuple(p) for p in np.column_stack((thin.first, thin.second))}
    T_1_2 = se2.matrix_from_pose(1.0, -2.0, 2.0)
    moved = se2.transform_segments(se2.invert(T_1_2), cluttered)
    result = integrate(cluttered, moved, config)
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
    assert np.hypot(dx, dy) < 1e-4 and abs(dtheta) < 1e-6  # refined: within 0.1 mm


def test_distinct_hypotheses_merge_cells_and_count_votes() -> None:
    raw = np.array([[0.1, 1.0, 2.0], [0.1001, 1.001, 2.0], [1.0, 0.0, 0.0]])
    unique, votes = distinct_hypotheses(raw, np.radians(0.5), 0.02, 10)
    assert len(unique) == 2 and list(votes) == [2, 1]
