"""Wolter's shape-based matching of two scans with no pose information.

Wolter, Latecki, Lakämper, Sun, *Shape-Based Robot Mapping* (``../shared/seeds/003_*``):

1. **Shape** (Sec. 3.1): a scan's returns, in the laser's counter-clockwise order, are grouped
   into polylines wherever two consecutive returns are more than ``group_distance`` apart, and
   each is simplified by Discrete Curve Evolution (DCE): the vertex of least relevance
   K(u, v, w) = d(u, v) + d(v, w) - d(u, w) (Eq. 1) is removed until the least relevance
   exceeds ``dce_threshold``. End points stay.
2. **Similarity** (Sec. 4.1): two polylines compared in tangent space, Eq. 2 with the
   orientation Θ of Eq. 3, which makes the integral the variance of the difference of the
   two turning functions over normalised arc length.
3. **Correspondence** (Sec. 4.2): the order-preserving correspondence of the two scans'
   polylines that minimises Eq. 4 (dissimilarity plus alignment deviation of each matched pair,
   plus a skip penalty growing with the length of each polyline left unmatched), by dynamic
   programming with 1-to-many and many-to-1 correspondences of up to ``max_group`` polylines.
4. **No odometry** (Sec. 4.3): the most reliable correspondences on shape alone,
   Q = C(P) + C(Q) - S(P, Q) (Eq. 5, C the shape complexity), each induce an estimate for
   the correspondence with the alignment term.
5. **Alignment** (Sec. 5.1, after Cox): the perceived polylines, sampled every
   ``align_spacing``, are fitted to their nearest points on the corresponding polylines of
   the reference, iteratively, each step in closed form.

Departures from the paper, each for a reason:
- DCE removes every vertex of least relevance among its neighbours in one vectorised round
  (such vertices are never adjacent, so removing them together is what the sequential process
  would do next, up to ties), instead of one vertex per step.
- The model-based evolution S* (continuing DCE on one polyline while the similarity improves)
  is not done: the similarity is Eq. 2 on the DCE result.
- A correspondence's induced alignment is the closed-form rigid fit of the two polylines
  sampled at the same normalised arc lengths.
- Reliability is ranked over every pair of polylines and groups, not only over the
  correspondences of a first matching pass without alignment term, and the
  ``reliable_candidates`` most reliable are each tried as the estimate (the paper: one).
- The order of polylines is the scan's, not cyclic: a laser of less than a full turn.

Frames: ``T_1_2`` maps the second (perceived) scan's coordinates into the first's (the
reference; the paper's map). Everything is vectorised over polylines and samples; the only
Python loops run over rows of the dynamic programme and its backtrack (polylines, not points).
"""

from __future__ import annotations

import dataclasses
import time
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import cluster_bounds
from multi_robot_mapper.core.geometry import ranges_index
from multi_robot_mapper.core.matching.shape_config import ShapeConfig
from multi_robot_mapper.core.scan import LaserScanData, scan_points
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

_SKIP_PERCEIVED = 1_000  # a choice of the dynamic programme: leave a perceived polyline out


@dataclasses.dataclass(frozen=True)
class Shape:
    """A scan's polylines after DCE: ``vertices[start[k] : stop[k] + 1]`` is polyline k."""

    vertices: FloatArray  # (V, 2) metres, the polylines one after the other in scan order
    start: IntArray  # (n,) first vertex of each polyline
    stop: IntArray  # (n,) last vertex of each polyline (inclusive)

    def __len__(self) -> int:
        return len(self.start)

    def polyline(self, k: int) -> FloatArray:
        return self.vertices[self.start[k] : self.stop[k] + 1]


