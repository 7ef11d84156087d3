"""Evaluation of hypotheses (Amigoni Alg. 4): matching values of segment pairs, refusal of
crossings, the cheap prescreen, and the support of a match across its weakest direction."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.geometry import Lines
from multi_robot_mapper.core.matching.config import IntegrateConfig
from multi_robot_mapper.core.segment_map import MapLike, SegmentMap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# The prescreen's rough cut (half the segments) keeps this many times its pool.
_ROUGH_CUT = 10


class PairTolerance(NamedTuple):
    """What matching two segments under a transformation reads of INTEGRATE's config (Alg. 4):
    the largest angle between two matching segments (rad), the largest distance between them
    (m), and the scale of the distance penalty (m)."""

    max_angle: float
    match_distance: float
    point_tolerance: float


def pair_tolerance(config: IntegrateConfig) -> PairTolerance:
    """The pair tolerances of ``config``: ``max_match_angle``, ``match_distance``,
    ``point_distance_tolerance``."""
    return PairTolerance(
        config.max_match_angle, config.match_distance, config.point_distance_tolerance
    )


class Prescreen(NamedTuple):
    """What the prescreen (:func:`pruned_values`) reads of INTEGRATE's config besides the pair
    tolerances: the largest angle between two segments it counts as matching (rad), how many
    of the longest segments it values, and how many hypotheses it passes on in full."""

    match_angle: float
    segments: int
    pool: int


@dataclasses.dataclass(frozen=True)
class PairScores:
    """Matching values of candidate (hypothesis, s1, s2) triples with a positive value."""

    hypothesis: IntArray
    first: IntArray  # index into S1
    second: IntArray  # index into S2
    value: FloatArray  # matching value mv (m)
    crossing: BoolArray  # the two segments intersect under the hypothesis


@dataclasses.dataclass(frozen=True)
class PairGeometry:
    """What every evaluation of two segment sets shares, whatever the hypotheses: the sets
    (one contiguous column per coordinate, which gathers faster than a 2-D index), their
    lines, and every segment pair (``first`` x ``second``, first-major) with the angle mod pi
    that a hypothesis must turn S2 by to make the pair parallel."""

    first_columns: tuple[FloatArray, FloatArray, FloatArray, FloatArray]  # x1, y1, x2, y2
    second_columns: tuple[FloatArray, FloatArray, FloatArray, FloatArray]
    first_direction: tuple[FloatArray, FloatArray]  # ux, uy
    second_direction: tuple[FloatArray, FloatArray]
    first_centres: tuple[FloatArray, FloatArray]  # x, y of each segment's midpoint
    second_centres: tuple[FloatArray, FloatArray]
    lines1: Lines
    lines2: Lines
    first: IntArray  # (N1 * N2,) index into S1 of each pair
    second: IntArray  # (N1 * N2,) index into S2
    parallel_at: FloatArray  # (N1 * N2,) theta mod pi that makes the pair parallel


# Pair geometries are held on the first map, within a :func:`pair_kept` block, up to this many
# pairs: the matcher evaluates the same two maps about ten times per match (values, each
# refinement iteration, refusal, ranking, slides); larger problems (whole maps) are rebuilt
# each time rather than kept in memory.
_KEPT_PAIRS = 40_000


class _HeldGeometry:
    """The pair geometry of two maps, built on first use (what :func:`pair_kept` holds)."""

    def __init__(self, map1: SegmentMap, map2: SegmentMap) -> None:
        self.maps = (map1, map2)

    @functools.cached_property
    def geometry(self) -> PairGeometry:
        return _build_geometry(*self.maps)


@contextlib.contextmanager
def pair_kept(map1: SegmentMap, map2: SegmentMap) -> Iterator[None]:
    """Within the block, :func:`pair_geometry` of ``map1`` and ``map2`` is built once (when
    they make at most ``_KEPT_PAIRS`` pairs) and held on ``map1``; dropped after the block, so
    that a map that lives long (a keyframe's scan) keeps nothing built with another."""
    if len(map1) * len(map2) > _KEPT_PAIRS:
        yield
        return
    with map1.holding(("pair", map2), lambda: _HeldGeometry(map1, map2)):
        yield


def pair_geometry(map1: MapLike, map2: MapLike) -> PairGeometry:
    """The :class:`PairGeometry` of S1 and S2: the one a :func:`pair_kept` block holds for
    these two :class:`~core.segment_map.SegmentMap` instances, else built (arrays are
    converted: a new array is a new map)."""
    first, second = SegmentMap.of(map1), SegmentMap.of(map2)
    held = first.held(("pair", second))
    if isinstance(held, _HeldGeometry):
        return held.geometry
    return _build_geometry(first, second)


def _build_geometry(map1: SegmentMap, map2: SegmentMap) -> PairGeometry:
    lines1, lines2 = map1.lines, map2.lines
    grid_a, grid_b = np.meshgrid(
        np.arange(len(map1), dtype=np.int64),
        np.arange(len(map2), dtype=np.int64),
        indexing="ij",
    )
    first, second = grid_a.ravel(), grid_b.ravel()
    parallel_at = np.mod(lines1.angle[first] - lines2.angle[second], np.pi)
    # A held geometry is shared by every later evaluation of the same maps: read only (the
    # maps' own arrays already are).
    for array in (first, second, parallel_at):
        array.flags.writeable = False
    return PairGeometry(
        first_columns=map1.columns,
        second_columns=map2.columns,
        first_direction=map1.direction_columns,
        second_direction=map2.direction_columns,
        first_centres=map1.centres,
        second_centres=map2.centres,
        lines1=lines1,
        lines2=lines2,
        first=first,
        second=second,
        parallel_at=parallel_at,
    )


def _candidate_triples(
    geometry: PairGeometry, theta: FloatArray, max_angle: float
) -> tuple[IntArray, IntArray, IntArray]:
    """(h, a, b) whose directions agree within ``max_angle`` (mod pi) under hypothesis h.

    For each segment pair the hypotheses that make it parallel form an interval of theta
    (mod pi): hypotheses sorted by theta mod pi are cut by searchsorted, so the work is
    proportional to the pairs and the candidates, not to hypotheses x pairs.
    """
    key = np.mod(theta, np.pi)
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    ext_key = np.concatenate((sorted_key - np.pi, sorted_key, sorted_key + np.pi))
    ext_idx = np.concatenate((order, order, order))
    centre = geometry.parallel_at
    lo = np.searchsorted(ext_key, centre - max_angle, side="left")
    hi = np.searchsorted(ext_key, centre + max_angle, side="right")
    count = hi - lo
    pair = np.repeat(np.arange(centre.size), count)
    start = np.repeat(np.cumsum(count) - count, count)
    position = lo[pair] + np.arange(pair.size) - start
    return ext_idx[position].astype(np.int64), geometry.first[pair], geometry.second[pair]


def score_pairs(
    map1: MapLike,
    map2: MapLike,
    transforms: FloatArray,
    pairs: PairTolerance,
) -> PairScores:
    """Matching value of every candidate triple (Alg. 4 l. 5-19), all hypotheses at once.

    mv = (l1 + l2) / 2 where l1 is the overlap of s2 projected on s1's line with s1 and l2 the
    converse; pairs whose distance d (Amigoni's, after Lu & Milios: the min over the two
    segments of the max distance of the other's end points to its line) exceeds
    ``match_distance`` score 0; pairs that do not intersect are penalised by 0.95^(d/tol).
    """
    return geometry_scores(pair_geometry(map1, map2), transforms, *pairs)


def geometry_scores(
    geometry: PairGeometry,
    transforms: FloatArray,
    max_angle: float,
    match_distance: float,
    tolerance: float,
) -> PairScores:
    """:func:`score_pairs` of the two sets whose :func:`pair_geometry` is given: directions
    within ``max_angle`` (rad), pairs within ``match_distance`` (m), the penalty of a pair
    that does not intersect on the scale ``tolerance`` (m)."""
    empty = PairScores(*(np.zeros(0, dtype=np.int64),) * 3, np.zeros(0), np.zeros(0, dtype=bool))
    if len(transforms) == 0 or geometry.first.size == 0:
        return empty
    h, a, b = _candidate_triples(geometry, transforms[:, 0], max_angle)
    if h.size == 0:
        return empty
    cos_h, sin_h = np.cos(transforms[:, 0]), np.sin(transforms[:, 0])
    c, s = cos_h[h], sin_h[h]
    tx, ty = np.ascontiguousarray(transforms[:, 1])[h], np.ascontiguousarray(transforms[:, 2])[h]
    triples = _Triples(h, a, b, c, s, tx, ty)
    triples = triples.take(_within_reach(geometry, triples, max_angle, match_distance))
    placed, d = _placed_pairs(geometry, triples)
    # Most candidate triples are far apart: drop them before the overlap arithmetic.
    near = np.flatnonzero(d <= match_distance)
    h, a, b, d = triples.h[near], triples.a[near], triples.b[near], d[near]
    placed = placed.take(near)
    l1, l2 = _overlaps(placed, geometry.lines1.length[a], geometry.lines2.length[b])
    crossing = _segments_cross(
        placed.e1x,
        placed.e1y,
        placed.e2x,
        placed.e2y,
        placed.q1x,
        placed.q1y,
        placed.q2x,
        placed.q2y,
    )
    penalty = np.where(crossing, 1.0, 0.95 ** (d / tolerance))
    value = 0.5 * (l1 + l2) * penalty
    keep = value > 0.0
    return PairScores(h[keep], a[keep], b[keep], value[keep], crossing[keep])


class _Triples(NamedTuple):
    """Candidate (hypothesis, s1, s2) triples: the hypothesis ``h``, the S1 segment ``a`` and
    the S2 segment ``b``, with the hypothesis's cosine ``c``, sine ``s`` and translation
    ``tx``, ``ty``."""

    h: IntArray
    a: IntArray
    b: IntArray
    c: FloatArray
    s: FloatArray
    tx: FloatArray
    ty: FloatArray

    def take(self, index: IntArray) -> _Triples:
        """The triples at ``index``."""
        h, a, b, c, s, tx, ty = self
        return _Triples(h[index], a[index], b[index], c[index], s[index], tx[index], ty[index])


def _within_reach(
    geometry: PairGeometry, triples: _Triples, angle: float, match_distance: float
) -> IntArray:
    """The candidate triples whose midpoints are close enough for the pair to score (their
    directions within ``angle``, their lines within ``match_distance``)."""
    _, a, b, c, s, tx, ty = triples
    lines1, lines2 = geometry.lines1, geometry.lines2
    # A pair scores only if it overlaps along one of its lines (l1 or l2 > 0 below) while one
    # segment's end points lie within match_distance of the other's line (d below). Then its
    # midpoints are at most reach apart: along the overlapping line by less than half the
    # two lengths; across it by at most match_distance where that same line holds the near
    # end points (a midpoint is no farther from a line than both its end points), else by
    # (match_distance + half the lengths x sin a) / cos a, the other line being turned by a
    # <= max_match_angle. Nine in ten candidates are farther: dropping them first gives the
    # same scores with a fraction of the arithmetic.
    reach = (lines1.length[a] + lines2.length[b]) * (0.5 * (1.0 + np.tan(angle)))
    reach += match_distance / np.cos(angle) + 1e-6  # 1e-6 m: rounding, never a score
    m2x, m2y = (column[b] for column in geometry.second_centres)
    gap_x = c * m2x - s * m2y + tx - geometry.first_centres[0][a]
    gap_y = s * m2x + c * m2y + ty - geometry.first_centres[1][a]
    return np.flatnonzero(gap_x * gap_x + gap_y * gap_y <= reach * reach)


class _PlacedPairs(NamedTuple):
    """Candidate pairs with S2 placed by their hypotheses: S2's end points q1, q2 and
    direction v in S1's frame, S1's direction u and end points e1, e2."""

    q1x: FloatArray
    q1y: FloatArray
    q2x: FloatArray
    q2y: FloatArray
    ux: FloatArray
    uy: FloatArray
    vx: FloatArray
    vy: FloatArray
    e1x: FloatArray
    e1y: FloatArray
    e2x: FloatArray
    e2y: FloatArray

    def take(self, index: IntArray) -> _PlacedPairs:
        """The pairs at ``index``."""
        return _PlacedPairs(*(column[index] for column in self))


def _placed_pairs(geometry: PairGeometry, triples: _Triples) -> tuple[_PlacedPairs, FloatArray]:
    """The candidate triples' pairs placed by their hypotheses (:class:`_PlacedPairs`) and
    their distance d (Alg. 4 l. 9: the min over the two segments of the max distance of the
    other's end points to its line)."""
    _, a, b, c, s, tx, ty = triples
    # S2 end points under the hypothesis, and their distances to s1's line (Alg. 4 l. 9).
    p1x, p1y, p2x, p2y = (column[b] for column in geometry.second_columns)
    q1x = c * p1x - s * p1y + tx
    q1y = s * p1x + c * p1y + ty
    q2x = c * p2x - s * p2y + tx
    q2y = s * p2x + c * p2y + ty
    ux, uy = (column[a] for column in geometry.first_direction)
    ca = geometry.lines1.normal_offset[a]
    dq = np.maximum(np.abs(-uy * q1x + ux * q1y - ca), np.abs(-uy * q2x + ux * q2y - ca))
    wx, wy = (column[b] for column in geometry.second_direction)
    vx = c * wx - s * wy
    vy = s * wx + c * wy
    e1x, e1y, e2x, e2y = (column[a] for column in geometry.first_columns)
    cb = -vy * q1x + vx * q1y
    de = np.maximum(np.abs(-vy * e1x + vx * e1y - cb), np.abs(-vy * e2x + vx * e2y - cb))
    placed = _PlacedPairs(q1x, q1y, q2x, q2y, ux, uy, vx, vy, e1x, e1y, e2x, e2y)
    return placed, np.minimum(dq, de)


def _overlaps(
    placed: _PlacedPairs, length1: FloatArray, length2: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """l1 and l2 of each placed pair: the overlap of s2 projected on s1's line with s1, and
    the converse (``length1``, ``length2``: the lengths of s1 and s2)."""
    q1x, q1y, q2x, q2y, ux, uy, vx, vy, e1x, e1y, e2x, e2y = placed
    # Overlaps along each line (s1 runs from e1 to e2 along u; s2 from q1 to q2 along v).
    sa1 = ux * e1x + uy * e1y
    sq1 = ux * q1x + uy * q1y
    sq2 = ux * q2x + uy * q2y
    l1 = np.clip(
        np.minimum(sa1 + length1, np.maximum(sq1, sq2)) - np.maximum(sa1, np.minimum(sq1, sq2)),
        0.0,
        None,
    )
    sb1 = vx * q1x + vy * q1y
    se1 = vx * e1x + vy * e1y
    se2_ = vx * e2x + vy * e2y
    l2 = np.clip(
        np.minimum(sb1 + length2, np.maximum(se1, se2_)) - np.maximum(sb1, np.minimum(se1, se2_)),
        0.0,
        None,
    )
    return l1, l2


def _segments_cross(
    ax: FloatArray,
    ay: FloatArray,
    bx: FloatArray,
    by: FloatArray,
    cx: FloatArray,
    cy: FloatArray,
    dx: FloatArray,
    dy: FloatArray,
) -> BoolArray:
    """Element-wise: do segments a-b and c-d intersect (proper crossing or touching)?"""

    def orient(
        px: FloatArray,
        py: FloatArray,
        qx: FloatArray,
        qy: FloatArray,
        rx: FloatArray,
        ry: FloatArray,
    ) -> FloatArray:
        return np.asarray((qx - px) * (ry - py) - (qy - py) * (rx - px))

    o1 = orient(ax, ay, bx, by, cx, cy)
    o2 = orient(ax, ay, bx, by, dx, dy)
    o3 = orient(cx, cy, dx, dy, ax, ay)
    o4 = orient(cx, cy, dx, dy, bx, by)
    return np.asarray((o1 * o2 <= 0.0) & (o3 * o4 <= 0.0))


def refusal(config: IntegrateConfig) -> tuple[float, float, float]:
    """What :func:`refused` reads of ``config``: the long segments' length, the shallowest
    crossing angle and the crossing's margin inside both segments."""
    return config.segment_length_refuse, config.min_landmark_angle, config.crossing_margin


def refused(
    map1: MapLike,
    map2: MapLike,
    transforms: FloatArray,
    long: float,
    min_angle: float,
    margin: float,
) -> BoolArray:
    """Hypotheses that make an S1 segment longer than ``long`` (m) cross such an S2 segment
    (Alg. 4 l. 6-7).

    Only a proper crossing counts: the crossing point must lie at least ``margin`` (m) inside
    both segments, since walls that meet at a corner or a T-junction touch without
    contradicting each other, and two walls crossing at a shallow angle (under ``min_angle``,
    rad) are one wall slightly misaligned.
    """
    first, second = SegmentMap.of(map1), SegmentMap.of(map2)
    segments1, segments2 = first.segments, second.segments
    lines1, lines2 = first.lines, second.lines
    long1 = np.flatnonzero(lines1.length > long)
    long2 = np.flatnonzero(lines2.length > long)
    out = np.zeros(len(transforms), dtype=bool)
    if long1.size == 0 or long2.size == 0 or len(transforms) == 0:
        return out
    grid_h, grid_a, grid_b = np.meshgrid(np.arange(len(transforms)), long1, long2, indexing="ij")
    h, a, b = grid_h.ravel(), grid_a.ravel(), grid_b.ravel()
    c, s = np.cos(transforms[h, 0]), np.sin(transforms[h, 0])
    p = segments2[b]
    qx = c * p[:, 0] - s * p[:, 1] + transforms[h, 1]
    qy = s * p[:, 0] + c * p[:, 1] + transforms[h, 2]
    vx = c * lines2.direction[b, 0] - s * lines2.direction[b, 1]
    vy = s * lines2.direction[b, 0] + c * lines2.direction[b, 1]
    ux, uy = lines1.direction[a, 0], lines1.direction[a, 1]
    sine = ux * vy - uy * vx
    steep = np.abs(sine) > np.sin(min_angle)
    safe = np.where(steep, sine, 1.0)
    dx, dy = qx - segments1[a, 0], qy - segments1[a, 1]
    along_a = (dx * vy - dy * vx) / safe  # distance from s1's start to the crossing
    along_b = (dx * uy - dy * ux) / safe  # distance from s2's start to the crossing
    inside = (
        (along_a > margin)
        & (along_a < lines1.length[a] - margin)
        & (along_b > margin)
        & (along_b < lines2.length[b] - margin)
    )
    # The grid is hypothesis-major: each hypothesis owns one contiguous block of pairs.
    return np.asarray((steep & inside).reshape(len(transforms), -1).any(axis=1))


def transform_values(scores: PairScores, count: int) -> FloatArray:
    """The value of each hypothesis: the sum of its pairs' matching values (Alg. 4 l. 18)."""
    return np.bincount(scores.hypothesis, weights=scores.value, minlength=count).astype(np.float64)


def information(map1: MapLike, scores: PairScores, count: int) -> tuple[FloatArray, FloatArray]:
    """Per hypothesis: smallest eigenvalue of sum(value n n^T) and its eigenvector (the
    direction matched walls constrain least, along a corridor)."""
    if scores.first.size == 0:
        return np.zeros(count), np.tile([1.0, 0.0], (count, 1))
    u = SegmentMap.of(map1).lines.direction[scores.first]
    nx, ny, w, h = -u[:, 1], u[:, 0], scores.value, scores.hypothesis
    sxx = np.bincount(h, weights=w * nx * nx, minlength=count)
    sxy = np.bincount(h, weights=w * nx * ny, minlength=count)
    syy = np.bincount(h, weights=w * ny * ny, minlength=count)
    half_trace = 0.5 * (sxx + syy)
    radius = np.hypot(0.5 * (sxx - syy), sxy)
    major = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # the dominant normal
    direction = np.column_stack((-np.sin(major), np.cos(major)))
    return np.asarray(np.maximum(half_trace - radius, 0.0), dtype=np.float64), direction


def cross_support(map1: MapLike, map2: MapLike, T_1_2: FloatArray, pairs: PairTolerance) -> float:
    """Matched length in the least constrained direction: the smallest eigenvalue of the sum
    of matching value x n n^T over matched pairs (n the S1 line's normal). Zero when every
    matched wall is parallel, so the offset along them rests on where walls happen to end."""
    T = np.asarray(T_1_2, dtype=np.float64).reshape(1, 3)
    first, second = SegmentMap.of(map1), SegmentMap.of(map2)
    scores = score_pairs(first, second, T, pairs)
    return float(information(first, scores, 1)[0][0])


def support_and_slide(
    map1: MapLike, map2: MapLike, T_1_2: FloatArray, pairs: PairTolerance
) -> tuple[float, FloatArray, float]:
    """The cross support of ``T_1_2``, its least constrained direction (a unit vector in
    S1's frame: along a corridor, the way the placement could slide) and the matched length
    (the trace of the walls' normal matrix: the two eigenvalues' sum)."""
    scores = score_pairs(map1, map2, T_1_2.reshape(1, 3), pairs)
    support, direction = information(map1, scores, 1)
    total = float(scores.value.sum())
    return float(support[0]), np.asarray(direction[0], dtype=np.float64), total


def best_prescreened(
    map1: MapLike,
    map2: MapLike,
    transforms: FloatArray,
    keep: int,
    segments_used: int,
    tolerances: tuple[float, float, float],
) -> IntArray:
    """Indices of the ``keep`` hypotheses (all when fewer) with the best rough value
    (:func:`_prescreen_values`, its ``tolerances``) on the ``segments_used`` longest segments
    of each set."""
    if len(transforms) <= keep:
        return np.arange(len(transforms), dtype=np.int64)
    first, second = SegmentMap.of(map1), SegmentMap.of(map2)
    rough = _prescreen_values(
        first.longest(segments_used), second.longest(segments_used), transforms, *tolerances
    )
    return np.asarray(np.argpartition(-rough, keep - 1)[:keep], dtype=np.int64)


def _prescreen_values(
    map1: SegmentMap,
    map2: SegmentMap,
    transforms: FloatArray,
    match_angle: float,
    match_distance: float,
    tolerance: float,
) -> FloatArray:
    """A cheap lower-fidelity value of every hypothesis, for ranking only.

    Alg. 4's matching value with half the arithmetic: the S2 segment's end points' distance
    to the S1 line (not the symmetric distance, within ``match_distance``), the overlap along
    the S1 line only, and no crossing test; directions must agree within ``match_angle``.
    """
    count = len(transforms)
    if count == 0 or len(map1) == 0 or len(map2) == 0:
        return np.zeros(count)
    segments1, segments2 = map1.segments, map2.segments
    geometry = pair_geometry(map1, map2)
    lines1 = geometry.lines1
    h, a, b = _candidate_triples(geometry, transforms[:, 0], match_angle)
    if h.size == 0:
        return np.zeros(count)
    cos_h, sin_h = np.cos(transforms[:, 0]), np.sin(transforms[:, 0])
    c, s = cos_h[h], sin_h[h]
    tx, ty = transforms[h, 1], transforms[h, 2]
    q1x = c * segments2[b, 0] - s * segments2[b, 1] + tx
    q1y = s * segments2[b, 0] + c * segments2[b, 1] + ty
    q2x = c * segments2[b, 2] - s * segments2[b, 3] + tx
    q2y = s * segments2[b, 2] + c * segments2[b, 3] + ty
    ux, uy = lines1.direction[a, 0], lines1.direction[a, 1]
    ca = lines1.normal_offset[a]
    d = np.maximum(np.abs(-uy * q1x + ux * q1y - ca), np.abs(-uy * q2x + ux * q2y - ca))
    near = np.flatnonzero(d <= match_distance)
    h, a, d = h[near], a[near], d[near]
    ux, uy = ux[near], uy[near]
    sa1 = ux * segments1[a, 0] + uy * segments1[a, 1]
    sq1 = ux * q1x[near] + uy * q1y[near]
    sq2 = ux * q2x[near] + uy * q2y[near]
    overlap = np.clip(
        np.minimum(sa1 + lines1.length[a], np.maximum(sq1, sq2))
        - np.maximum(sa1, np.minimum(sq1, sq2)),
        0.0,
        None,
    )
    value = overlap * 0.95 ** (d / tolerance)
    return np.bincount(h, weights=value, minlength=count).astype(np.float64)


def pruned_values(
    map1: MapLike,
    map2: MapLike,
    transforms: FloatArray,
    tolerance: PairTolerance,
    screen: Prescreen,
    forced: int = 0,
) -> tuple[FloatArray, int]:
    """Values of the hypotheses worth a full evaluation, 0 for the others (Amigoni III-B).

    Long segments carry most of a good transformation's value, and the work of Alg. 4 grows
    with hypotheses x segments x segments. When there are more than ``screen.pool``
    hypotheses, each is first valued roughly (:func:`_prescreen_values`) on the longest
    segments of both sets: half of ``screen.segments`` for a rough cut to
    10 x ``screen.pool``, then ``screen.segments``; the ``screen.pool`` best are
    evaluated in full (Alg. 4 l. 5-19, by the pair ``tolerance``), and so are the first
    ``forced`` hypotheses.
    """
    first, second = SegmentMap.of(map1), SegmentMap.of(map2)
    count = len(transforms)
    pool = np.arange(forced, count)
    tolerances = (screen.match_angle, tolerance.match_distance, tolerance.point_tolerance)
    for segments_used, keep in (
        (max(1, screen.segments // 2), _ROUGH_CUT * screen.pool),
        (screen.segments, screen.pool),
    ):
        best = best_prescreened(first, second, transforms[pool], keep, segments_used, tolerances)
        pool = pool[best]
    pool = np.concatenate((np.arange(forced), pool))
    values = np.zeros(count)
    scores = score_pairs(first, second, transforms[pool], tolerance)
    values[pool] = transform_values(scores, pool.size)
    return values, int(pool.size)
