"""INTEGRATE with known answers: rigid copies are recovered, unrelated places are refused."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.geometry import lines_of
from multi_robot_mapper.core.matching import (
    HEURISTICS,
    IntegrateConfig,
    distinct_hypotheses,
    integrate,
    landmarks,
    refine,
    refine_many,
    scoring,
    seen_through,
)
from multi_robot_mapper.core.matching.confidence import is_right
from multi_robot_mapper.core.matching.hypotheses import (
    PAIRS_PER_KEPT_HYPOTHESIS,
    _within_comparison_budget,
)
from multi_robot_mapper.core.matching.integrate import _distinct_candidates
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.segment_map import SegmentMap
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.core.worlds import ROUTES, WORLDS

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


def test_a_confidence_not_wanted_is_not_computed_and_changes_nothing_else() -> None:
    # A caller that discards placements far from its prediction asks for no confidence there:
    # the placement is the same, with confidence 0 and no evidence; where it is wanted, the
    # result is the one without the question.
    s2, view2 = scan("office", (8.7, 3.2, 0.45), seed=1)
    views = (ROOM_VIEW, view2)
    plain = integrate(ROOM, s2, CONFIG, views=views)
    asked: list[np.ndarray] = []

    def wanted(answer: bool):  # type: ignore[no-untyped-def]
        def judged(T_1_2: np.ndarray) -> bool:
            asked.append(T_1_2.copy())
            return answer

        return judged

    kept = integrate(ROOM, s2, CONFIG, views=views, judged=wanted(True))
    skipped = integrate(ROOM, s2, CONFIG, views=views, judged=wanted(False))
    np.testing.assert_array_equal(asked[0], plain.T_1_2)
    for result in (kept, skipped):
        np.testing.assert_array_equal(result.T_1_2, plain.T_1_2)
        assert (result.value, result.valid) == (plain.value, plain.valid)
    assert kept.confidence == plain.confidence > 0.9 and kept.evidence == plain.evidence
    assert skipped.confidence == 0.0 and skipped.evidence is None
    assert "confidence" not in skipped.seconds


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
    marks = landmarks(cluttered, HEURISTICS, config, False, np.random.default_rng(0))
    assert len(marks.angle) ** 2 > 10 * budget
    thin, _ = _within_comparison_budget(cluttered, marks, cluttered, marks, config)
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


def test_each_view_judges_by_its_own_beams_when_many_are_judged_in_turn() -> None:
    # The beams of the views judged last are kept (a keyframe's scan is judged many times
    # per match): each view still answers from its own ranges, whatever was judged before.
    points = np.array([[1.0, 0.0], [3.0, 0.0], [4.95, 0.0]])
    walls = {2.0: [True, False, False], 5.0: [True, True, False], 3.05: [True, False, False]}
    for spread in (0, 1, 0):
        for distance, expected in walls.items():
            view = LaserScanData(
                np.full(181, distance), -np.pi / 2, np.pi / 2, np.pi / 180, 0.1, 10.0
            )
            for _ in range(2):  # the second time from the kept beams
                np.testing.assert_array_equal(seen_through(view, points, 0.15, spread), expected)


def test_distinct_hypotheses_merge_cells_and_count_votes() -> None:
    raw = np.array([[0.1, 1.0, 2.0], [0.1001, 1.001, 2.0], [1.0, 0.0, 0.0]])
    unique, votes = distinct_hypotheses(raw, np.radians(0.5), 0.02, 10)
    assert len(unique) == 2 and list(votes) == [2, 1]


def test_a_step_down_a_corridor_is_matched_with_views() -> None:
    # The cross corridor between the two blocks: parallel walls, door gaps, a far end.
    pose1, pose2 = (16.0, 8.0, np.pi / 2), (16.0, 9.1, np.pi / 2 + 0.05)
    s1, view1 = scan("corridors", pose1, seed=2)
    s2, view2 = scan("corridors", pose2, seed=3)
    result = integrate(s1, s2, CONFIG, views=(view1, view2))
    T_1_2 = se2.invert(se2.matrix_from_pose(*pose1)) @ se2.matrix_from_pose(*pose2)
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
    assert np.hypot(dx, dy) < 0.05 and abs(dtheta) < np.radians(1.0)


def test_refinement_pulls_several_hypotheses_at_once() -> None:
    T_1_2 = np.array([0.4, 1.0, -0.5])
    moved = se2.transform_segments(
        se2.invert(se2.matrix_from_pose(T_1_2[1], T_1_2[2], T_1_2[0])), ROOM
    )
    start = T_1_2 + np.array([[0.02, 0.05, -0.04], [-0.015, -0.06, 0.03], [0.0, 0.0, 0.0]])
    refined = refine_many(ROOM, moved, start, pair_tolerance(CONFIG), CONFIG.refine_iterations)
    np.testing.assert_allclose(refined, np.tile(T_1_2, (3, 1)), atol=1e-4)
    # refine() is the one-hypothesis case.
    np.testing.assert_allclose(
        refine(ROOM, moved, start[0], pair_tolerance(CONFIG), CONFIG.refine_iterations),
        T_1_2,
        atol=1e-4,
    )


def test_no_refinement_leaves_hypotheses_unchanged() -> None:
    start = np.array([[0.1, 0.2, 0.3], [1.0, -1.0, 2.0]])
    config = dataclasses.replace(CONFIG, refine_iterations=0)
    np.testing.assert_array_equal(
        refine_many(ROOM, ROOM, start, pair_tolerance(config), config.refine_iterations), start
    )


def test_without_refinement_the_answer_is_a_generated_hypothesis() -> None:
    # A copy moved by a transform that no hypothesis grid cell holds exactly: with
    # refinement the answer is exact, without it only within the hypothesis grid.
    T_1_2 = se2.matrix_from_pose(0.7, -0.3, 0.25)
    moved = se2.transform_segments(se2.invert(T_1_2), ROOM)
    config = dataclasses.replace(CONFIG, refine_iterations=0)
    rough = integrate(ROOM, moved, config)
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ rough.matrix)
    assert np.hypot(dx, dy) < 0.1 and abs(dtheta) < np.radians(1.0)


def test_seen_through_ignores_a_point_beside_a_grazing_return() -> None:
    ranges = np.full(181, 5.0)
    ranges[91] = 1.0  # the beam next to the point's bearing stops short
    view = LaserScanData(ranges, -np.pi / 2, np.pi / 2, np.pi / 180, 0.1, 10.0)
    point = np.array([[2.0, 0.0]])  # bearing 0: beam 90
    assert seen_through(view, point, 0.15, spread=0)[0]
    assert not seen_through(view, point, 0.15, spread=1)[0]


def test_distinct_candidates_are_apart() -> None:
    transforms = np.array(
        [[0.0, 0.0, 0.0], [0.01, 0.05, 0.0], [0.0, 1.0, 0.0], [np.pi, 0.0, 0.0], [0.0, 1.1, 0.0]]
    )
    values = np.array([5.0, 4.0, 3.0, 2.0, 1.0])
    config = dataclasses.replace(CONFIG, refine_candidates=10)
    picked = _distinct_candidates(np.zeros((0, 4)), np.zeros((0, 4)), transforms, values, config)
    assert list(picked) == [0, 2, 3]


def test_the_config_fields_are_documented_with_units_and_bounds() -> None:
    for field in dataclasses.fields(IntegrateConfig):
        assert field.metadata.get("doc"), field.name
        assert "unit" in field.metadata, field.name


def test_hypotheses_from_other_sets_are_evaluated_on_the_given_sets() -> None:
    T_1_2 = se2.matrix_from_pose(0.8, 0.4, -0.6)
    moved = se2.transform_segments(se2.invert(T_1_2), ROOM)
    half = len(ROOM) // 2  # the hypotheses come from half of each set only
    result = integrate(ROOM, moved, CONFIG, hypothesis_sets=(ROOM[:half], moved[:half]))
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
    assert np.hypot(dx, dy) < 1e-6 and abs(dtheta) < 1e-6
    assert result.fraction > 0.99


def test_an_extra_hypothesis_is_always_evaluated_and_refined() -> None:
    # No heuristic at all: the prediction alone, a few centimetres and a degree off.
    T_1_2 = np.array([0.3, 1.2, -0.7])
    moved = se2.transform_segments(
        se2.invert(se2.matrix_from_pose(T_1_2[1], T_1_2[2], T_1_2[0])), ROOM
    )
    guess = T_1_2 + np.array([0.02, 0.05, -0.03])
    result = integrate(ROOM, moved, CONFIG, heuristics=(), extra_hypotheses=guess[None, :])
    np.testing.assert_allclose(result.T_1_2, T_1_2, atol=1e-4)
    assert result.evaluated == 1


def _corridor(door: bool) -> np.ndarray:
    """A 2.4 m wide corridor, 60 m long (its ends beyond the laser's reach), with or without a
    door recess on one side."""
    if not door:
        return np.array([[-30.0, -1.2, 30.0, -1.2], [-30.0, 1.2, 30.0, 1.2]])
    return np.array(
        [
            [-30.0, -1.2, 30.0, -1.2],
            [-30.0, 1.2, 1.0, 1.2],
            [1.0, 1.2, 1.0, 2.0],
            [1.0, 2.0, 2.0, 2.0],
            [2.0, 2.0, 2.0, 1.2],
            [2.0, 1.2, 30.0, 1.2],
        ]
    )


def test_a_corridor_that_fits_at_many_places_gets_a_low_confidence() -> None:
    # Two scans 0.8 m apart in a bare corridor: every slide along it fits the walls as well as
    # the true one (a tie), and the match must not claim to be right.
    laser = LaserModel(beams=361, range_noise=0.005, dropout=0.0, range_max=20.0)
    rng = np.random.default_rng(3)
    bare = _corridor(False)
    first = simulate_scan(bare, (0.0, 0.0, 0.0), laser, rng)
    second = simulate_scan(bare, (0.8, 0.0, 0.0), laser, rng)
    segments = [extract_scan(s, ExtractionConfig())[0].segments for s in (first, second)]
    result = integrate(*segments, CONFIG, views=(first, second))
    assert result.confidence < 0.5
    assert result.evidence is not None and result.evidence.support < 0.1
    # A door recess fixes the offset along the corridor, yet INTEGRATE can still prefer a
    # slide here: read at the nearest beam, the walls' grazing returns confirm a copy of the
    # scan where it stood far better than any other placement. The confidence must say which
    # it is: right and confident, or wrong and doubtful, never wrong and confident.
    door = _corridor(True)
    first = simulate_scan(door, (0.0, 0.0, 0.0), laser, rng)
    second = simulate_scan(door, (0.8, 0.0, 0.0), laser, rng)
    segments = [extract_scan(s, ExtractionConfig())[0].segments for s in (first, second)]
    result = integrate(*segments, CONFIG, views=(first, second))
    right = is_right(result.matrix, se2.matrix_from_pose(0.8, 0.0, 0.0))
    assert result.confidence > 0.9 if right else result.confidence < 0.5


@settings(max_examples=40, deadline=None)
@given(
    first=st.lists(st.floats(-np.pi, np.pi), min_size=1, max_size=12),
    second=st.lists(st.floats(-np.pi, np.pi), min_size=1, max_size=12),
    turns=st.lists(st.floats(-2 * np.pi, 2 * np.pi), min_size=1, max_size=20),
    max_angle=st.floats(0.01, 0.5),
)
def test_candidate_pairs_are_every_pair_a_hypothesis_turns_parallel(
    first: list[float], second: list[float], turns: list[float], max_angle: float
) -> None:
    def unit_segments(angles: list[float]) -> np.ndarray:
        a = np.asarray(angles)
        return np.column_stack((np.zeros_like(a), np.zeros_like(a), np.cos(a), np.sin(a)))

    segments1, segments2 = unit_segments(first), unit_segments(second)
    theta = np.asarray(turns)
    geometry = scoring.pair_geometry(segments1, segments2)
    h, a, b = scoring._candidate_triples(geometry, theta, max_angle)
    found = set(zip(h.tolist(), a.tolist(), b.tolist(), strict=True))
    assert len(found) == h.size  # each triple once
    # Brute force: S2's direction turned by theta against S1's, mod pi (lines have no sign).
    angle1 = np.arctan2(segments1[:, 3], segments1[:, 2])
    angle2 = np.arctan2(segments2[:, 3], segments2[:, 2])
    off = np.mod(angle1[None, :, None] - angle2[None, None, :] - theta[:, None, None], np.pi)
    apart = np.minimum(off, np.pi - off)
    margin = 1e-9  # the two computations round differently at the interval's ends
    assert found >= set(map(tuple, np.argwhere(apart < max_angle - margin).tolist()))
    assert found <= set(map(tuple, np.argwhere(apart <= max_angle + margin).tolist()))


def test_pair_scores_follow_a_segment_set_changed_in_place() -> None:
    # An array is converted to a map at each call: a set changed in place is a new set.
    moved = se2.transform_segments(se2.matrix_from_pose(0.3, -0.2, 0.1), ROOM)
    T = np.array([[0.0, 0.0, 0.0], [-0.1, -0.3, 0.2]])
    edited = moved.copy()
    before = scoring.score_pairs(ROOM, edited, T, pair_tolerance(CONFIG))
    edited[:, [0, 2]] += 1.0  # the same array, new content
    again = scoring.score_pairs(ROOM, edited, T, pair_tolerance(CONFIG))
    fresh = scoring.score_pairs(ROOM.copy(), edited.copy(), T, pair_tolerance(CONFIG))
    for field in dataclasses.fields(again):
        assert np.array_equal(getattr(again, field.name), getattr(fresh, field.name))
    assert not np.array_equal(before.value, again.value)


def test_large_pair_geometries_are_not_kept() -> None:
    rng = np.random.default_rng(0)
    many = rng.uniform(-20.0, 20.0, (250, 4))  # 62 500 pairs, over the kept size
    segment_map = SegmentMap.of(many)
    with scoring.pair_kept(segment_map, segment_map):
        scores = scoring.score_pairs(
            segment_map, segment_map, np.zeros((1, 3)), pair_tolerance(CONFIG)
        )
        assert scoring.pair_geometry(segment_map, segment_map) is not scoring.pair_geometry(
            segment_map, segment_map
        )
    # A small pair's geometry is held on the first map, for the second, within the block only.
    room, moved = SegmentMap.of(ROOM), SegmentMap.of(ROOM[::-1])
    with scoring.pair_kept(room, moved):
        kept = scoring.pair_geometry(room, moved)
        assert scoring.pair_geometry(room, moved) is kept
        assert scoring.pair_geometry(moved, room) is not scoring.pair_geometry(moved, room)
    assert scoring.pair_geometry(room, moved) is not kept
    # identity: every segment matches itself fully (its own length, no penalty: it crosses)
    itself = scores.first == scores.second
    length = np.hypot(many[:, 2] - many[:, 0], many[:, 3] - many[:, 1])
    assert np.allclose(scores.value[itself], length[scores.first[itself]])


def _pair_values_by_hand(
    segments1: np.ndarray, segments2: np.ndarray, transforms: np.ndarray, config: IntegrateConfig
) -> dict[tuple[int, int, int], float]:
    """Alg. 4 l. 5-19 one triple at a time, straight from its definition."""

    def overlap(s: np.ndarray, t: np.ndarray) -> float:
        # t's end points projected on s's line, against s itself (along s's direction).
        u = (s[2:] - s[:2]) / np.hypot(*(s[2:] - s[:2]))
        lo, hi = sorted((float(u @ (t[:2] - s[:2])), float(u @ (t[2:] - s[:2]))))
        return max(0.0, min(hi, float(np.hypot(*(s[2:] - s[:2])))) - max(lo, 0.0))

    def line_distance(s: np.ndarray, p: np.ndarray) -> float:
        u = (s[2:] - s[:2]) / np.hypot(*(s[2:] - s[:2]))
        return abs(float(u[0] * (p[1] - s[1]) - u[1] * (p[0] - s[0])))

    def crosses(s: np.ndarray, t: np.ndarray) -> bool:
        def orient(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> float:
            return float((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))

        return (
            orient(s[:2], s[2:], t[:2]) * orient(s[:2], s[2:], t[2:]) <= 0.0
            and orient(t[:2], t[2:], s[:2]) * orient(t[:2], t[2:], s[2:]) <= 0.0
        )

    values = {}
    for h, (theta, tx, ty) in enumerate(transforms):
        T = se2.matrix_from_pose(tx, ty, theta)
        for b, moved in enumerate(se2.transform_segments(T, segments2)):
            for a, s in enumerate(segments1):
                turn = np.arctan2(moved[3] - moved[1], moved[2] - moved[0]) - np.arctan2(
                    s[3] - s[1], s[2] - s[0]
                )
                if abs(se2.wrap_angle(2.0 * turn)) > 2.0 * config.max_match_angle + 1e-9:
                    continue  # not parallel (mod pi)
                d = min(
                    max(line_distance(s, moved[:2]), line_distance(s, moved[2:])),
                    max(line_distance(moved, s[:2]), line_distance(moved, s[2:])),
                )
                if d > config.match_distance:
                    continue
                penalty = (
                    1.0 if crosses(s, moved) else 0.95 ** (d / config.point_distance_tolerance)
                )
                value = 0.5 * (overlap(s, moved) + overlap(moved, s)) * penalty
                if value > 1e-9:
                    values[(h, a, b)] = value
    return values


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_pair_values_are_alg4_triple_by_triple(seed: int) -> None:
    rng = np.random.default_rng(seed)

    def segments(count: int) -> np.ndarray:
        start = rng.uniform(-3.0, 3.0, (count, 2))
        angle = rng.choice([0.0, np.pi / 2, rng.uniform(-np.pi, np.pi)], count)
        length = rng.uniform(0.1, 4.0, count)
        return np.column_stack(
            (start, start + length[:, None] * np.column_stack((np.cos(angle), np.sin(angle))))
        )

    segments1, segments2 = segments(12), segments(12)
    transforms = np.column_stack(
        (rng.choice([0.0, np.pi / 2, 0.15], 6) + rng.normal(0, 0.05, 6), rng.normal(0, 0.5, (6, 2)))
    )
    scores = scoring.score_pairs(segments1, segments2, transforms, pair_tolerance(CONFIG))
    found = {
        (int(h), int(a), int(b)): float(v)
        for h, a, b, v in zip(
            scores.hypothesis, scores.first, scores.second, scores.value, strict=True
        )
        if v > 1e-9
    }
    expected = _pair_values_by_hand(segments1, segments2, transforms, CONFIG)
    assert found.keys() == expected.keys()
    assert all(abs(found[k] - expected[k]) < 1e-9 for k in found)