@dataclasses.dataclass(frozen=True)
class ShapeMatch:
    """The alignment of a perceived scan's shape on a reference shape."""

    T_1_2: Pose  # (x, y, theta): perceived-scan coordinates into the reference's frame
    valid: bool  # at least one correspondence was found
    # matched polylines: ((first, count) of the reference's, (first, count) of the perceived's)
    correspondences: tuple[tuple[tuple[int, int], tuple[int, int]], ...]
    cost: float  # Eq. 4 of the second pass (lower is better)
    rms: float  # of the final alignment's point-to-polyline distances, metres
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)
    # every candidate's aligned T_1_2, least cost first (T_1_2 is the first): the placements
    # a matcher that scores its own hypotheses can choose from
    alternatives: tuple[Pose, ...] = ()

    @property
    def matrix(self) -> FloatArray:
        return se2.matrix_from_pose(*self.T_1_2)


def relevance(vertices: FloatArray) -> FloatArray:
    """Wolter Eq. 1 for every inner vertex of one chain: d(u,v) + d(v,w) - d(u,w)."""
    u, v, w = vertices[:-2], vertices[1:-1], vertices[2:]
    detour: FloatArray = np.hypot(*(v - u).T) + np.hypot(*(w - v).T) - np.hypot(*(w - u).T)
    return detour


def discrete_curve_evolution(
    points: FloatArray, first: IntArray, last: IntArray, threshold: float
) -> BoolArray:
    """Which points survive DCE (Wolter 3.1, Eq. 1) within each chain ``first[k]..last[k]``:
    every round removes each vertex whose relevance is below ``threshold`` and is the least
    among its alive neighbours' (ties to the lower index). End points always stay."""
    alive = np.zeros(len(points), dtype=bool)
    chain = np.full(len(points), -1, dtype=np.int64)
    if len(first) == 0:
        return alive
    index, owner, _ = ranges_index(first, last + 1)
    alive[index] = True
    chain[index] = owner
    while True:
        live = np.flatnonzero(alive)
        if live.size < 3:
            return alive
        u, v, w = live[:-2], live[1:-1], live[2:]
        inner = (chain[u] == chain[v]) & (chain[v] == chain[w])
        k = np.where(inner, relevance(points[live]), np.inf)
        # A candidate is below threshold and no more relevant than its live neighbours in
        # the same chain (strictly less than the previous one, so that of two equal
        # neighbours only the first goes: never two adjacent vertices in one round).
        previous = np.concatenate(([np.inf], k[:-1]))
        following = np.concatenate((k[1:], [np.inf]))
        remove = (k < threshold) & (k < previous) & (k <= following)
        if not remove.any():
            return alive
        alive[v[remove]] = False


def shape_of_points(points: FloatArray, config: ShapeConfig) -> Shape:
    """Polylines of consecutive returns (counter-clockwise, laser frame), simplified by DCE.
    A group of one return has no shape and is dropped."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(points) < 2:
        return Shape(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    first, last = cluster_bounds(points, config.group_distance)
    keep = last > first
    first, last = first[keep], last[keep]
    alive = discrete_curve_evolution(points, first, last, config.dce_threshold)
    kept = np.flatnonzero(alive)
    # Polyline k's vertices are the kept points between first[k] and last[k], both kept.
    start = np.searchsorted(kept, first)
    stop = np.searchsorted(kept, last)
    return Shape(points[kept], start.astype(np.int64), stop.astype(np.int64))


def shape_of_scan(scan: LaserScanData, config: ShapeConfig) -> Shape:
    """:func:`shape_of_points` of a scan's valid returns."""
    return shape_of_points(scan_points(scan).points, config)


@dataclasses.dataclass(frozen=True)
class _Groups:
    """Every run of 1..max_group consecutive polylines of a shape, as one chain of vertices
    (a group's polylines joined end to start), sampled along its arc length."""

    first: IntArray  # (R,) first polyline of each group
    count: IntArray  # (R,) polylines in it
    length: FloatArray  # (R,) arc length, metres
    angles: FloatArray  # (R, M) turning function at the sample midpoints (unwrapped, rad)
    points: FloatArray  # (R, M, 2) the chain's points at the same arc lengths
    complexity: FloatArray  # (R,) Wolter's C: inner vertices' relevance summed, or half the
    # end-to-end distance of a chain without inner vertex
    penalty: FloatArray  # (R,) skip penalty of its polylines (Eq. 4, P)
    centre: FloatArray  # (R, 2) mean of its samples
    row: IntArray  # (max_group + 1, n): row[c, f] is the group of c polylines from f (-1: none)
    ending: IntArray  # (max_group + 1, n): the group of c polylines whose last is j (-1: none)


