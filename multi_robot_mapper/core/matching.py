"""Pipeline stage 3: how two segment sets fit together, with no initial guess (INTEGRATE).

Amigoni, Gasparini & Gini 2006, Sec. III: angles between pairs of segments are geometric
landmarks; every rototranslation that superimposes an angle of S2 on an equal angle of S1 is a
hypothesis (Algorithm 2, with the heuristics of III-A that choose which angles); each
hypothesis is scored by the overlap length of matching segments (Algorithm 4). Then, beyond
the paper: the best few distinct hypotheses are refined by point-to-line least squares (Cox,
as in Wolter 5.1), corridor-like ones are also slid along their free direction, and the
winner is the one the two scans' beams agree with best (overlap, minus what one scan saw
through, plus what its beams confirm). Overlap alone cannot tell a corridor's true motion from
standing still, nor a scan from its mirror image behind the robot.

All of it is array code: landmarks x landmarks for hypotheses, and hypotheses x segments x
segments for the evaluation, restricted early to the nearly parallel triples that can score
and, with many hypotheses, to the few that a cheap prescreen on the longest segments ranks
best. Transforms are ``(theta, tx, ty)`` rows: ``T_1_2`` maps S2 coordinates into S1's frame.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.scan import LaserScanData, scan_points

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# A refined slid hypothesis replaces the slid one unless its net score is this much lower (m):
# the slide grid is coarse, the refinement is the precise answer.
_POLISH_TOLERANCE = 0.25

# The prescreen's rough cut (half the segments) keeps this many times candidate_pool.
_ROUGH_CUT = 10

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
        20000,
        unit="",
        doc="at most this many distinct hypotheses (most voted first) are prescreened",
        minimum=1,
    )
    hypothesis_angle_cell: float = param(
        0.0087,
        unit="rad",
        doc="hypotheses in the same (angle, x, y) cell are one (the most voted cells first)",
        minimum=0.0,
        exclusive_minimum=True,
    )
    hypothesis_distance_cell: float = param(
        0.02,
        unit="m",
        doc="translation size of the cells that merge hypotheses",
        minimum=0.0,
        exclusive_minimum=True,
    )
    refine_iterations: int = param(
        6,
        unit="",
        doc="Gauss-Newton iterations of the least-squares refinement of each candidate (0: none)",
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
        12,
        unit="",
        doc="the best this many distinct hypotheses are refined; the best net score wins",
        minimum=1,
    )

    free_space_spread: int = param(
        1,
        unit="beams",
        doc="a point is seen through only if the beams this many either side passed it too",
        minimum=0,
    )
    free_space_min_length: float = param(
        0.3,
        unit="m",
        doc="with one view only, segments shorter than this (people) are not tested",
        minimum=0.0,
    )
    view_point_length: float = param(
        0.3,
        unit="m",
        doc="with both views, one return stands for at most this much surface",
        minimum=0.0,
        exclusive_minimum=True,
    )
    confirmed_weight: float = param(
        3.0,
        unit="",
        doc="metres of score one metre of a scan that the other scan's beams end on adds when "
        "candidates are ranked (a wrong transform puts one scan where the other never looked)",
        minimum=0.0,
    )
    cross_support_weight: float = param(
        5.0,
        unit="",
        doc="metres of score one metre of cross support adds when candidates are ranked",
        minimum=0.0,
    )
    slide_candidates: int = param(
        3,
        unit="",
        doc="this many best candidates are slid along the direction their walls leave free",
        minimum=0,
    )
    slide_below_support: float = param(
        1.0,
        unit="m",
        doc="only candidates with less cross support than this are slid",
        minimum=0.0,
    )
    slide_range: float = param(1.5, unit="m", doc="slides go this far either way", minimum=0.0)
    slide_step: float = param(
        0.1,
        unit="m",
        doc="slides are tried every this far",
        minimum=0.0,
        exclusive_minimum=True,
    )
    candidate_pool: int = param(
        100,
        unit="",
        doc="this many prescreened hypotheses are evaluated in full (Alg. 4) and searched for "
        "distinct candidates",
        minimum=1,
    )
    prescreen_segments: int = param(
        16,
        unit="segments",
        doc="with more than candidate_pool hypotheses, all are first valued on this many "
        "longest segments of each set; the candidate_pool best are evaluated in full",
        minimum=1,
    )
    prescreen_match_angle: float = param(
        0.1,
        unit="rad",
        doc="in the prescreen, segments whose directions differ more than this never match",
        minimum=0.0,
        exclusive_minimum=True,
        maximum=1.5,
    )
    candidate_separation: float = param(
        0.4,
        unit="m",
        doc="candidates closer than this (and candidate_angle_separation) are one answer",
        minimum=0.0,
    )
    candidate_angle_separation: float = param(
        0.05,
        unit="rad",
        doc="candidates turned less than this (and candidate_separation) are one answer",
        minimum=0.0,
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
    # One int64 per cell (1-D unique is several times faster than unique rows).
    span = 1 << 24
    code = (keys[:, 0] * span + (keys[:, 1] % span)) * span + (keys[:, 2] % span)
    _, first, votes = np.unique(code, return_index=True, return_counts=True)
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
    cos_h, sin_h = np.cos(transforms[:, 0]), np.sin(transforms[:, 0])
    c, s = cos_h[h], sin_h[h]
    tx, ty = transforms[h, 1], transforms[h, 2]
    # S2 end points under the hypothesis, and their distances to s1's line (Alg. 4 l. 9).
    q1x = c * segments2[b, 0] - s * segments2[b, 1] + tx
    q1y = s * segments2[b, 0] + c * segments2[b, 1] + ty
    q2x = c * segments2[b, 2] - s * segments2[b, 3] + tx
    q2y = s * segments2[b, 2] + c * segments2[b, 3] + ty
    ux, uy = lines1.direction[a, 0], lines1.direction[a, 1]
    ca = lines1.normal_offset[a]
    dq = np.maximum(np.abs(-uy * q1x + ux * q1y - ca), np.abs(-uy * q2x + ux * q2y - ca))
    vx = c * lines2.direction[b, 0] - s * lines2.direction[b, 1]
    vy = s * lines2.direction[b, 0] + c * lines2.direction[b, 1]
    e1x, e1y, e2x, e2y = segments1[a, 0], segments1[a, 1], segments1[a, 2], segments1[a, 3]
    cb = -vy * q1x + vx * q1y
    de = np.maximum(np.abs(-vy * e1x + vx * e1y - cb), np.abs(-vy * e2x + vx * e2y - cb))
    d = np.minimum(dq, de)
    # Most candidate triples are far apart: drop them before the overlap arithmetic.
    near = np.flatnonzero(d <= config.match_distance)
    h, a, b, d = h[near], a[near], b[near], d[near]
    q1x, q1y, q2x, q2y = q1x[near], q1y[near], q2x[near], q2y[near]
    ux, uy, vx, vy = ux[near], uy[near], vx[near], vy[near]
    e1x, e1y, e2x, e2y = e1x[near], e1y[near], e2x[near], e2y[near]
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
    keep = value > 0.0
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
    # The grid is hypothesis-major: each hypothesis owns one contiguous block of pairs.
    return np.asarray((steep & inside).reshape(len(transforms), -1).any(axis=1))


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
    hypothesis_sets: tuple[FloatArray, FloatArray] | None = None,
) -> MatchResult:
    """Find how S2 lies in S1's frame with no initial guess (INTEGRATE steps 1-2).

    ``hypothesis_sets`` (same frames as S1 and S2) are the sets whose landmarks generate the
    hypotheses when they differ from the sets evaluated: a local mapper draws hypotheses from
    the last keyframe's scan (few segments, few landmarks) and evaluates them on the partial
    map around it (every wall seen nearby).

    ``views`` are the scans each set was seen in, in its own frame, when known. Overlap length
    cannot tell a corridor's true motion from standing still (the visible stretch of wall moves
    with the robot); the beams can: under a wrong hypothesis one scan's walls lie where the
    other scan's beams passed (seen through), and few of its returns lie where the other's
    beams ended (confirmed). The ``refine_candidates`` best distinct hypotheses are refined
    and ranked by overlap - ``free_space_weight`` x seen through + ``confirmed_weight`` x
    confirmed + ``cross_support_weight`` x cross support (without views: overlap and cross
    support). Validity uses overlap minus seen through only.

    Steps: hypotheses (Alg. 2 and the heuristics of III-A); values (Alg. 4 l. 5-19, after a
    prescreen when there are many); the best distinct ones, refused ones dropped (Alg. 4
    l. 6-7, 20-23); refinement; slides along corridors; the best net score wins.
    """
    rng = np.random.default_rng(config.seed)
    total1 = float(lines_of(segments1).length.sum()) if len(segments1) else 0.0
    total2 = float(lines_of(segments2).length.sum()) if len(segments2) else 0.0
    shorter = max(min(total1, total2), 1e-9)
    source1, source2 = (segments1, segments2) if hypothesis_sets is None else hypothesis_sets
    marks1 = landmarks(source1, heuristics, config, ordered[0], rng) if len(source1) > 1 else None
    marks2 = landmarks(source2, heuristics, config, ordered[1], rng) if len(source2) > 1 else None
    raw = (
        hypotheses(source1, marks1, source2, marks2, config)
        if marks1 is not None and marks2 is not None
        else np.zeros((0, 3))
    )
    if "endpoints" in heuristics and len(source1) and len(source2):
        raw = np.vstack((raw, endpoint_hypotheses(source1, source2, config)))
    transforms, _ = distinct_hypotheses(
        raw, config.hypothesis_angle_cell, config.hypothesis_distance_cell, config.max_hypotheses
    )
    # Extra hypotheses (predictions) come first and are always evaluated in full.
    extra = (
        np.zeros((0, 3))
        if extra_hypotheses is None
        else np.asarray(extra_hypotheses, dtype=np.float64).reshape(-1, 3)
    )
    transforms = np.vstack((extra, transforms))
    if len(transforms) == 0:
        return MatchResult(np.zeros(3), 0.0, 0.0, False, 0, 0)
    values, evaluated = _pruned_values(segments1, segments2, transforms, config, len(extra))
    # Alg. 4 l. 20-23 (keep the best), widened: the best few DISTINCT hypotheses are refused
    # (l. 6-7) or refined, then ranked by their net score (overlap and the scans' beams).
    candidates = _distinct_candidates(segments1, segments2, transforms, values, config)
    if candidates.size == 0:
        return MatchResult(np.zeros(3), 0.0, 0.0, False, len(transforms), evaluated)
    refined = refine_many(segments1, segments2, transforms[candidates], config)
    refined_values, scores, support, slide = _net_scores(
        segments1, segments2, refined, views, config
    )
    if config.refine_iterations > 0:
        # A refinement that slid into a crossing (or lost its overlap) falls back to the
        # unrefined hypothesis, which passed the refusal test.
        bad = refused(segments1, segments2, refined, config) | (refined_values <= 0.0)
        if bad.any():
            refined[bad] = transforms[candidates[bad]]
            refined_values[bad], scores[bad], support[bad], slide[bad] = _net_scores(
                segments1, segments2, refined[bad], views, config
            )
    slid, slid_values, slid_scores = _slide(
        segments1, segments2, refined, scores, support, slide, views, config
    )
    refined = np.vstack((refined, slid))
    refined_values = np.concatenate((refined_values, slid_values))
    scores = np.concatenate((scores, slid_scores))
    pick = int(np.argmax(scores))
    if pick >= len(candidates) and config.refine_iterations > 0:
        # A slid hypothesis sits on a grid along the corridor: refine it too (the damped
        # steps leave it where it is along a bare corridor).
        polished = refine_many(segments1, segments2, refined[pick : pick + 1], config)
        polished_value, polished_score, _, _ = _net_scores(
            segments1, segments2, polished, views, config
        )
        if (
            polished_score[0] >= scores[pick] - _POLISH_TOLERANCE
            and not refused(segments1, segments2, polished, config)[0]
        ):
            refined[pick], refined_values[pick] = polished[0], polished_value[0]
    best_T, best_value = refined[pick], float(refined_values[pick])
    # Validity on the net value: overlap that the other scan's free space contradicts counts
    # against it (two unrelated rectilinear places easily overlap by a third).
    through, _ = _seen_through_many(segments1, segments2, best_T[None, :], views, config)
    best_score = best_value - config.free_space_weight * float(through[0])
    fraction = best_score / shorter
    valid = (
        best_score >= config.min_match_value
        and fraction >= config.min_match_fraction
        and cross_support(segments1, segments2, best_T, config) >= config.min_cross_support
    )
    return MatchResult(best_T.copy(), best_value, fraction, bool(valid), len(transforms), evaluated)


def _slide(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    scores: FloatArray,
    support: FloatArray,
    direction: FloatArray,
    views: tuple[LaserScanData | None, LaserScanData | None],
    config: IntegrateConfig,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Hypotheses slid along the direction their matched walls leave free, with their values
    and net scores.

    In a corridor every wall is parallel: no angle fixes the offset along it and end points
    rarely do, so the true offset may be missing from the hypotheses. The best
    ``slide_candidates`` candidates whose cross support is below ``slide_below_support`` are
    tried at every ``slide_step`` within ``slide_range`` along that direction; free space
    (what each scan saw down the corridor) tells the offsets apart. Refused ones are dropped.
    """
    top = np.argsort(-scores, kind="stable")[: config.slide_candidates]
    top = top[support[top] < config.slide_below_support]
    if top.size == 0 or config.slide_range <= 0.0:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0)
    offsets = np.arange(-config.slide_range, config.slide_range + 1e-9, config.slide_step)
    offsets = offsets[np.abs(offsets) > 1e-9]
    shifted = np.repeat(transforms[top], offsets.size, axis=0)
    step = np.tile(offsets, top.size)
    shifted[:, 1] += step * np.repeat(direction[top, 0], offsets.size)
    shifted[:, 2] += step * np.repeat(direction[top, 1], offsets.size)
    keep = ~refused(segments1, segments2, shifted, config)
    shifted = shifted[keep]
    values, net, _, _ = _net_scores(segments1, segments2, shifted, views, config)
    return shifted, values, net


