"""Landmarks (angles between segment pairs) and the hypotheses they give (Amigoni Alg. 2,
the heuristics of III-A, end-point hypotheses for corridors)."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.config import IntegrateConfig
from multi_robot_mapper.core.segment_map import MapLike, SegmentMap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

HEURISTICS = ("consecutive", "random", "histogram", "all", "endpoints")


@dataclasses.dataclass(frozen=True)
class Landmarks:
    """Ordered segment pairs (i, j): the angle from line i to line j (mod pi) and their vertex."""

    first: IntArray
    second: IntArray
    angle: FloatArray  # (A,) in [0, pi)
    vertex: FloatArray  # (A, 2) intersection of the two supporting lines


class LandmarkSettings(NamedTuple):
    """What the heuristics of III-A read of INTEGRATE's config: the shortest segment a landmark
    takes (m), heuristic 1's share of the longest (%), heuristic 2's division factor and
    rounds, heuristic 3's direction buckets, the set size up to which every pair is taken, and
    the smallest angle a landmark may have (rad)."""

    min_length: float
    length_percentage: float
    division_factor: float
    random_rounds: int
    histogram_slots: int
    all_pairs_below: int
    min_angle: float


def landmark_settings(config: IntegrateConfig) -> LandmarkSettings:
    """The landmark settings of ``config``: ``min_segment_length``,
    ``segment_length_percentage``, ``segment_division_factor``, ``random_rounds``,
    ``histogram_slots``, ``all_pairs_below``, ``min_landmark_angle``."""
    return LandmarkSettings(
        config.min_segment_length,
        config.segment_length_percentage,
        config.segment_division_factor,
        config.random_rounds,
        config.histogram_slots,
        config.all_pairs_below,
        config.min_landmark_angle,
    )


def landmarks_from_pairs(
    segments: MapLike, first: IntArray, second: IntArray, min_angle: float
) -> Landmarks:
    """Landmarks of the given (i, j) pairs, both orders, dropping pairs nearer parallel than
    ``min_angle`` (rad)."""
    i = np.concatenate((first, second)).astype(np.int64)
    j = np.concatenate((second, first)).astype(np.int64)
    keep = i != j
    i, j = i[keep], j[keep]
    segment_map = SegmentMap.of(segments)
    lines = segment_map.lines
    ui, uj = lines.direction[i], lines.direction[j]
    sine = ui[:, 0] * uj[:, 1] - ui[:, 1] * uj[:, 0]
    ok = np.abs(sine) >= np.sin(min_angle)
    i, j, ui, uj, sine = i[ok], j[ok], ui[ok], uj[ok], sine[ok]
    # Intersection of p_i + s u_i and p_j + r u_j.
    pi, pj = segment_map.segments[i, :2], segment_map.segments[j, :2]
    delta = pj - pi
    s = (delta[:, 0] * uj[:, 1] - delta[:, 1] * uj[:, 0]) / sine
    vertex = pi + s[:, None] * ui
    angle = np.mod(lines.angle[j] - lines.angle[i], np.pi)
    pairs = np.unique(np.column_stack((i, j)), axis=0, return_index=True)[1]
    return Landmarks(i[pairs], j[pairs], angle[pairs], vertex[pairs])


def consecutive_pairs(
    segments: MapLike, ordered: bool, min_length: float, length_percentage: float
) -> tuple[IntArray, IntArray]:
    """Heuristic 1: consecutive segments of an ordered scan, both long enough (III-A-1): at
    least ``min_length`` (m) and ``length_percentage`` % of the longest."""
    n = len(segments)
    if not ordered or n < 2:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    length = SegmentMap.of(segments).length
    long_enough = length >= max(min_length, length_percentage / 100.0 * length.max())
    idx = np.flatnonzero(long_enough)
    # Consecutive among the long ones, even without a shared end point (the paper's improvement).
    return idx[:-1], idx[1:]


def random_pairs(
    segments: MapLike, rounds: int, min_length: float, factor: float, rng: np.random.Generator
) -> tuple[IntArray, IntArray]:
    """Heuristic 2 (Alg. 3): for k = 1 .. ``rounds``, N_k = 20 * 2^k random pairs of segments
    longer than ``factor``^k x longest (and than ``min_length``)."""
    length = SegmentMap.of(segments).length
    firsts, seconds = [], []
    for k in range(1, rounds + 1):
        pool = np.flatnonzero(length >= max(min_length, factor**k * length.max()))
        if pool.size < 2:
            continue
        count = 20 * 2**k
        a = rng.integers(0, pool.size, count)
        b = rng.integers(0, pool.size - 1, count)
        b = b + (b >= a)  # two distinct segments
        firsts.append(pool[a])
        seconds.append(pool[b])
    if not firsts:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(firsts), np.concatenate(seconds)


def histogram_pairs(segments: MapLike, min_length: float, slots: int) -> tuple[IntArray, IntArray]:
    """Heuristic 3: principal-direction segments x normal-direction segments (III-A-3), of the
    segments at least ``min_length`` long, directions in ``slots`` buckets."""
    lines = SegmentMap.of(segments).lines
    usable = lines.length >= min_length
    bucket = (np.mod(lines.angle, np.pi) / np.pi * slots).astype(np.int64) % slots
    weight = np.bincount(bucket[usable], weights=lines.length[usable], minlength=slots)
    principal = int(np.argmax(weight))
    normal = (principal + slots // 2) % slots
    # Neighbouring buckets too: a direction near a bucket edge must not be lost.
    near_p = np.abs((bucket - principal + slots // 2) % slots - slots // 2) <= 1
    near_n = np.abs((bucket - normal + slots // 2) % slots - slots // 2) <= 1
    p = np.flatnonzero(near_p & usable)
    q = np.flatnonzero(near_n & usable)
    if p.size == 0 or q.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    grid_p, grid_q = np.meshgrid(p, q, indexing="ij")
    return grid_p.ravel(), grid_q.ravel()


def all_pairs(segments: MapLike, min_length: float) -> tuple[IntArray, IntArray]:
    """Every pair of segments at least ``min_length`` long (Alg. 2 as written), for small sets."""
    idx = np.flatnonzero(SegmentMap.of(segments).length >= min_length)
    a, b = np.triu_indices(idx.size, k=1)
    return idx[a], idx[b]


def landmarks(
    segments: MapLike,
    heuristics: tuple[str, ...],
    settings: LandmarkSettings,
    ordered: bool,
    rng: np.random.Generator,
) -> Landmarks:
    """The landmarks of one segment set under the chosen heuristics (their union), each
    heuristic given its own ``settings``."""
    segments = SegmentMap.of(segments)
    min_length = settings.min_length
    firsts: list[IntArray] = []
    seconds: list[IntArray] = []
    for name in heuristics:
        if name == "consecutive":
            a, b = consecutive_pairs(segments, ordered, min_length, settings.length_percentage)
        elif name == "random":
            factor = settings.division_factor
            a, b = random_pairs(segments, settings.random_rounds, min_length, factor, rng)
        elif name == "histogram":
            a, b = histogram_pairs(segments, min_length, settings.histogram_slots)
        elif name == "all":
            if len(segments) > settings.all_pairs_below:
                continue
            a, b = all_pairs(segments, min_length)
        elif name == "endpoints":
            continue  # pairs of segments across the two sets, see endpoint_hypotheses
        else:
            raise ValueError(f"unknown heuristic {name!r}; choose from {', '.join(HEURISTICS)}")
        firsts.append(a)
        seconds.append(b)
    first = np.concatenate(firsts) if firsts else np.zeros(0, dtype=np.int64)
    second = np.concatenate(seconds) if seconds else np.zeros(0, dtype=np.int64)
    return landmarks_from_pairs(segments, first, second, settings.min_angle)


def hypotheses(
    segments1: MapLike,
    marks1: Landmarks,
    segments2: MapLike,
    marks2: Landmarks,
    angle_tolerance: float,
    max_hypotheses: int,
) -> FloatArray:
    """Every (theta, tx, ty) superimposing an angle of S2 on an angle of S1 equal within
    ``angle_tolerance`` (rad), of at most a budget of landmark pairs (``max_hypotheses``, see
    :data:`PAIRS_PER_KEPT_HYPOTHESIS`).

    Lines have no sense, so each correspondence gives two rotations, theta and theta + pi;
    the translation maps the S2 vertex onto the S1 vertex.
    """
    if len(marks1.angle) == 0 or len(marks2.angle) == 0:
        return np.zeros((0, 3))
    marks1, marks2 = _within_comparison_budget(segments1, marks1, segments2, marks2, max_hypotheses)
    diff = np.abs(marks1.angle[:, None] - marks2.angle[None, :])
    diff = np.minimum(diff, np.pi - diff)
    a1, a2 = np.nonzero(diff <= angle_tolerance)
    if a1.size == 0:
        return np.zeros((0, 3))
    phi1 = SegmentMap.of(segments1).lines.angle
    phi2 = SegmentMap.of(segments2).lines.angle
    # Rotation that aligns the first lines; average in the second lines' disagreement (mod pi).
    base = phi1[marks1.first[a1]] - phi2[marks2.first[a2]]
    other = phi1[marks1.second[a1]] - phi2[marks2.second[a2]]
    disagreement = se2.wrap_angle(2.0 * (other - base)) / 2.0  # other - base, mod pi
    theta0 = base + 0.5 * disagreement
    theta = np.concatenate((theta0, theta0 + np.pi))
    v1 = np.concatenate((marks1.vertex[a1], marks1.vertex[a1]))
    v2 = np.concatenate((marks2.vertex[a2], marks2.vertex[a2]))
    c, s = np.cos(theta), np.sin(theta)
    tx = v1[:, 0] - (c * v2[:, 0] - s * v2[:, 1])
    ty = v1[:, 1] - (s * v2[:, 0] + c * v2[:, 1])
    return np.column_stack((se2.wrap_angle(theta), tx, ty))


# Landmark pairs compared per distinct hypothesis kept (max_hypotheses): the votes that
# rank the distinct hypotheses need many raw ones, but not unboundedly many. The largest
# comparison on the shared logs is 0.25 M pairs (intel); a cluttered hall's submaps (250-300
# segments each, thousands of perpendicular pairs by the histogram heuristic) reached 37 M,
# 23 M raw hypotheses and 8 s per match, of which 20 000 were kept.
PAIRS_PER_KEPT_HYPOTHESIS = 50


def _within_comparison_budget(
    segments1: MapLike,
    marks1: Landmarks,
    segments2: MapLike,
    marks2: Landmarks,
    max_hypotheses: int,
) -> tuple[Landmarks, Landmarks]:
    """The two sets' landmarks, thinned (the same fraction of each) to at most
    ``PAIRS_PER_KEPT_HYPOTHESIS x max_hypotheses`` pairs to compare: the strongest kept, a
    landmark as strong as the shorter of its two segments (a long wall's corner is seen again;
    a chair leg's is not). Unchanged within the budget."""
    budget = PAIRS_PER_KEPT_HYPOTHESIS * max_hypotheses
    count1, count2 = len(marks1.angle), len(marks2.angle)
    if count1 * count2 <= budget:
        return marks1, marks2
    fraction = np.sqrt(budget / (count1 * count2))
    return (
        _strongest(segments1, marks1, max(1, int(count1 * fraction))),
        _strongest(segments2, marks2, max(1, int(count2 * fraction))),
    )


def _strongest(segments: MapLike, marks: Landmarks, keep: int) -> Landmarks:
    """The ``keep`` landmarks whose shorter segment is longest (ties: the first)."""
    length = SegmentMap.of(segments).length
    strength = np.minimum(length[marks.first], length[marks.second])
    chosen = np.sort(np.argsort(-strength, kind="stable")[:keep])
    return Landmarks(
        marks.first[chosen], marks.second[chosen], marks.angle[chosen], marks.vertex[chosen]
    )


def endpoint_hypotheses(map1: MapLike, map2: MapLike, min_length: float) -> FloatArray:
    """Hypotheses that lay a long S2 segment on a long S1 segment (at least ``min_length`` and
    0.3 of the longest), end points superimposed.

    Angles need two non-parallel segments; in a corridor every long segment is parallel and
    the angle heuristics find nothing. Aligning one wall with another fixes the rotation (two
    senses) and the offset across the wall; superimposing their ends (a door frame, a wall's
    end) proposes the offset along it, and the evaluation decides which offset is right.
    """
    first, second = SegmentMap.of(map1), SegmentMap.of(map2)
    segments1, segments2 = first.segments, second.segments
    l1, l2 = first.lines, second.lines
    long1 = np.flatnonzero(l1.length >= max(min_length, 0.3 * l1.length.max(initial=0.0)))
    long2 = np.flatnonzero(l2.length >= max(min_length, 0.3 * l2.length.max(initial=0.0)))
    if long1.size == 0 or long2.size == 0:
        return np.zeros((0, 3))
    grid_a, grid_b = np.meshgrid(long1, long2, indexing="ij")
    a, b = grid_a.ravel(), grid_b.ravel()
    theta = l1.angle[a] - l2.angle[b]
    # Same sense: start on start, end on end. Opposite sense (theta + pi): start on end.
    rotations = np.concatenate((theta, theta, theta + np.pi, theta + np.pi))
    target = np.concatenate(
        (segments1[a, :2], segments1[a, 2:], segments1[a, 2:], segments1[a, :2])
    )
    source = np.concatenate(
        (segments2[b, :2], segments2[b, 2:], segments2[b, :2], segments2[b, 2:])
    )
    c, s = np.cos(rotations), np.sin(rotations)
    tx = target[:, 0] - (c * source[:, 0] - s * source[:, 1])
    ty = target[:, 1] - (s * source[:, 0] + c * source[:, 1])
    return np.column_stack((se2.wrap_angle(rotations), tx, ty))


def distinct_hypotheses(
    transforms: FloatArray, angle_step: float, distance_step: float, limit: int
) -> tuple[FloatArray, IntArray]:
    """Merge hypotheses in the same (angle, x, y) cell; most-voted first, at most ``limit``."""
    if len(transforms) == 0:
        return transforms, np.zeros(0, dtype=np.int64)
    keys = np.column_stack(
        (
            np.round(transforms[:, 0] / angle_step),
            np.round(transforms[:, 1] / distance_step),
            np.round(transforms[:, 2] / distance_step),
        )
    ).astype(np.int64)
    keys[:, 0] %= round(2 * np.pi / angle_step)
    # One int64 per cell (1-D unique is several times faster than unique rows).
    span = 1 << 24
    code = (keys[:, 0] * span + (keys[:, 1] % span)) * span + (keys[:, 2] % span)
    _, first, votes = np.unique(code, return_index=True, return_counts=True)
    order = np.argsort(-votes, kind="stable")[:limit]
    return transforms[first[order]], votes[order]