class Grouping(NamedTuple):
    """What a shape's groups (:func:`_groups`) read of ShapeConfig: the samples of each
    group's turning function (``tangent_samples``), the most polylines in one group
    (``max_group``) and the skip penalty per metre (``skip_penalty``, Eq. 4's P)."""

    tangent_samples: int
    max_group: int
    skip_penalty: float


def grouping(config: ShapeConfig) -> Grouping:
    """The grouping settings of ``config``."""
    return Grouping(config.tangent_samples, config.max_group, config.skip_penalty)


def _groups(shape: Shape, settings: Grouping) -> _Groups:
    n, m = len(shape), settings.tangent_samples
    counts = np.arange(1, min(settings.max_group, n) + 1)
    first = np.concatenate([np.arange(n - c + 1) for c in counts]).astype(np.int64)
    count = np.concatenate([np.full(n - c + 1, c) for c in counts]).astype(np.int64)
    a, b = shape.start[first], shape.stop[first + count - 1]  # vertex range [a, b]
    vertices = shape.vertices
    step = np.diff(vertices, axis=0)
    seg_length = np.hypot(step[:, 0], step[:, 1])
    direction = np.unwrap(np.arctan2(step[:, 1], step[:, 0]))
    cumulative = np.concatenate(([0.0], np.cumsum(seg_length)))
    length = cumulative[b] - cumulative[a]
    # Sample midpoints at the same normalised arc lengths on every group.
    s = (np.arange(m) + 0.5) / m
    at = cumulative[a][:, None] + s[None, :] * length[:, None]
    segment = np.searchsorted(cumulative, at, side="right") - 1
    segment = np.clip(segment, a[:, None], b[:, None] - 1)
    angles = direction[segment]
    t = (at - cumulative[segment]) / np.maximum(seg_length[segment], 1e-12)
    points = vertices[segment] + t[..., None] * step[segment]
    # Shape complexity (Wolter 4.3): relevance of the inner vertices, as prefix sums.
    inner = np.zeros(len(vertices))
    if len(vertices) >= 3:
        inner[1:-1] = relevance(vertices)
    inner_sum = np.concatenate(([0.0], np.cumsum(inner)))
    complexity = inner_sum[b] - inner_sum[a + 1]
    chord = np.hypot(*(vertices[b] - vertices[a]).T)
    complexity = np.where(b - a >= 2, complexity, 0.5 * chord)
    own = cumulative[shape.stop] - cumulative[shape.start]  # each polyline's length alone
    own_sum = np.concatenate(([0.0], np.cumsum(own)))
    penalty = settings.skip_penalty * (own_sum[first + count] - own_sum[first])
    row = np.full((settings.max_group + 1, n), -1, dtype=np.int64)
    row[count, first] = np.arange(len(first))
    ending = np.full((settings.max_group + 1, n), -1, dtype=np.int64)
    ending[count, first + count - 1] = np.arange(len(first))
    centre = points.mean(axis=1)
    return _Groups(first, count, length, angles, points, complexity, penalty, centre, row, ending)


def similarity(reference: _Groups, perceived: _Groups) -> FloatArray:
    """Wolter Eq. 2 with Θ of Eq. 3 for every pair of groups: (1 + (l_C - l_D)²) times the
    variance over arc length of T_C - T_D (the integral with the Θ that minimises it)."""
    m = reference.angles.shape[1]
    a, b = reference.angles, perceived.angles
    mean_a, mean_b = a.mean(axis=1), b.mean(axis=1)
    square_a, square_b = (a * a).mean(axis=1), (b * b).mean(axis=1)
    cross = a @ b.T / m
    variance = square_a[:, None] + square_b[None, :] - 2.0 * cross
    variance -= (mean_a[:, None] - mean_b[None, :]) ** 2
    scale = 1.0 + (reference.length[:, None] - perceived.length[None, :]) ** 2
    dissimilarity: FloatArray = scale * np.maximum(variance, 0.0)
    return dissimilarity


