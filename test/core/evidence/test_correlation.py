"""Map correlation (core/merging/correlation.py): known answers in metres, and the rigid-motion
property.

The correlation proposes placements of one map on another for the merger; its score is
metres of wall on wall of the same direction minus ``free_space_weight`` x metres of wall in
the other map's free space.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.correlation import (
    CorrelationConfig,
    Drawing,
    correlation_peaks,
    placement_scores,
    rotation_candidates,
)
from multi_robot_mapper.core.worlds import WORLDS, polygon

CONFIG = CorrelationConfig()
NO_FREE = np.zeros((0, 2))


def row(x: float, y: float, theta: float) -> np.ndarray:
    """A placement as the correlation writes it: (theta, tx, ty)."""
    return np.array([[theta, x, y]])


def test_a_wall_on_itself_scores_about_its_length_in_metres() -> None:
    # About: how a wall falls on the grid's cells changes the score by up to 15 %.
    wall = np.array([[0.0, 0.0, 20.0, 0.0]])
    for direction in (0.0, 0.4, np.pi / 4, np.pi / 2, 2.0):  # the channels are isotropic
        T = se2.matrix_from_pose(0.37, 0.11, direction)
        drawing = Drawing.of(se2.transform_segments(T, wall), NO_FREE, CONFIG.cell)
        score = placement_scores(drawing, drawing, row(0.0, 0.0, 0.0), CONFIG)[0]
        assert score == pytest.approx(20.0, rel=0.15)
        peaks, scores = correlation_peaks(drawing, drawing, np.zeros(1), CONFIG)
        assert scores[0] == pytest.approx(20.0, rel=0.15)
        assert np.abs(peaks[0]).max() < 1e-9  # the best shift of a map over itself: none
    # Moved off by far more than the blur, it scores nothing; across, a third per metre at most.
    drawing = Drawing.of(wall, NO_FREE, CONFIG.cell)
    assert placement_scores(drawing, drawing, row(0.0, 2.0, 0.0), CONFIG)[0] == 0.0
    across = Drawing.of(np.array([[3.0, -3.0, 3.0, 3.0]]), NO_FREE, CONFIG.cell)
    assert 0.0 < placement_scores(drawing, across, row(0.0, 0.0, 0.0), CONFIG)[0] < 0.5


def test_a_wall_in_the_other_robots_free_space_counts_against() -> None:
    # Map a: a wall at y = 4 seen from below (free space between y = 0.5 and 3.5).
    xs, ys = np.meshgrid(np.arange(0.0, 6.0, 0.1), np.arange(0.5, 3.5, 0.1))
    free = np.column_stack((xs.ravel(), ys.ravel()))
    a = Drawing.of(np.array([[0.0, 4.0, 6.0, 4.0]]), free, CONFIG.cell)
    b = Drawing.of(np.array([[0.0, 0.0, 6.0, 0.0]]), NO_FREE, CONFIG.cell)
    on_wall, in_free = placement_scores(a, b, np.vstack((row(0, 4, 0), row(0, 2, 0))), CONFIG)
    assert on_wall == pytest.approx(6.0, rel=0.15)
    assert in_free == pytest.approx(-CONFIG.free_space_weight * 6.0, rel=0.15)


def test_rotation_candidates_hold_the_turn_between_two_copies_of_a_map() -> None:
    office = WORLDS["office"]()
    for turn in (0.3, -2.0, 3.0):
        moved = se2.transform_segments(se2.matrix_from_pose(1.0, 2.0, turn), office)
        candidates = rotation_candidates(moved, office, CONFIG.rotations)
        assert np.min(np.abs(se2.wrap_angle(candidates - turn))) < np.radians(0.5)


@settings(max_examples=25, deadline=None)
@given(
    theta=st.floats(-np.pi, np.pi),
    distance=st.floats(0.0, 20.0),
    direction=st.floats(-np.pi, np.pi),
)
def test_the_best_peak_is_the_rigid_motion_between_a_map_and_its_copy(
    theta: float, distance: float, direction: float
) -> None:
    # A building that is not symmetric: an L-shaped hall with a slanted wall and a pillar.
    walls = np.vstack(
        (
            polygon([(0, 0), (12, 0), (12, 5), (5, 5), (5, 10), (0, 10)]),
            polygon([(7, 1), (9, 3)], closed=False),
            polygon([(2, 6), (3, 6), (3, 7), (2, 7)]),
        )
    ).astype(np.float64)
    T_a_b = se2.matrix_from_pose(distance * np.cos(direction), distance * np.sin(direction), theta)
    b = se2.transform_segments(se2.invert(T_a_b), walls)  # map b's frame is at T_a_b in a's
    drawing_a = Drawing.of(walls, NO_FREE, CONFIG.cell)
    drawing_b = Drawing.of(b, NO_FREE, CONFIG.cell)
    peaks, scores = correlation_peaks(
        drawing_a, drawing_b, rotation_candidates(walls, b, CONFIG.rotations), CONFIG
    )
    assert scores[0] == pytest.approx(scores.max())
    best_theta, tx, ty = peaks[0]
    x, y, _ = se2.pose_from_matrix(T_a_b)
    # One cell of translation (and what half a degree of turn moves the far end by).
    assert abs(se2.wrap_angle(best_theta - theta)) < np.radians(0.5)
    assert np.hypot(tx - x, ty - y) < CONFIG.cell + 0.2


def test_slides_scored_through_their_bound_pick_what_scoring_all_picks() -> None:
    # PlacementScorer.best_of scores in full only the slides whose bound (score_bound) can
    # reach the best: the same slide and score as np.argmax over every slide's score.
    from multi_robot_mapper.core.evidence.correlation import score_bound
    from multi_robot_mapper.core.evidence.placement import EVIDENCE_CORRELATION, PlacementScorer

    walls = polygon([(0, 0), (40, 0), (40, 3), (22, 3), (22, 12), (19, 12), (19, 3), (0, 3)])
    for index in range(10):  # doors every 4 m along the corridor: look-alikes slid by 4 m
        walls = np.vstack((walls, [[4.0 * index, 0.0, 4.0 * index, -1.5]]))
    xs, ys = np.meshgrid(np.arange(0.2, 40.0, 0.3), np.arange(0.2, 2.8, 0.3))
    a = Drawing.of(walls, np.column_stack((xs.ravel(), ys.ravel())), EVIDENCE_CORRELATION.cell)
    patch = walls[np.hypot(walls[:, 0] - 20.0, walls[:, 1] - 2.0) < 6.0]
    b = Drawing.of(patch, np.zeros((0, 2)), EVIDENCE_CORRELATION.cell)
    scorer = PlacementScorer(a, b, EVIDENCE_CORRELATION)
    for theta, tx, ty in ((0.0, 0.0, 0.0), (0.05, 0.4, -0.2), (np.pi, 40.0, 3.0)):
        slides = scorer.slides(np.array([theta, tx, ty]))
        assert len(slides) > 50
        every = scorer.scores(slides)
        blur_cell = (EVIDENCE_CORRELATION.blur, EVIDENCE_CORRELATION.cell)
        weight = EVIDENCE_CORRELATION.free_space_weight
        assert (score_bound(b, slides, scorer.rasters_a, blur_cell, weight) >= every).all()
        best, value = scorer.best_of(slides)
        assert best == int(np.argmax(every))
        assert value == pytest.approx(float(every[best]), rel=1e-12, abs=1e-12)
