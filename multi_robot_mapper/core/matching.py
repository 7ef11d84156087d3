"""Pipeline stage 3: how two segment sets fit together, with no initial guess (INTEGRATE).

Amigoni, Gasparini & Gini 2006, Sec. III: angles between pairs of segments are geometric
landmarks; every rototranslation that superimposes an angle of S2 on an equal angle of S1 is a
hypothesis (Algorithm 2, with the heuristics of III-A that choose which angles); each
hypothesis is scored by the overlap length of matching segments (Algorithm 4); the best one is
refined by point-to-line least squares (Cox, as in Wolter 5.1).

All of it is array code: landmarks x landmarks for hypotheses, and hypotheses x segments x
segments for the evaluation, restricted early to the nearly parallel triples that can score.
Transforms are ``(theta, tx, ty)`` rows: ``T_1_2`` maps S2 coordinates into S1's frame.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.scan import LaserScanData

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

HEURISTICS = ("consecutive", "random", "histogram", "all", "endpoints")


@dataclasses.dataclass(frozen=True)
class IntegrateConfig:
    """INTEGRATE parameters (Amigoni III). Lengths in metres, angles in radians."""

    point_distance_tolerance: float = param(
        0.05,
        unit="m",
        doc="POINTDISTANCETOLERANCE: scale of the distance penalty 0.95^(d/tol) (Alg. 4 l. 16)",
        minimum=0.0,
        exclusive_minimum=True,
    )
    segment_distance_threshold: float = param(
        5.0,
        unit="",
        doc="SEGMENTDISTANCETHRESHOLD: pairs farther than this many tolerances do not match",
        minimum=0.0,
        exclusive_minimum=True,
    )
    angle_difference_tolerance: float = param(
        0.05,
        unit="rad",
        doc="ANGLEDIFFERENCETOLERANCE: two landmark angles this close are equal",
        minimum=0.0,
        exclusive_minimum=True,
    )
    segment_length_refuse: float = param(
        0.8,
        unit="m",
        doc="SEGMENTLENGTHREFUSE: a hypothesis making two longer segments cross is refused",
        minimum=0.0,
    )
    crossing_margin: float = param(
        0.2,
        unit="m",
        doc="a crossing refuses only if it lies this far inside both long segments",
        minimum=0.0,
    )
    min_landmark_angle: float = param(
        0.35,
        unit="rad",
        doc="segment pairs closer to parallel than this have no reliable vertex",
        minimum=0.0,
        maximum=1.5,
    )
    segment_length_percentage: float = param(
        20.0,
        unit="%",
        doc="SEGMENTLENGTHPERCENTAGE: consecutive-angle segments must be this long vs the longest",
        minimum=0.0,
        maximum=100.0,
    )
    segment_division_factor: float = param(
        0.5,
        unit="",
        doc="SEGMENTDIVISIONFACTOR: random heuristic draws from segments longer than f^k x longest",
        minimum=0.0,
        exclusive_minimum=True,
        maximum=1.0,
    )
    random_rounds: int = param(
        3, unit="", doc="K of Alg. 3: rounds k = 1..K drawing N_k = 20 * 2^k angles", minimum=0
    )
    histogram_slots: int = param(
        18,
        unit="",
        doc="orientation histogram buckets over pi (perpendicular heuristic)",
        minimum=4,
    )
    all_pairs_below: int = param(
        12,
        unit="segments",
        doc="use every segment pair when a set has at most this many",
        minimum=0,
    )
    min_segment_length: float = param(
        0.1, unit="m", doc="shorter segments never form landmarks", minimum=0.0
    )
    max_match_angle: float = param(
        0.2,
        unit="rad",
        doc="segments whose directions differ more than this never match (bounds the work)",
        minimum=0.0,
        exclusive_minimum=True,
        maximum=1.5,
    )
    max_hypotheses: int = param(
        4000, unit="", doc="at most this many distinct hypotheses are evaluated", minimum=1
    )
    refine_iterations: int = param(
        15,
        unit="",
        doc="point-to-line least-squares iterations after the best hypothesis",
        minimum=0,
    )
    seed: int = param(0, unit="", doc="seed of the random-pair heuristic (deterministic runs)")
    min_match_value: float = param(
        1.0,
        unit="m",
        doc="validity: the best transformation must overlap at least this length",
        minimum=0.0,
    )
    min_match_fraction: float = param(
        0.5,
        unit="",
        doc="validity: net value at least this fraction of the shorter set's total length",
        minimum=0.0,
        maximum=1.0,
    )
    free_space_margin: float = param(
        0.15,
        unit="m",
        doc="a point this far in front of what the other scan's beam measured is a contradiction",
        minimum=0.0,
    )
    free_space_weight: float = param(
        1.0,
        unit="",
        doc="metres of overlap one metre of segment inside the other scan's free space cancels",
        minimum=0.0,
    )
    min_cross_support: float = param(
        0.5,
        unit="m",
        doc="validity: matched length across the weakest direction (one wall or a bare corridor "
        "cannot fix the offset along it)",
        minimum=0.0,
    )
    refine_candidates: int = param(
        3,
        unit="",
        doc="the best this many hypotheses are refined; the best refined one wins",
        minimum=1,
    )

    def __post_init__(self) -> None:
        validate(self)

    @property
    def match_distance(self) -> float:
        """Pairs with d(s1, s2) above this contribute nothing (Alg. 4 l. 9)."""
        return self.point_distance_tolerance * self.segment_distance_threshold


@dataclasses.dataclass(frozen=True)
class Lines:
    """Per-segment geometry used everywhere below."""

    direction: FloatArray  # (N, 2) unit vectors
    angle: FloatArray  # (N,) direction angle in [-pi, pi)
    length: FloatArray  # (N,)
    normal_offset: FloatArray  # (N,) c in n . p = c, with n = (-uy, ux)


def lines_of(segments: FloatArray) -> Lines:
    d = segments[:, 2:] - segments[:, :2]
    length = np.hypot(d[:, 0], d[:, 1])
    direction = d / np.maximum(length, 1e-12)[:, None]
    normal_offset = -direction[:, 1] * segments[:, 0] + direction[:, 0] * segments[:, 1]
    return Lines(direction, np.arctan2(direction[:, 1], direction[:, 0]), length, normal_offset)


# --- Landmarks: angles between segment pairs (Alg. 2 l. 2-8 and the heuristics of III-A) ----


@dataclasses.dataclass(frozen=True)
class Landmarks:
    """Ordered segment pairs (i, j): the angle from line i to line j (mod pi) and their vertex."""

    first: IntArray
    second: IntArray
    angle: FloatArray  # (A,) in [0, pi)
    vertex: FloatArray  # (A, 2) intersection of the two supporting lines


def landmarks_from_pairs(
    segments: FloatArray, first: IntArray, second: IntArray, config: IntegrateConfig
) -> Landmarks:
    """Landmarks of the given (i, j) pairs, both orders, dropping near-parallel pairs."""
    i = np.concatenate((first, second)).astype(np.int64)
    j = np.concatenate((second, first)).astype(np.int64)
    keep = i != j
    i, j = i[keep], j[keep]
    lines = lines_of(segments)
    ui, uj = lines.direction[i], lines.direction[j]
    sine = ui[:, 0] * uj[:, 1] - ui[:, 1] * uj[:, 0]
    ok = np.abs(sine) >= np.sin(config.min_landmark_angle)
    i, j, ui, uj, sine = i[ok], j[ok], ui[ok], uj[ok], sine[ok]
    # Intersection of p_i + s u_i and p_j + r u_j.
    pi, pj = segments[i, :2], segments[j, :2]
    delta = pj - pi
    s = (delta[:, 0] * uj[:, 1] - delta[:, 1] * uj[:, 0]) / sine
    vertex = pi + s[:, None] * ui
    angle = np.mod(lines.angle[j] - lines.angle[i], np.pi)
    pairs = np.unique(np.column_stack((i, j)), axis=0, return_index=True)[1]
    return Landmarks(i[pairs], j[pairs], angle[pairs], vertex[pairs])


def consecutive_pairs(
    segments: FloatArray, ordered: bool, config: IntegrateConfig
) -> tuple[IntArray, IntArray]:
    """Heuristic 1: consecutive segments of an ordered scan, both long enough (III-A-1)."""
    n = len(segments)
    if not ordered or n < 2:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    length = lines_of(segments).length
    long_enough = length >= max(
        config.min_segment_length, config.segment_length_percentage / 100.0 * length.max()
    )
    idx = np.flatnonzero(long_enough)
    # Consecutive among the long ones, even without a shared end point (the paper's improvement).
    return idx[:-1], idx[1:]


def random_pairs(
    segments: FloatArray, config: IntegrateConfig, rng: np.random.Generator
) -> tuple[IntArray, IntArray]:
    """Heuristic 2 (Alg. 3): N_k = 20 * 2^k random pairs of segments longer than f^k x longest."""
    length = lines_of(segments).length
    firsts, seconds = [], []
    for k in range(1, config.random_rounds + 1):
        pool = np.flatnonzero(
            length
            >= max(config.min_segment_length, config.segment_division_factor**k * length.max())
        )
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


def histogram_pairs(segments: FloatArray, config: IntegrateConfig) -> tuple[IntArray, IntArray]:
    """Heuristic 3: principal-direction segments x normal-direction segments (III-A-3)."""
    lines = lines_of(segments)
    usable = lines.length >= config.min_segment_length
    slots = config.histogram_slots
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


def all_pairs(segments: FloatArray, config: IntegrateConfig) -> tuple[IntArray, IntArray]:
    """Every pair of usable segments (Alg. 2 as written), for small sets."""
    idx = np.flatnonzero(lines_of(segments).length >= config.min_segment_length)
    a, b = np.triu_indices(idx.size, k=1)
    return idx[a], idx[b]


def landmarks(
    segments: FloatArray,
    heuristics: tuple[str, ...],
    config: IntegrateConfig,
    ordered: bool,
    rng: np.random.Generator,
) -> Landmarks:
    """The landmarks of one segment set under the chosen heuristics (their union)."""
    firsts: list[IntArray] = []
    seconds: list[IntArray] = []
    for name in heuristics:
        if name == "consecutive":
            a, b = consecutive_pairs(segments, ordered, config)
        elif name == "random":
            a, b = random_pairs(segments, config, rng)
        elif name == "histogram":
            a, b = histogram_pairs(segments, config)
        elif name == "all":
            if len(segments) > config.all_pairs_below:
                continue
            a, b = all_pairs(segments, config)
        elif name == "endpoints":
            continue  # pairs of segments across the two sets, see endpoint_hypotheses
        else:
            raise ValueError(f"unknown heuristic {name!r}; choose from {', '.join(HEURISTICS)}")
        firsts.append(a)
        seconds.append(b)
    first = np.concatenate(firsts) if firsts else np.zeros(0, dtype=np.int64)
    second = np.concatenate(seconds) if seconds else np.zeros(0, dtype=np.int64)
    return landmarks_from_pairs(segments, first, second, config)


# --- Hypotheses (Alg. 2 l. 10-14) ----------------------------------------------------------


def hypotheses(
    segments1: FloatArray,
    marks1: Landmarks,
    segments2: FloatArray,
    marks2: Landmarks,
    config: IntegrateConfig,
) -> FloatArray:
    """Every (theta, tx, ty) superimposing an angle of S2 on an equal angle of S1.

    Lines have no sense, so each correspondence gives two rotations, theta and theta + pi;
    the translation maps the S2 vertex onto the S1 vertex.
    """
    if len(marks1.angle) == 0 or len(marks2.angle) == 0:
        return np.zeros((0, 3))
    diff = np.abs(marks1.angle[:, None] - marks2.angle[None, :])
    diff = np.minimum(diff, np.pi - diff)
    a1, a2 = np.nonzero(diff <= config.angle_difference_tolerance)
    if a1.size == 0:
        return np.zeros((0, 3))
    phi1 = lines_of(segments1).angle
    phi2 = lines_of(segments2).angle
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


def endpoint_hypotheses(
    segments1: FloatArray, segments2: FloatArray, config: IntegrateConfig
) -> FloatArray:
    """Hypotheses that lay a long S2 segment on a long S1 segment, end points superimposed.

    Angles need two non-parallel segments; in a corridor every long segment is parallel and
    the angle heuristics find nothing. Aligning one wall with another fixes the rotation (two
    senses) and the offset across the wall; superimposing their ends (a door frame, a wall's
    end) proposes the offset along it, and the evaluation decides which offset is right.
    """
    l1, l2 = lines_of(segments1), lines_of(segments2)
    long1 = np.flatnonzero(
        l1.length >= max(config.min_segment_length, 0.3 * l1.length.max(initial=0.0))
    )
    long2 = np.flatnonzero(
        l2.length >= max(config.min_segment_length, 0.3 * l2.length.max(initial=0.0))
    )
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
    _, first, votes = np.unique(keys, axis=0, return_index=True, return_counts=True)
    order = np.argsort(-votes, kind="stable")[:limit]
    return transforms[first[order]], votes[order]


# --- Evaluation (Alg. 4) ---------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class PairScores:
    """Matching values of candidate (hypothesis, s1, s2) triples with a positive value."""

    hypothesis: IntArray
    first: IntArray  # index into S1
    second: IntArray  # index into S2
    value: FloatArray  # matching value mv (m)
    crossing: BoolArray  # the two segments intersect under the hypothesis


def _candidate_triples(
    lines1: Lines, lines2: Lines, theta: FloatArray, second_subset: IntArray, max_angle: float
) -> tuple[IntArray, IntArray, IntArray]:
    """(h, a, b) whose directions agree within ``max_angle`` (mod pi) under hypothesis h.

    For each segment pair the hypotheses that make it parallel form an interval of theta
    (mod pi): hypotheses sorted by theta mod pi are cut by searchsorted, so the work is
    proportional to the candidates, not to hypotheses x pairs.
    """
    key = np.mod(theta, np.pi)
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    ext_key = np.concatenate((sorted_key - np.pi, sorted_key, sorted_key + np.pi))
    ext_idx = np.concatenate((order, order, order))
    grid_a, grid_b = np.meshgrid(np.arange(len(lines1.angle)), second_subset, indexing="ij")
    a, b = grid_a.ravel(), grid_b.ravel()
    centre = np.mod(lines1.angle[a] - lines2.angle[b], np.pi)
    lo = np.searchsorted(ext_key, centre - max_angle, side="left")
    hi = np.searchsorted(ext_key, centre + max_angle, side="right")
    count = hi - lo
    pair = np.repeat(np.arange(a.size), count)
    start = np.repeat(np.cumsum(count) - count, count)
    position = lo[pair] + np.arange(pair.size) - start
    return ext_idx[position].astype(np.int64), a[pair].astype(np.int64), b[pair].astype(np.int64)


def score_pairs(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    config: IntegrateConfig,
    second_subset: IntArray | None = None,
) -> PairScores:
    """Matching value of every candidate triple (Alg. 4 l. 5-19), all hypotheses at once.

    mv = (l1 + l2) / 2 where l1 is the overlap of s2 projected on s1's line with s1 and l2 the
    converse; pairs whose distance d (Amigoni's, after Lu & Milios: the min over the two
    segments of the max distance of the other's end points to its line) exceeds
    ``match_distance`` score 0; pairs that do not intersect are penalised by 0.95^(d/tol).
    """
    lines1, lines2 = lines_of(segments1), lines_of(segments2)
    subset = np.arange(len(segments2)) if second_subset is None else second_subset
    empty = PairScores(*(np.zeros(0, dtype=np.int64),) * 3, np.zeros(0), np.zeros(0, dtype=bool))
    if len(transforms) == 0 or len(segments1) == 0 or len(subset) == 0:
        return empty
    h, a, b = _candidate_triples(lines1, lines2, transforms[:, 0], subset, config.max_match_angle)
    if h.size == 0:
        return empty
    c, s = np.cos(transforms[h, 0]), np.sin(transforms[h, 0])
    tx, ty = transforms[h, 1], transforms[h, 2]
    # S2 end points and direction under the hypothesis.
    q1x = c * segments2[b, 0] - s * segments2[b, 1] + tx
    q1y = s * segments2[b, 0] + c * segments2[b, 1] + ty
    q2x = c * segments2[b, 2] - s * segments2[b, 3] + tx
    q2y = s * segments2[b, 2] + c * segments2[b, 3] + ty
    vx = c * lines2.direction[b, 0] - s * lines2.direction[b, 1]
    vy = s * lines2.direction[b, 0] + c * lines2.direction[b, 1]
    ux, uy = lines1.direction[a, 0], lines1.direction[a, 1]
    e1x, e1y, e2x, e2y = segments1[a, 0], segments1[a, 1], segments1[a, 2], segments1[a, 3]
    # Distances of each segment's end points to the other's supporting line.
    ca = lines1.normal_offset[a]
    dq1 = np.abs(-uy * q1x + ux * q1y - ca)
    dq2 = np.abs(-uy * q2x + ux * q2y - ca)
    cb = -vy * q1x + vx * q1y
    de1 = np.abs(-vy * e1x + vx * e1y - cb)
    de2 = np.abs(-vy * e2x + vx * e2y - cb)
    d = np.minimum(np.maximum(dq1, dq2), np.maximum(de1, de2))
    near = d <= config.match_distance
    # Overlaps along each line (s1 runs from e1 to e2 along u; s2 from q1 to q2 along v).
    sa1 = ux * e1x + uy * e1y
    sq1 = ux * q1x + uy * q1y
    sq2 = ux * q2x + uy * q2y
    l1 = np.clip(
        np.minimum(sa1 + lines1.length[a], np.maximum(sq1, sq2))
        - np.maximum(sa1, np.minimum(sq1, sq2)),
        0.0,
        None,
    )
    sb1 = vx * q1x + vy * q1y
    se1 = vx * e1x + vy * e1y
    se2_ = vx * e2x + vy * e2y
    l2 = np.clip(
        np.minimum(sb1 + lines2.length[b], np.maximum(se1, se2_))
        - np.maximum(sb1, np.minimum(se1, se2_)),
        0.0,
        None,
    )
    crossing = _segments_cross(e1x, e1y, e2x, e2y, q1x, q1y, q2x, q2y)
    penalty = np.where(crossing, 1.0, 0.95 ** (d / config.point_distance_tolerance))
    value = 0.5 * (l1 + l2) * penalty
    keep = near & (value > 0.0)
    return PairScores(h[keep], a[keep], b[keep], value[keep], crossing[keep])


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


def refused(
    segments1: FloatArray, segments2: FloatArray, transforms: FloatArray, config: IntegrateConfig
) -> BoolArray:
    """Hypotheses that make a long S1 segment cross a long S2 segment (Alg. 4 l. 6-7).

    Only a proper crossing counts: the crossing point must lie at least ``crossing_margin``
    inside both segments, since walls that meet at a corner or a T-junction touch without
    contradicting each other, and two walls crossing at a shallow angle are one wall slightly
    misaligned.
    """
    lines1, lines2 = lines_of(segments1), lines_of(segments2)
    long1 = np.flatnonzero(lines1.length > config.segment_length_refuse)
    long2 = np.flatnonzero(lines2.length > config.segment_length_refuse)
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
    steep = np.abs(sine) > np.sin(config.min_landmark_angle)
    safe = np.where(steep, sine, 1.0)
    dx, dy = qx - segments1[a, 0], qy - segments1[a, 1]
    along_a = (dx * vy - dy * vx) / safe  # distance from s1's start to the crossing
    along_b = (dx * uy - dy * ux) / safe  # distance from s2's start to the crossing
    margin = config.crossing_margin
    inside = (
        (along_a > margin)
        & (along_a < lines1.length[a] - margin)
        & (along_b > margin)
        & (along_b < lines2.length[b] - margin)
    )
    np.logical_or.at(out, h, steep & inside)
    return out


def transform_values(scores: PairScores, count: int) -> FloatArray:
    """The value of each hypothesis: the sum of its pairs' matching values (Alg. 4 l. 18)."""
    return np.bincount(scores.hypothesis, weights=scores.value, minlength=count).astype(np.float64)


# --- INTEGRATE (Alg. 1): hypotheses, pruned evaluation, refinement, validity -----------------


@dataclasses.dataclass(frozen=True)
class MatchResult:
    """The best transformation of S2 onto S1 and how much to trust it."""

    T_1_2: FloatArray  # (3,) theta, tx, ty
    value: float  # overlap length of matching segments under T_1_2 (m)
    fraction: float  # net value (overlap minus length seen through) / shorter set's length
    valid: bool  # passes min_match_value and min_match_fraction
    hypotheses: int  # distinct hypotheses generated
    evaluated: int  # hypotheses fully evaluated after pruning

    @property
    def matrix(self) -> FloatArray:
        return se2.matrix_from_pose(
            float(self.T_1_2[1]), float(self.T_1_2[2]), float(self.T_1_2[0])
        )


def integrate(
    segments1: FloatArray,
    segments2: FloatArray,
    config: IntegrateConfig,
    heuristics: tuple[str, ...] = HEURISTICS,
    ordered: tuple[bool, bool] = (True, True),
    extra_hypotheses: FloatArray | None = None,
    views: tuple[LaserScanData | None, LaserScanData | None] = (None, None),
) -> MatchResult:
    """Find how S2 lies in S1's frame with no initial guess (INTEGRATE steps 1-2).

    ``views`` are the scans each set was seen in, in its own frame, when known. Overlap length
    cannot tell a corridor's true motion from standing still (the visible stretch of wall moves
    with the robot); free space can: under a wrong hypothesis one scan's walls lie where the
    other scan's beams passed. With views, the best candidates are refined and ranked by
    overlap minus ``free_space_weight`` times the length seen through.
    """
    rng = np.random.default_rng(config.seed)
    total1 = float(lines_of(segments1).length.sum()) if len(segments1) else 0.0
    total2 = float(lines_of(segments2).length.sum()) if len(segments2) else 0.0
    shorter = max(min(total1, total2), 1e-9)
    marks1 = (
        landmarks(segments1, heuristics, config, ordered[0], rng) if len(segments1) > 1 else None
    )
    marks2 = (
        landmarks(segments2, heuristics, config, ordered[1], rng) if len(segments2) > 1 else None
    )
    raw = (
        hypotheses(segments1, marks1, segments2, marks2, config)
        if marks1 is not None and marks2 is not None
        else np.zeros((0, 3))
    )
    if "endpoints" in heuristics and len(segments1) and len(segments2):
        raw = np.vstack((raw, endpoint_hypotheses(segments1, segments2, config)))
    if extra_hypotheses is not None and len(extra_hypotheses):
        raw = np.vstack((np.asarray(extra_hypotheses, dtype=np.float64).reshape(-1, 3), raw))
    transforms, _ = distinct_hypotheses(raw, np.radians(0.5), 0.02, config.max_hypotheses)
    if len(transforms) == 0:
        return MatchResult(np.zeros(3), 0.0, 0.0, False, 0, 0)
    values, evaluated = _pruned_values(segments1, segments2, transforms, config, total2)
    # Best hypotheses first; a refused one (long walls crossing) is skipped (Alg. 4 l. 6-7).
    order = np.argsort(-values, kind="stable")
    candidates: list[int] = []
    for start in range(0, len(order), 32):
        batch = order[start : start + 32]
        batch = batch[values[batch] > 0.0]
        if batch.size == 0:
            break
        ok = ~refused(segments1, segments2, transforms[batch], config)
        candidates.extend(int(i) for i in batch[ok])
        if len(candidates) >= config.refine_candidates:
            break
    if not candidates:
        return MatchResult(np.zeros(3), 0.0, 0.0, False, len(transforms), evaluated)
    best_T, best_value = transforms[candidates[0]], float(values[candidates[0]])
    best_score = best_value - _seen_through(segments1, segments2, best_T, views, config)
    for index in candidates[: config.refine_candidates]:
        refined_T = refine(segments1, segments2, transforms[index], config)
        refined_value = float(
            transform_values(score_pairs(segments1, segments2, refined_T[None, :], config), 1)[0]
        )
        score = refined_value - _seen_through(segments1, segments2, refined_T, views, config)
        if score > best_score and not refused(segments1, segments2, refined_T[None, :], config)[0]:
            best_T, best_value, best_score = refined_T, refined_value, score
    # Validity on the net value: overlap that the other scan's free space contradicts counts
    # against it (two unrelated rectilinear places easily overlap by a third).
    fraction = best_score / shorter
    valid = (
        best_score >= config.min_match_value
        and fraction >= config.min_match_fraction
        and cross_support(segments1, segments2, best_T, config) >= config.min_cross_support
    )
    return MatchResult(best_T.copy(), best_value, fraction, bool(valid), len(transforms), evaluated)


def cross_support(
    segments1: FloatArray, segments2: FloatArray, T_1_2: FloatArray, config: IntegrateConfig
) -> float:
    """Matched length in the least constrained direction: the smallest eigenvalue of the sum
    of matching value x n n^T over matched pairs (n the S1 line's normal). Zero when every
    matched wall is parallel, so the offset along them rests on where walls happen to end."""
    scores = score_pairs(segments1, segments2, T_1_2[None, :], config)
    if scores.first.size == 0:
        return 0.0
    u = lines_of(segments1).direction[scores.first]
    nx, ny, w = -u[:, 1], u[:, 0], scores.value
    info = np.array(
        [[np.sum(w * nx * nx), np.sum(w * nx * ny)], [np.sum(w * nx * ny), np.sum(w * ny * ny)]]
    )
    return float(np.linalg.eigvalsh(info)[0])


def _pruned_values(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    config: IntegrateConfig,
    total2: float,
) -> tuple[FloatArray, int]:
    """Values of all hypotheses, skipping the ones that cannot beat the best (Amigoni III-B).

    The long S2 segments are scored first for every hypothesis; a hypothesis whose partial
    value plus the length of the S2 segments not yet scored stays below the best partial
    value cannot become the best, so only the others are scored on the short segments.
    """
    length2 = lines_of(segments2).length
    by_length = np.argsort(-length2, kind="stable")
    covered = np.cumsum(length2[by_length])
    head = max(1, int(np.searchsorted(covered, 0.6 * total2)) + 1)
    first, rest = by_length[:head], by_length[head:]
    values = transform_values(
        score_pairs(segments1, segments2, transforms, config, first), len(transforms)
    )
    if rest.size == 0:
        return values, len(transforms)
    bound = values + float(length2[rest].sum())
    alive = np.flatnonzero(bound >= values.max())
    tail = score_pairs(segments1, segments2, transforms[alive], config, rest)
    values[alive] += transform_values(tail, len(alive))
    values[np.setdiff1d(np.arange(len(transforms)), alive)] = 0.0
    return values, len(alive)


def refine(
    segments1: FloatArray, segments2: FloatArray, T_1_2: FloatArray, config: IntegrateConfig
) -> FloatArray:
    """Point-to-line least squares (Cox; Wolter 5.1) from ``T_1_2``, iterated to convergence.

    Points sampled along S2 (every 5 cm) are pulled onto the lines of the S1 segments they
    match under the current estimate (matching pairs of Alg. 4, nearest line per point, points
    projecting onto that segment only); a Gauss-Newton step solves the 3x3 normal equations.
    """
    points, owner = sample_segments(segments2, 0.05)
    lines1 = lines_of(segments1)
    T = np.asarray(T_1_2, dtype=np.float64).copy()
    for _ in range(config.refine_iterations):
        scores = score_pairs(segments1, segments2, T[None, :], config)
        if scores.first.size == 0:
            break
        # Every sampled point of each matched S2 segment, paired with each S1 segment it matched.
        pair_a, pair_b = scores.first, scores.second
        take = np.isin(owner, pair_b)
        idx = np.flatnonzero(take)
        # Expand (point, pair) for pairs sharing the point's segment.
        order = np.argsort(pair_b, kind="stable")
        pb_sorted = pair_b[order]
        lo = np.searchsorted(pb_sorted, owner[idx], side="left")
        hi = np.searchsorted(pb_sorted, owner[idx], side="right")
        count = hi - lo
        point = np.repeat(idx, count)
        pos = (
            np.repeat(lo, count)
            + np.arange(point.size)
            - np.repeat(np.cumsum(count) - count, count)
        )
        a = pair_a[order[pos]]
        c, s = np.cos(T[0]), np.sin(T[0])
        px, py = points[point, 0], points[point, 1]
        qx, qy = c * px - s * py + T[1], s * px + c * py + T[2]
        ux, uy = lines1.direction[a, 0], lines1.direction[a, 1]
        residual = -uy * qx + ux * qy - lines1.normal_offset[a]
        along = ux * (qx - segments1[a, 0]) + uy * (qy - segments1[a, 1])
        inside = (along >= -0.1) & (along <= lines1.length[a] + 0.1)
        near = inside & (np.abs(residual) <= config.match_distance)
        if not near.any():
            break
        point, a, residual, px, py = point[near], a[near], residual[near], px[near], py[near]
        ux, uy = ux[near], uy[near]
        # Nearest matched line per point.
        pick = np.lexsort((np.abs(residual), point))
        first_of = np.concatenate(([True], point[pick][1:] != point[pick][:-1]))
        sel = pick[first_of]
        r, nx, ny = residual[sel], -uy[sel], ux[sel]
        # d q / d theta = (-(s px + c py), c px - s py)
        dqx = -(s * px[sel] + c * py[sel])
        dqy = c * px[sel] - s * py[sel]
        J = np.column_stack((nx * dqx + ny * dqy, nx, ny))
        H = J.T @ J
        if np.linalg.cond(H) > 1e8:
            break  # all matched lines parallel: the step along them is not observable
        step = -np.linalg.solve(H, J.T @ r)
        T += step
        if abs(step[0]) < 1e-5 and np.hypot(step[1], step[2]) < 1e-4:
            break
    T[0] = float(se2.wrap_angle(T[0]))
    return T


def sample_segments(segments: FloatArray, spacing: float) -> tuple[FloatArray, IntArray]:
    """Points every ``spacing`` metres along each segment (ends included) and their segment."""
    length = lines_of(segments).length
    count = np.maximum(2, np.ceil(length / spacing).astype(np.int64) + 1)
    owner = np.repeat(np.arange(len(segments)), count)
    start = np.repeat(np.cumsum(count) - count, count)
    t = (np.arange(owner.size) - start) / (count[owner] - 1)
    pts = segments[owner, :2] + t[:, None] * (segments[owner, 2:] - segments[owner, :2])
    return pts, owner.astype(np.int64)


# --- Free-space consistency --------------------------------------------------------------------


def seen_through(view: LaserScanData, points: FloatArray, margin: float) -> BoolArray:
    """Points (in the view's laser frame) lying in free space that the view's beams crossed.

    A point is seen through when the beam nearest its bearing returned from more than
    ``margin`` beyond it; beams without a valid return say nothing.
    """
    ranges = np.asarray(view.ranges, dtype=np.float64)
    bearing = np.arctan2(points[:, 1], points[:, 0])
    distance = np.hypot(points[:, 0], points[:, 1])
    beam = np.rint((bearing - view.angle_min) / view.angle_increment).astype(np.int64)
    inside = (beam >= 0) & (beam < ranges.size)
    measured = np.full(len(points), np.nan)
    measured[inside] = ranges[beam[inside]]
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(measured) & (measured >= view.range_min) & (measured < view.range_max)
        return np.asarray(valid & (distance < measured - margin))


def _seen_through(
    segments1: FloatArray,
    segments2: FloatArray,
    T_1_2: FloatArray,
    views: tuple[LaserScanData | None, LaserScanData | None],
    config: IntegrateConfig,
) -> float:
    """Weighted length of each set lying in the other's observed free space under ``T_1_2``."""
    view1, view2 = views
    if view1 is None and view2 is None:
        return 0.0
    spacing = 0.05
    T = se2.matrix_from_pose(float(T_1_2[1]), float(T_1_2[2]), float(T_1_2[0]))
    count = 0
    if view1 is not None and len(segments2):
        points2, _ = sample_segments(segments2, spacing)
        moved = se2.transform_points(T, points2)
        count += int(np.count_nonzero(seen_through(view1, moved, config.free_space_margin)))
    if view2 is not None and len(segments1):
        points1, _ = sample_segments(segments1, spacing)
        moved = se2.transform_points(se2.invert(T), points1)
        count += int(np.count_nonzero(seen_through(view2, moved, config.free_space_margin)))
    return config.free_space_weight * spacing * count