def shared_shape(reference: Shape, perceived: Shape, config: ShapeConfig) -> float:
    """How much shape two scans share, on shape alone, in [0, 1]: the fraction of the skip
    penalty of every polyline of both that their first-pass correspondence (Wolter Eq. 4
    without the alignment term) saves (1: the same shape; 0: nothing shared). Unlike Eq. 5's
    single most reliable pair, it ranks a view of the same place above a view of some other
    place with one long intricate polyline; as a fraction, above a view with many polylines
    of which a few match."""
    if len(reference) == 0 or len(perceived) == 0:
        return 0.0
    settings = grouping(config)
    groups_1, groups_2 = _groups(reference, settings), _groups(perceived, settings)
    total, _ = correspond(similarity(groups_1, groups_2), groups_1, groups_2)
    skip_all = groups_1.penalty[groups_1.row[1]].sum() + groups_2.penalty[groups_2.row[1]].sum()
    return float((skip_all - total) / skip_all) if skip_all > 0.0 else 0.0


def induced_alignments(reference: _Groups, perceived: _Groups) -> tuple[FloatArray, FloatArray]:
    """For every pair of groups, the rigid motion that fits the perceived group's samples onto
    the reference's at the same arc lengths (closed form): turn (R1, R2) and translation
    (R1, R2, 2), perceived into reference coordinates."""
    p, q = perceived.points, reference.points
    cp, cq = p.mean(axis=1), q.mean(axis=1)
    pc, qc = p - cp[:, None, :], q - cq[:, None, :]
    # sum over samples of q . p and q x p, for all pairs at once
    dot = qc[..., 0] @ pc[..., 0].T + qc[..., 1] @ pc[..., 1].T
    cross = qc[..., 1] @ pc[..., 0].T - qc[..., 0] @ pc[..., 1].T
    theta = np.arctan2(cross, dot)
    c, s = np.cos(theta), np.sin(theta)
    rotated_x = c * cp[None, :, 0] - s * cp[None, :, 1]
    rotated_y = s * cp[None, :, 0] + c * cp[None, :, 1]
    translation = np.stack((cq[:, None, 0] - rotated_x, cq[:, None, 1] - rotated_y), axis=-1)
    return theta, translation


def _deviation(
    theta: FloatArray,
    translation: FloatArray,
    perceived: _Groups,
    T_est: Pose,
    scale: tuple[float, float],
) -> FloatArray:
    """How far each pair's induced alignment is from the estimate, in units of ``scale``
    (``alignment_distance``, ``alignment_angle``), squared: measured at the perceived group's
    centre, so that it does not depend on where the frame's origin is."""
    centre = perceived.centre
    c, s = np.cos(theta), np.sin(theta)
    moved_x = c * centre[None, :, 0] - s * centre[None, :, 1] + translation[..., 0]
    moved_y = s * centre[None, :, 0] + c * centre[None, :, 1] + translation[..., 1]
    estimated = se2.transform_points(se2.matrix_from_pose(*T_est), centre)
    distance = np.hypot(moved_x - estimated[None, :, 0], moved_y - estimated[None, :, 1])
    turn = se2.wrap_angle(theta - T_est[2])
    alignment_distance, alignment_angle = scale
    squared: FloatArray = (distance / alignment_distance) ** 2
    squared += (turn / alignment_angle) ** 2
    return squared


