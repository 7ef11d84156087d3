"""Amigoni's Alg. 4 values of hypotheses: candidate pairs, pair scores, triple by triple."""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from test_integrate import CONFIG, ROOM

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching import (
    IntegrateConfig,
    scoring,
)
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.segment_map import SegmentMap


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