def _net_scores(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    views: tuple[LaserScanData | None, LaserScanData | None],
    config: IntegrateConfig,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Value, net score, cross support and least constrained direction of each transform.

    The net score is the overlap (Alg. 4 l. 18) minus the length seen through in the other
    scan's free space plus ``cross_support_weight`` x the cross support: in a corridor the
    overlap of the long walls barely changes with the offset along them (standing still even
    wins, the visible stretch of wall moving with the robot), and what tells the offsets
    apart is the little that crosses the corridor (door jambs, its end).
    """
    scores = score_pairs(segments1, segments2, transforms, config)
    count = len(transforms)
    values = transform_values(scores, count)
    support, direction = _information(segments1, scores, count)
    through, confirmed = _seen_through_many(segments1, segments2, transforms, views, config)
    net = (
        values
        - config.free_space_weight * through
        + config.confirmed_weight * confirmed
        + config.cross_support_weight * support
    )
    return values, net, support, direction


def _information(
    segments1: FloatArray, scores: PairScores, count: int
) -> tuple[FloatArray, FloatArray]:
    """Per hypothesis: smallest eigenvalue of sum(value n n^T) and its eigenvector (the
    direction matched walls constrain least, along a corridor)."""
    if scores.first.size == 0:
        return np.zeros(count), np.tile([1.0, 0.0], (count, 1))
    u = lines_of(segments1).direction[scores.first]
    nx, ny, w, h = -u[:, 1], u[:, 0], scores.value, scores.hypothesis
    sxx = np.bincount(h, weights=w * nx * nx, minlength=count)
    sxy = np.bincount(h, weights=w * nx * ny, minlength=count)
    syy = np.bincount(h, weights=w * ny * ny, minlength=count)
    half_trace = 0.5 * (sxx + syy)
    radius = np.hypot(0.5 * (sxx - syy), sxy)
    major = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # the dominant normal
    direction = np.column_stack((-np.sin(major), np.cos(major)))
    return np.asarray(np.maximum(half_trace - radius, 0.0), dtype=np.float64), direction


def _distinct_candidates(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    values: FloatArray,
    config: IntegrateConfig,
    limit: int | None = None,
) -> IntArray:
    """Indices of the best ``limit`` (``refine_candidates``) hypotheses, near-duplicates
    suppressed.

    Hypotheses are taken best first (Alg. 4 l. 20-23); one within ``candidate_separation``
    (and ``candidate_angle_separation``) of a hypothesis already taken is the same answer
    and is skipped; a refused one (long walls crossing, Alg. 4 l. 6-7) is skipped too.
    """
    order = np.argsort(-values, kind="stable")
    order = order[values[order] > 0.0][: config.candidate_pool]
    if order.size == 0:
        return order
    pool = transforms[order]
    free = np.ones(len(order), dtype=bool)
    allowed = np.zeros(len(order), dtype=bool)
    checked, chunk = 0, 8  # the refusal test runs on the pool best first, in growing chunks
    taken: list[int] = []
    limit = config.refine_candidates if limit is None else limit
    while len(taken) < limit and free.any():
        k = int(np.argmax(free))  # best remaining, the pool being sorted
        if k >= checked:
            end = min(len(order), k + chunk)
            allowed[k:end] = ~refused(segments1, segments2, pool[k:end], config)
            checked, chunk = end, 2 * chunk
        if not allowed[k]:
            free[k] = False
            continue
        taken.append(int(order[k]))
        turn = np.abs(se2.wrap_angle(pool[:, 0] - pool[k, 0]))
        shift = np.hypot(pool[:, 1] - pool[k, 1], pool[:, 2] - pool[k, 2])
        free &= (turn > config.candidate_angle_separation) | (shift > config.candidate_separation)
    return np.asarray(taken, dtype=np.int64)


def cross_support(
    segments1: FloatArray, segments2: FloatArray, T_1_2: FloatArray, config: IntegrateConfig
) -> float:
    """Matched length in the least constrained direction: the smallest eigenvalue of the sum
    of matching value x n n^T over matched pairs (n the S1 line's normal). Zero when every
    matched wall is parallel, so the offset along them rests on where walls happen to end."""
    T = np.asarray(T_1_2, dtype=np.float64).reshape(1, 3)
    return float(_cross_support_many(segments1, segments2, T, config)[0])


def _cross_support_many(
    segments1: FloatArray, segments2: FloatArray, transforms: FloatArray, config: IntegrateConfig
) -> FloatArray:
    """:func:`cross_support` of each transform (closed-form 2x2 eigenvalue, no loop)."""
    scores = score_pairs(segments1, segments2, transforms, config)
    count = len(transforms)
    if scores.first.size == 0:
        return np.zeros(count)
    u = lines_of(segments1).direction[scores.first]
    nx, ny, w, h = -u[:, 1], u[:, 0], scores.value, scores.hypothesis
    sxx = np.bincount(h, weights=w * nx * nx, minlength=count)
    sxy = np.bincount(h, weights=w * nx * ny, minlength=count)
    syy = np.bincount(h, weights=w * ny * ny, minlength=count)
    half_trace = 0.5 * (sxx + syy)
    radius = np.hypot(0.5 * (sxx - syy), sxy)
    return np.asarray(np.maximum(half_trace - radius, 0.0), dtype=np.float64)


def _longest(segments: FloatArray, count: int) -> IntArray:
    """Indices of the ``count`` longest segments."""
    length = lines_of(segments).length
    return np.argsort(-length, kind="stable")[:count].astype(np.int64)


def best_prescreened(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    keep: int,
    segments_used: int,
    config: IntegrateConfig,
) -> IntArray:
    """Indices of the ``keep`` hypotheses (all when fewer) with the best rough value
    (:func:`_prescreen_values`) on the ``segments_used`` longest segments of each set."""
    if len(transforms) <= keep:
        return np.arange(len(transforms), dtype=np.int64)
    long1 = _longest(segments1, segments_used)
    long2 = _longest(segments2, segments_used)
    rough = _prescreen_values(segments1[long1], segments2[long2], transforms, config)
    return np.asarray(np.argpartition(-rough, keep - 1)[:keep], dtype=np.int64)


def _prescreen_values(
    segments1: FloatArray, segments2: FloatArray, transforms: FloatArray, config: IntegrateConfig
) -> FloatArray:
    """A cheap lower-fidelity value of every hypothesis, for ranking only.

    Alg. 4's matching value with half the arithmetic: the S2 segment's end points' distance
    to the S1 line (not the symmetric distance), the overlap along the S1 line only, and no
    crossing test; directions must agree within ``prescreen_match_angle``.
    """
    count = len(transforms)
    if count == 0 or len(segments1) == 0 or len(segments2) == 0:
        return np.zeros(count)
    lines1, lines2 = lines_of(segments1), lines_of(segments2)
    h, a, b = _candidate_triples(
        lines1, lines2, transforms[:, 0], np.arange(len(segments2)), config.prescreen_match_angle
    )
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
    near = np.flatnonzero(d <= config.match_distance)
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
    value = overlap * 0.95 ** (d / config.point_distance_tolerance)
    return np.bincount(h, weights=value, minlength=count).astype(np.float64)


def _pruned_values(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    config: IntegrateConfig,
    forced: int = 0,
) -> tuple[FloatArray, int]:
    """Values of the hypotheses worth a full evaluation, 0 for the others (Amigoni III-B).

    Long segments carry most of a good transformation's value, and the work of Alg. 4 grows
    with hypotheses x segments x segments. When there are more than ``candidate_pool``
    hypotheses, each is first valued roughly (:func:`_prescreen_values`) on the longest
    segments of both sets: half of ``prescreen_segments`` for a rough cut to
    10 x ``candidate_pool``, then ``prescreen_segments``; the ``candidate_pool`` best are
    evaluated in full (Alg. 4 l. 5-19), and so are the first ``forced`` hypotheses.
    """
    count = len(transforms)
    pool = np.arange(forced, count)
    for segments_used, keep in (
        (max(1, config.prescreen_segments // 2), _ROUGH_CUT * config.candidate_pool),
        (config.prescreen_segments, config.candidate_pool),
    ):
        pool = pool[
            best_prescreened(segments1, segments2, transforms[pool], keep, segments_used, config)
        ]
    pool = np.concatenate((np.arange(forced), pool))
    values = np.zeros(count)
    values[pool] = transform_values(
        score_pairs(segments1, segments2, transforms[pool], config), pool.size
    )
    return values, int(pool.size)


def refine(
    segments1: FloatArray, segments2: FloatArray, T_1_2: FloatArray, config: IntegrateConfig
) -> FloatArray:
    """Point-to-line least squares (Cox; Wolter 5.1) from ``T_1_2``; see :func:`refine_many`."""
    T = np.asarray(T_1_2, dtype=np.float64).reshape(1, 3)
    return np.asarray(refine_many(segments1, segments2, T, config)[0], dtype=np.float64)


def refine_many(
    segments1: FloatArray, segments2: FloatArray, transforms: FloatArray, config: IntegrateConfig
) -> FloatArray:
    """Point-to-line least squares (Cox; Wolter 5.1) of several hypotheses at once.

    Each iteration pairs the segments that match under the current estimate (the matching
    pairs of Alg. 4 l. 5-19) and pulls the part of each S2 segment that projects onto its S1
    segment onto that segment's line. The squared point-to-line residual and its Jacobian are
    linear along a segment, so two Gauss points per pair integrate the normal equations
    exactly (before weighting); a Cauchy weight (scale ``point_distance_tolerance``) lets the
    nearer of two parallel candidate lines win. A damped Gauss-Newton step solves each 3x3
    system, so the offset along a bare corridor (not observable) stays where it was.
    ``refine_iterations`` 0 returns the hypotheses unchanged.
    """
    T = np.array(transforms, dtype=np.float64).reshape(-1, 3)
    count = len(T)
    if count == 0 or len(segments1) == 0 or len(segments2) == 0 or config.refine_iterations == 0:
        return T
    lines1, lines2 = lines_of(segments1), lines_of(segments2)
    gauss = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])
    active = np.ones(count, dtype=bool)
    for _ in range(config.refine_iterations):
        live = np.flatnonzero(active)
        if live.size == 0:
            break
        scores = score_pairs(segments1, segments2, T[live], config)
        if scores.first.size == 0:
            break
        h, a, b = scores.hypothesis, scores.first, scores.second
        c, s = np.cos(T[live[h], 0]), np.sin(T[live[h], 0])
        tx, ty = T[live[h], 1], T[live[h], 2]
        ux, uy = lines1.direction[a, 0], lines1.direction[a, 1]
        # Where S2's end points fall along S1's line: the part of s2 over s1.
        p1, p2 = segments2[b, :2], segments2[b, 2:]
        t1 = ux * (c * p1[:, 0] - s * p1[:, 1] + tx - segments1[a, 0]) + uy * (
            s * p1[:, 0] + c * p1[:, 1] + ty - segments1[a, 1]
        )
        t2 = ux * (c * p2[:, 0] - s * p2[:, 1] + tx - segments1[a, 0]) + uy * (
            s * p2[:, 0] + c * p2[:, 1] + ty - segments1[a, 1]
        )
        span = np.where(np.abs(t2 - t1) > 1e-9, t2 - t1, 1e-9)
        lo = np.clip(np.minimum(-t1 / span, (lines1.length[a] - t1) / span), 0.0, 1.0)
        hi = np.clip(np.maximum(-t1 / span, (lines1.length[a] - t1) / span), 0.0, 1.0)
        weight = 0.5 * (hi - lo) * lines2.length[b]
        # Two Gauss points per pair on the overlapping part of s2 (in S2's frame).
        lam = lo[:, None] + (hi - lo)[:, None] * gauss[None, :]
        px = (p1[:, 0, None] + lam * (p2[:, 0] - p1[:, 0])[:, None]).ravel()
        py = (p1[:, 1, None] + lam * (p2[:, 1] - p1[:, 1])[:, None]).ravel()
        hh = np.repeat(h, 2)
        aa = np.repeat(a, 2)
        cc, ss = np.repeat(c, 2), np.repeat(s, 2)
        qx = cc * px - ss * py + np.repeat(tx, 2)
        qy = ss * px + cc * py + np.repeat(ty, 2)
        nx, ny = -lines1.direction[aa, 1], lines1.direction[aa, 0]
        r = nx * qx + ny * qy - lines1.normal_offset[aa]
        w = np.repeat(weight, 2) / (1.0 + (r / config.point_distance_tolerance) ** 2)
        # d q / d theta = (-(s px + c py), c px - s py)
        j0 = nx * -(ss * px + cc * py) + ny * (cc * px - ss * py)
        J = (j0, nx, ny)
        H = np.empty((live.size, 3, 3))
        g = np.empty((live.size, 3))
        for i in range(3):
            g[:, i] = np.bincount(hh, weights=w * J[i] * r, minlength=live.size)
            for j in range(i, 3):
                H[:, i, j] = H[:, j, i] = np.bincount(
                    hh, weights=w * J[i] * J[j], minlength=live.size
                )
        # Levenberg damping: a direction no matched line constrains gets no step.
        damping = 1e-6 + 1e-4 * np.trace(H, axis1=1, axis2=2)
        H += damping[:, None, None] * np.eye(3)[None, :, :]
        step = -np.linalg.solve(H, g[:, :, None])[:, :, 0]
        T[live] += step
        small = (np.abs(step[:, 0]) < 1e-5) & (np.hypot(step[:, 1], step[:, 2]) < 1e-4)
        active[live[small]] = False
    T[:, 0] = se2.wrap_angle(T[:, 0])
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


def seen_through(
    view: LaserScanData, points: FloatArray, margin: float, spread: int = 0
) -> BoolArray:
    """Points (in the view's laser frame) lying in free space that the view's beams crossed.

    A point is seen through when every beam within ``spread`` beams of its bearing returned
    from more than ``margin`` beyond it: a wall seen at a grazing angle returns very different
    ranges on neighbouring beams. Beams without a valid return say nothing.
    """
    return _beam_evidence(view, points, margin, spread)[0]


def _beam_evidence(
    view: LaserScanData, points: FloatArray, margin: float, spread: int
) -> tuple[BoolArray, BoolArray]:
    """For points in the view's laser frame: seen through (:func:`seen_through`), and
    confirmed, lying within ``margin`` of the return of the beam nearest their bearing."""
    ranges = np.asarray(view.ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(ranges) & (ranges >= view.range_min) & (ranges < view.range_max)
    # Invalid beams never contradict nor confirm; the shortest return around each beam is the
    # free-space test.
    returned = np.where(valid, ranges, np.inf)
    nearest = np.where(valid, ranges, -np.inf)
    if spread > 0:
        padded = np.concatenate((np.full(spread, -np.inf), nearest, np.full(spread, -np.inf)))
        window = np.lib.stride_tricks.sliding_window_view(padded, 2 * spread + 1).min(axis=1)
        nearest = np.where(valid, window, -np.inf)
    bearing = np.arctan2(points[:, 1], points[:, 0])
    distance = np.hypot(points[:, 0], points[:, 1])
    beam = np.rint((bearing - view.angle_min) / view.angle_increment).astype(np.int64)
    outside = (beam < 0) | (beam >= ranges.size)
    beam[outside] = 0
    free = np.where(outside, -np.inf, nearest[beam])
    hit = np.where(outside, np.inf, returned[beam])
    return np.asarray(distance < free - margin), np.asarray(np.abs(distance - hit) <= margin)


def _view_points(view: LaserScanData, cap: float) -> tuple[FloatArray, FloatArray]:
    """A view's returns in its laser frame, each weighted by the surface it stands for (the
    smaller gap to a neighbouring return, at most ``cap``); one return per degree at most."""
    points = scan_points(view).points
    points = points[:: max(1, round(np.radians(1.0) / abs(view.angle_increment)))]
    if len(points) < 2:
        return points, np.full(len(points), cap)
    gap = np.hypot(*np.diff(points, axis=0).T)
    gap = np.minimum(np.concatenate((gap, gap[-1:])), np.concatenate((gap[:1], gap)))
    return points, np.minimum(gap, cap)


def _segment_points(segments: FloatArray, config: IntegrateConfig) -> tuple[FloatArray, FloatArray]:
    """Points every 5 cm along the segments of at least ``free_space_min_length``."""
    spacing = 0.05
    if len(segments) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    long = segments[lines_of(segments).length >= config.free_space_min_length]
    if len(long) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    points, _ = sample_segments(long, spacing)
    return points, np.full(len(points), spacing)


def _seen_through_many(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    views: tuple[LaserScanData | None, LaserScanData | None],
    config: IntegrateConfig,
) -> tuple[FloatArray, FloatArray]:
    """Per transform: the length of each scan lying in the other's observed free space, and
    the length the other's beams confirm (ending within ``free_space_margin`` of it).

    With both views the tested points are the views' own returns (a corridor's far end is a
    few sparse returns, too few for a segment, and it is what fixes the offset along the
    corridor); with one view, points along the other set's long segments (short ones are
    mostly people, who move between scans).
    """
    view1, view2 = views
    through = np.zeros(len(transforms))
    confirmed = np.zeros(len(transforms))
    if (view1 is None and view2 is None) or len(transforms) == 0:
        return through, confirmed
    cap = config.view_point_length
    if view1 is not None and view2 is not None:
        points2, weight2 = _view_points(view2, cap)
        points1, weight1 = _view_points(view1, cap)
    else:
        points2, weight2 = _segment_points(segments2, config)
        points1, weight1 = _segment_points(segments1, config)
    c, s = np.cos(transforms[:, 0])[:, None], np.sin(transforms[:, 0])[:, None]
    tx, ty = transforms[:, 1, None], transforms[:, 2, None]
    margin, spread = config.free_space_margin, config.free_space_spread
    shape = (len(transforms), -1)
    if view1 is not None and len(points2):
        # S2 points in S1's frame: q = R p + t, for every transform.
        qx = c * points2[None, :, 0] - s * points2[None, :, 1] + tx
        qy = s * points2[None, :, 0] + c * points2[None, :, 1] + ty
        hit, seen = _beam_evidence(view1, np.column_stack((qx.ravel(), qy.ravel())), margin, spread)
        through += hit.reshape(shape) @ weight2
        confirmed += seen.reshape(shape) @ weight2
    if view2 is not None and len(points1):
        # S1 points in S2's frame: p = R^T (q - t).
        dx, dy = points1[None, :, 0] - tx, points1[None, :, 1] - ty
        px, py = c * dx + s * dy, -s * dx + c * dy
        hit, seen = _beam_evidence(view2, np.column_stack((px.ravel(), py.ravel())), margin, spread)
        through += hit.reshape(shape) @ weight1
        confirmed += seen.reshape(shape) @ weight1
    return through, confirmed