def correspond(
    cost: FloatArray, reference: _Groups, perceived: _Groups
) -> tuple[float, list[tuple[int, int]]]:
    """Wolter Eq. 4 by dynamic programming: the order-preserving correspondence of the two
    shapes' polylines (1-to-1, 1-to-many, many-to-1 up to ``max_group``, as the groups were
    made) with the least total
    of ``cost`` (R1, R2: each matched pair of groups) plus the skip penalty of each polyline
    left out. Returns the total and the matched (reference row, perceived row) pairs."""
    n1, n2 = reference.row.shape[1], perceived.row.shape[1]
    single1, single2 = reference.row[1], perceived.row[1]
    skip1, skip2 = reference.penalty[single1], perceived.penalty[single2]
    prefix2 = np.concatenate(([0.0], np.cumsum(skip2)))
    total = np.empty((n1 + 1, n2 + 1))
    total[0] = prefix2
    total[:, 0] = np.concatenate(([0.0], np.cumsum(skip1)))
    # choice[i, j], how total[i, j] was reached: 0 skips reference polyline i-1; k > 0 matches
    # it with perceived j-k..j-1; -k (k >= 2) matches reference i-k..i-1 with perceived j-1;
    # _SKIP_PERCEIVED skips perceived polyline j-1.
    choice = np.zeros((n1 + 1, n2 + 1), dtype=np.int64)
    choice[0, 1:] = _SKIP_PERCEIVED
    j_all = np.arange(1, n2 + 1)
    max_group = min(reference.row.shape[0], perceived.row.shape[0]) - 1
    for i in range(1, n1 + 1):
        best = total[i - 1, 1:] + skip1[i - 1]
        best_choice = np.zeros(n2, dtype=np.int64)
        for k in range(1, max_group + 1):  # reference i-1 with perceived j-k..j-1
            rows = perceived.ending[k]  # per j, the group ending at j-1
            ok = rows >= 0
            candidate = np.full(n2, np.inf)
            candidate[ok] = total[i - 1, j_all[ok] - k] + cost[single1[i - 1], rows[ok]]
            better = candidate < best
            best, best_choice = np.where(better, candidate, best), np.where(better, k, best_choice)
        for k in range(2, min(max_group, i) + 1):  # reference i-k..i-1 with perceived j-1
            candidate = total[i - k, j_all - 1] + cost[reference.row[k, i - k], single2]
            better = candidate < best
            best, best_choice = np.where(better, candidate, best), np.where(better, -k, best_choice)
        # total[i, j] = min(best[j], total[i, j-1] + skip2[j-1]): a running minimum of
        # total - prefix2 along the row.
        reached = best - prefix2[1:]
        running = np.minimum.accumulate(np.concatenate(([total[i, 0]], reached)))[1:]
        total[i, 1:] = running + prefix2[1:]
        choice[i, 1:] = np.where(running < reached, _SKIP_PERCEIVED, best_choice)
    pairs: list[tuple[int, int]] = []
    i, j = n1, n2
    while i > 0 or j > 0:
        c = int(choice[i, j]) if i > 0 else _SKIP_PERCEIVED
        if j > 0 and c == _SKIP_PERCEIVED:
            j -= 1
        elif c == 0 or j == 0:
            i -= 1
        elif c > 0:
            pairs.append((int(reference.row[1, i - 1]), int(perceived.row[c, j - c])))
            i, j = i - 1, j - c
        else:
            pairs.append((int(reference.row[-c, i + c]), int(perceived.row[1, j - 1])))
            i, j = i + c, j - 1
    return float(total[n1, n2]), pairs[::-1]


def align(
    reference: Shape,
    perceived: Shape,
    matched: list[tuple[tuple[int, int], tuple[int, int]]],
    T_start: Pose,
    spacing: float,
    iterations: int,
) -> tuple[Pose, float]:
    """Wolter 5.1 (after Cox): the matched perceived polylines, a point every ``spacing`` m
    (one per segment at least), fitted to their nearest points on the reference ones: nearest
    points and closed-form fit in turn from ``T_start``, ``iterations`` times (once at least).
    Returns the fit and its RMS distance."""
    ref_segments, ref_owner = _polyline_segments(reference)
    per_segments, per_owner = _polyline_segments(perceived)
    allowed = np.zeros((len(perceived), len(reference)), dtype=bool)
    for (r_first, r_count), (p_first, p_count) in matched:
        allowed[p_first : p_first + p_count, r_first : r_first + r_count] = True
    use = allowed[per_owner].any(axis=1)
    per_segments, per_owner = per_segments[use], per_owner[use]
    if len(per_segments) == 0:
        return T_start, float("inf")
    samples, owner = _samples(per_segments, spacing)
    mask = allowed[per_owner[owner]][:, ref_owner]  # (S, segments of the reference)
    a, b = ref_segments[:, :2], ref_segments[:, 2:]
    ab = b - a
    # A polyline's first and last segments, whose outer ends are the polyline's ends.
    ref_first = np.concatenate(([True], ref_owner[1:] != ref_owner[:-1]))
    ref_last = np.concatenate((ref_owner[1:] != ref_owner[:-1], [True]))
    ab_square = np.maximum((ab * ab).sum(axis=1), 1e-18)
    T = se2.matrix_from_pose(*T_start)
    rms = float("inf")
    for _ in range(max(iterations, 1)):
        moved = se2.transform_points(T, samples)
        t = ((moved[:, None, 0] - a[None, :, 0]) * ab[None, :, 0]) + (
            (moved[:, None, 1] - a[None, :, 1]) * ab[None, :, 1]
        )
        t = np.clip(t / ab_square[None, :], 0.0, 1.0)
        near_x = a[None, :, 0] + t * ab[None, :, 0]
        near_y = a[None, :, 1] + t * ab[None, :, 1]
        distance = np.hypot(near_x - moved[:, None, 0], near_y - moved[:, None, 1])
        distance = np.where(mask, distance, np.inf)
        nearest = np.argmin(distance, axis=1)
        rows = np.arange(len(samples))
        # Only the body of a polyline corresponds (Wolter 5.2): a sample whose nearest point
        # is an end of the corresponding polyline lies in its head or tail, seen by one scan
        # only, and would pull the two ends together.
        at_end = (ref_first[nearest] & (t[rows, nearest] <= 0.0)) | (
            ref_last[nearest] & (t[rows, nearest] >= 1.0)
        )
        body = np.flatnonzero(~at_end & np.isfinite(distance[rows, nearest]))
        if body.size < 2:
            break
        targets = np.column_stack((near_x[body, nearest[body]], near_y[body, nearest[body]]))
        rms = float(np.sqrt(np.mean(distance[body, nearest[body]] ** 2)))
        fitted = se2.fit_points(samples[body], targets)
        change = se2.pose_from_matrix(se2.invert(T) @ fitted)
        T = fitted
        if np.hypot(change[0], change[1]) < 1e-4 and abs(change[2]) < 1e-5:
            break
    return se2.pose_from_matrix(T), rms


def _polyline_segments(shape: Shape) -> tuple[FloatArray, IntArray]:
    """Every polyline's segments (N, 4) and the polyline each belongs to (no segment joins
    two polylines)."""
    if len(shape) == 0:
        return np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
    index, owner, _ = ranges_index(shape.start, shape.stop)  # vertex k starts a segment
    v = shape.vertices
    return np.hstack((v[index], v[index + 1])), owner.astype(np.int64)


def _samples(segments: FloatArray, spacing: float) -> tuple[FloatArray, IntArray]:
    """Points every ``spacing`` along each segment, starting at its first end, at least one per
    segment (a segment's far end is the next one's first)."""
    length = np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1])
    count = np.maximum(1, np.floor(length / spacing).astype(np.int64))
    owner = np.repeat(np.arange(len(segments)), count)
    start = np.repeat(np.cumsum(count) - count, count)
    t = (np.arange(owner.size) - start) / count[owner]
    points = segments[owner, :2] + t[:, None] * (segments[owner, 2:] - segments[owner, :2])
    return points, owner


def match_shapes(reference: Shape, perceived: Shape, config: ShapeConfig) -> ShapeMatch:
    """Align ``perceived`` on ``reference`` with no pose information (Wolter 4.2-5.1)."""
    started = time.perf_counter()
    seconds: dict[str, float] = {}
    identity: Pose = (0.0, 0.0, 0.0)
    if len(reference) == 0 or len(perceived) == 0:
        return ShapeMatch(identity, False, (), float("inf"), float("inf"), seconds)
    settings = grouping(config)
    groups_1, groups_2 = _groups(reference, settings), _groups(perceived, settings)
    dissimilarity = similarity(groups_1, groups_2)
    theta, translation = induced_alignments(groups_1, groups_2)
    seconds["similarity"] = time.perf_counter() - started
    # Sec. 4.3: the most reliable correspondences on shape alone (Eq. 5), among every pair of
    # polylines and groups (the paper ranks only its first pass's correspondences: on 100
    # intel and 100 aces pairs every pair ranked gives 60 and 45 right, the first pass's 53
    # and 35).
    reliability = groups_1.complexity[:, None] + groups_2.complexity[None, :] - dissimilarity
    ranked = np.argsort(-reliability, axis=None, kind="stable")[: config.reliable_candidates]
    r1, r2 = np.unravel_index(ranked, reliability.shape)
    seconds["reliable"] = time.perf_counter() - started - seconds["similarity"]
    # Second pass from each candidate's induced alignment (Sec. 4.3), then the alignment
    # (Sec. 5.1); each candidate's aligned result is judged by Eq. 4 once more, with the
    # alignment term taken from where it ended: the least wins.
    skips = groups_1.penalty[:, None] + groups_2.penalty[None, :]
    scale = (config.alignment_distance, config.alignment_angle)

    def second_pass(estimate: Pose) -> tuple[float, list[tuple[int, int]]]:
        deviation = _deviation(theta, translation, groups_2, estimate, scale)
        cost = dissimilarity + skips * np.minimum(deviation, 1.0)
        return correspond(cost, groups_1, groups_2)

    def as_polylines(pairs: list[tuple[int, int]]) -> list[tuple[tuple[int, int], tuple[int, int]]]:
        return [
            (
                (int(groups_1.first[a]), int(groups_1.count[a])),
                (int(groups_2.first[b]), int(groups_2.count[b])),
            )
            for a, b in pairs
        ]

    results: list[ShapeMatch] = []
    for a, b in zip(r1.tolist(), r2.tolist(), strict=True):
        estimate = (float(translation[a, b, 0]), float(translation[a, b, 1]), float(theta[a, b]))
        _, pairs = second_pass(estimate)
        if not pairs:
            continue
        fit = (config.align_spacing, config.align_iterations)
        T_1_2, rms = align(reference, perceived, as_polylines(pairs), estimate, *fit)
        total, final = second_pass(T_1_2)
        if final:
            results.append(ShapeMatch(T_1_2, True, tuple(as_polylines(final)), total, rms))
    seconds["second_pass"] = time.perf_counter() - started - sum(seconds.values())
    seconds["total"] = time.perf_counter() - started
    if not results:
        return ShapeMatch(identity, False, (), float("inf"), float("inf"), seconds)
    results.sort(key=lambda result: result.cost)
    alternatives = tuple(result.T_1_2 for result in results)
    return dataclasses.replace(results[0], seconds=seconds, alternatives=alternatives)


def match_scans(
    reference: LaserScanData, perceived: LaserScanData, config: ShapeConfig | None = None
) -> ShapeMatch:
    """:func:`match_shapes` of two scans' shapes."""
    config = config if config is not None else ShapeConfig()
    return match_shapes(shape_of_scan(reference, config), shape_of_scan(perceived, config), config)


class Shapes:
    """Wolter's shapes of the scans the front end matches, each made once: a bounded cache,
    keyed by the scan object (kept alive while cached, so its id is not reused)."""

    def __init__(self, config: ShapeConfig, size: int = 64) -> None:
        self.config = config
        self._size = size
        self._cache: dict[int, tuple[LaserScanData, Shape]] = {}

    def __call__(self, view: LaserScanData) -> Shape:
        entry = self._cache.get(id(view))
        if entry is not None and entry[0] is view:
            return entry[1]
        shape = shape_of_scan(view, self.config)
        if len(self._cache) >= self._size:
            del self._cache[next(iter(self._cache))]  # the oldest
        self._cache[id(view)] = (view, shape)
        return shape
