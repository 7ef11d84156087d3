"""Pipeline stage 1: scan points to an ordered set of line segments (the front end).

Method (Amigoni et al. 2006, Sec. III-D; Wolter et al., Sec. 3.1):

1. **Clusters**: consecutive points (counter-clockwise) closer than tau = ``cluster_distance``
   belong to one cluster; clusters with fewer than ``min_cluster_points`` points are dropped.
2. **Polylines**: each cluster is approximated by recursive split (first/last point, then the
   farthest point becomes a vertex) until every point lies within kappa = ``split_tolerance`` of
   its piece; or, with ``simplifier: dce``, by Discrete Curve Evolution (Wolter eq. 1).
3. **Merge**: consecutive segments whose union one total-least-squares line fits within kappa
   are joined (the merge half of split-and-merge): chords between two noisy points otherwise
   split straight walls.
4. **Refit**: every segment is refitted by total least squares to the points it covers; the
   ends are those points' projections, and the corner shared by two consecutive segments of a
   polyline is the intersection of their lines when it lies near the scan point they share.

All steps run over every cluster of the scan at once (numpy, no loop over points): the
split loop runs once per recursion depth, not once per segment.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.scan import LaserScanData, ScanPoints, scan_points

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# The refit may leave a point this much beyond kappa before the segment is split again: at a
# sparse corner the line tilts towards the corner point (which lies on the other wall), and
# splitting there would only carve a two-point sliver.
REFIT_SLACK = 0.005  # m

# Below this |sin| between two consecutive segments their lines are too close to parallel for a
# stable intersection; the corner is then the midpoint of the two projected ends.
_MIN_CORNER_SINE = np.sin(np.radians(2.0))


@dataclasses.dataclass(frozen=True)
class ExtractionConfig:
    """Scan-to-segment front end. Lengths in metres."""

    cluster_distance: float = param(
        0.20,
        unit="m",
        doc="tau: consecutive points farther apart start a new cluster (Amigoni III-D, Wolter 3.1)",
        minimum=0.0,
        exclusive_minimum=True,
    )
    split_tolerance: float = param(
        0.025,
        unit="m",
        doc="kappa: recursive split stops when every point is this close to its segment",
        minimum=0.0,
        exclusive_minimum=True,
    )
    min_cluster_points: int = param(
        4,
        unit="points",
        doc="clusters with fewer points are dropped (isolated returns, rain, glass)",
        minimum=2,
    )
    simplifier: str = param(
        "split",
        unit="",
        doc="polyline simplifier: recursive split (tolerance kappa) or Discrete Curve Evolution",
        choices=("split", "dce"),
    )
    dce_threshold: float = param(
        0.005,
        unit="m",
        doc="DCE removes vertices while the least relevance K(u,v,w) (Wolter eq. 1) is below this",
        minimum=0.0,
        exclusive_minimum=True,
    )
    max_beams: int = param(
        100_000,
        unit="beams",
        doc="scans with more beams are refused as corrupt",
        minimum=1,
    )

    def __post_init__(self) -> None:
        validate(self)


@dataclasses.dataclass(frozen=True)
class SegmentScan:
    """The segments of one scan, in the laser frame, in counter-clockwise scan order.

    ``segments[i] = [x1, y1, x2, y2]`` runs in scan order; ``joined_to_next[i]`` says that segments
    i and i+1 are consecutive pieces of one polyline (they share a corner scan point, or hold
    the two adjacent beams that straddle the corner); their ends then coincide at the corner,
    unless moving them there would push a covered point beyond kappa. ``point_span[i]`` is the
    first and last index (inclusive) into ``points`` of the points
    segment i was fitted to.
    """

    segments: FloatArray
    joined_to_next: BoolArray
    point_span: IntArray
    points: FloatArray
    dropped_points: int

    def __len__(self) -> int:
        return len(self.segments)


def empty_segment_scan(points: FloatArray | None = None, dropped_points: int = 0) -> SegmentScan:
    """A scan with no segments (no points, or every cluster too small)."""
    pts = np.zeros((0, 2)) if points is None else points
    return SegmentScan(
        segments=np.zeros((0, 4)),
        joined_to_next=np.zeros(0, dtype=bool),
        point_span=np.zeros((0, 2), dtype=np.int64),
        points=pts,
        dropped_points=dropped_points,
    )


def extract_segments(points: FloatArray, config: ExtractionConfig) -> SegmentScan:
    """Turn counter-clockwise scan points into an ordered segment set (the whole front end)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(points) == 0:
        return empty_segment_scan(points)
    cluster_first, cluster_last = cluster_bounds(points, config.cluster_distance)
    big = (cluster_last - cluster_first + 1) >= config.min_cluster_points
    dropped = int(np.sum(cluster_last[~big] - cluster_first[~big] + 1))
    if not np.any(big):
        return empty_segment_scan(points, dropped)
    first, last = cluster_first[big], cluster_last[big]
    # Centred coordinates keep the cumulative moments well conditioned far from the laser.
    origin = points.mean(axis=0)
    x = points[:, 0] - origin[0]
    y = points[:, 1] - origin[1]
    moments = _cumulative_moments(x, y)
    by_split = config.simplifier == "split"
    tolerance = config.split_tolerance
    if by_split:
        vertex = split_vertices(x, y, moments, first, last, tolerance)
    else:
        vertex = dce_vertices(points, first, last, config.dce_threshold)
    seg_first, seg_last = _pieces(vertex, first, last)
    if by_split:
        seg_first, seg_last = merge_collinear(x, y, moments, seg_first, seg_last, tolerance)
    seg_first, seg_last = drop_corner_slivers(seg_first, seg_last)
    segments, joined, seg_first, seg_last = refit_segments(
        x, y, moments, first, seg_first, seg_last, tolerance, enforce_tolerance=by_split
    )
    segments += np.tile(origin, 2)
    return SegmentScan(
        segments=segments,
        joined_to_next=joined,
        point_span=np.column_stack((seg_first, seg_last)),
        points=points,
        dropped_points=dropped,
    )


def cluster_bounds(points: FloatArray, cluster_distance: float) -> tuple[IntArray, IntArray]:
    """First and last point index of each cluster of consecutive points closer than tau."""
    step = np.hypot(*np.diff(points, axis=0).T)
    breaks = np.flatnonzero(step > cluster_distance)
    first = np.concatenate(([0], breaks + 1)).astype(np.int64)
    last = np.concatenate((breaks, [len(points) - 1])).astype(np.int64)
    return first, last


def _cluster_vertex_mask(n_points: int, first: IntArray, last: IntArray) -> BoolArray:
    vertex = np.zeros(n_points, dtype=bool)
    vertex[first] = True
    vertex[last] = True
    return vertex


def _interior_mask(n_points: int, first: IntArray, last: IntArray) -> BoolArray:
    """Points strictly inside a kept cluster (neither its first nor its last point)."""
    inside = np.zeros(n_points + 1, dtype=np.int64)
    np.add.at(inside, first + 1, 1)
    np.add.at(inside, last, -1)
    return np.cumsum(inside[:-1]) > 0


def point_segment_distance(
    px: FloatArray, py: FloatArray, ax: FloatArray, ay: FloatArray, bx: FloatArray, by: FloatArray
) -> FloatArray:
    """Element-wise distance from points (px, py) to segments (ax, ay)-(bx, by).

    Coordinates come as separate 1-D arrays: on the few hundred points of a scan this is
    several times faster than (K, 2) arrays with einsum.
    """
    abx, aby = bx - ax, by - ay
    apx, apy = px - ax, py - ay
    denom = np.maximum(abx * abx + aby * aby, 1e-18)
    t = np.clip((apx * abx + apy * aby) / denom, 0.0, 1.0)
    return np.asarray(np.hypot(apx - t * abx, apy - t * aby))


def split_vertices(
    x: FloatArray,
    y: FloatArray,
    moments: FloatArray,
    first: IntArray,
    last: IntArray,
    tolerance: float,
) -> BoolArray:
    """Recursive split (Amigoni III-D) of every cluster at once: the polyline vertex mask.

    A piece is split at its farthest point from the chord joining its end points (which finds
    corners) unless its points lie within ``tolerance`` of that chord (the classic test) or of
    the piece's total-least-squares line (the segment it will become). The second test keeps a
    noisy end point, whose chord is tilted, from splitting a straight wall; at a true corner the
    end point lies on the other wall, fails it, and the classic test decides. Points of pieces
    that pass leave the working set, so each pass costs only what
    is still open. ``x``, ``y`` are centred coordinates and ``moments`` their cumulative moments.
    """
    n = len(x)
    vertex = _cluster_vertex_mask(n, first, last)
    open_points = np.flatnonzero(_interior_mask(n, first, last))
    while open_points.size:
        vertices = np.flatnonzero(vertex)
        piece = np.searchsorted(vertices, open_points) - 1
        a, b = vertices[:-1], vertices[1:]
        pa, pb = a[piece], b[piece]
        px, py = x[open_points], y[open_points]
        dist = point_segment_distance(px, py, x[pa], y[pa], x[pb], y[pb])
        mx, my, ux, uy = _tls_lines(moments, a, b)
        residual = np.abs((px - mx[piece]) * uy[piece] - (py - my[piece]) * ux[piece])
        off_chord = np.zeros(len(a), dtype=bool)
        off_chord[piece[dist > tolerance]] = True
        off_line = (
            np.maximum(
                np.abs((x[a] - mx) * uy - (y[a] - my) * ux),
                np.abs((x[b] - mx) * uy - (y[b] - my) * ux),
            )
            > tolerance
        )
        off_line[piece[residual > tolerance]] = True
        in_failing = (off_chord & off_line)[piece]
        if not in_failing.any():
            break
        open_points, piece, dist = open_points[in_failing], piece[in_failing], dist[in_failing]
        # Farthest point from the chord in every failing piece (ties: the first).
        order = np.lexsort((-dist, piece))
        ordered_piece = piece[order]
        leader = np.empty(order.size, dtype=bool)
        leader[0] = True
        np.not_equal(ordered_piece[1:], ordered_piece[:-1], out=leader[1:])
        chosen = order[leader]
        vertex[open_points[chosen]] = True
        keep = np.ones(open_points.size, dtype=bool)
        keep[chosen] = False
        open_points = open_points[keep]
    return vertex


def dce_vertices(
    points: FloatArray, first: IntArray, last: IntArray, threshold: float
) -> BoolArray:
    """Discrete Curve Evolution (Wolter eq. 1) of every cluster at once: the vertex mask.

    The relevance of vertex v between its polyline neighbours u and w is
    K(u, v, w) = d(u, v) + d(v, w) - d(u, w). Sequential DCE removes the least relevant vertex
    until the least relevance exceeds ``threshold``. Here every vertex whose relevance is a
    local minimum (below both neighbours') and below the threshold goes in the same pass: such
    vertices are never adjacent, and each removal only changes its neighbours' relevance, so the
    result matches the sequential order up to ties while needing a few passes instead of one
    per vertex. Cluster end points carry no relevance and stay (Wolter 3.1).
    """
    n = len(points)
    vertex = np.zeros(n, dtype=bool)
    vertex[_interior_mask(n, first, last)] = True
    vertex |= _cluster_vertex_mask(n, first, last)
    fixed = _cluster_vertex_mask(n, first, last)
    while True:
        v = np.flatnonzero(vertex)
        inner = np.flatnonzero(~fixed[v])
        if inner.size == 0:
            break
        u, w = v[inner - 1], v[inner + 1]
        pv, pu, pw = points[v[inner]], points[u], points[w]
        relevance = np.full(len(v), np.inf)
        relevance[inner] = np.hypot(*(pv - pu).T) + np.hypot(*(pw - pv).T) - np.hypot(*(pw - pu).T)
        left = np.concatenate(([np.inf], relevance[:-1]))
        right = np.concatenate((relevance[1:], [np.inf]))
        remove = (relevance < threshold) & (relevance < left) & (relevance <= right)
        if not np.any(remove):
            break
        vertex[v[remove]] = False
    return vertex


def _ranges_index(first: IntArray, last: IntArray) -> tuple[IntArray, IntArray]:
    """Concatenated ``arange(first[k], last[k] + 1)`` for all k, and the k of each entry."""
    length = last - first + 1
    owner = np.repeat(np.arange(len(first)), length)
    offset = np.arange(owner.size) - np.repeat(np.cumsum(length) - length, length)
    return first[owner] + offset, owner


def _tls_lines(
    moments: FloatArray, first: IntArray, last: IntArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Centroid and unit direction of the total-least-squares line of each point range.

    ``moments`` are the cumulative sums (with a leading zero row) of x, y, x^2, xy, y^2.
    """
    sums = moments[last + 1] - moments[first]
    count = (last - first + 1).astype(np.float64)
    mx = sums[:, 0] / count
    my = sums[:, 1] / count
    cxx = sums[:, 2] / count - mx * mx
    cxy = sums[:, 3] / count - mx * my
    cyy = sums[:, 4] / count - my * my
    phi = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)  # direction of largest variance
    return mx, my, np.cos(phi), np.sin(phi)


def _cumulative_moments(x: FloatArray, y: FloatArray) -> FloatArray:
    """Running sums of x, y, x^2, xy, y^2 with a leading zero row: range sums in O(1)."""
    moments = np.zeros((len(x) + 1, 5))
    body = moments[1:]
    body[:, 0] = x
    body[:, 1] = y
    np.multiply(x, x, out=body[:, 2])
    np.multiply(x, y, out=body[:, 3])
    np.multiply(y, y, out=body[:, 4])
    np.cumsum(body, axis=0, out=body)
    return moments


def merge_collinear(
    x: FloatArray,
    y: FloatArray,
    moments: FloatArray,
    seg_first: IntArray,
    seg_last: IntArray,
    tolerance: float,
) -> tuple[IntArray, IntArray]:
    """The merge half of split-and-merge: join consecutive segments one line fits within kappa.

    Recursive split draws chords between two measured (noisy) points, so a chord can tilt
    enough to split a straight wall; the total-least-squares line through both pieces may
    still hold every point within ``tolerance``. Each pass merges, among the pairs that
    qualify, those whose residual is lower than both neighbouring pairs' (so no segment is
    merged twice in one pass). Passes repeat only while a qualifying pair was held back by a
    neighbour. ``x``, ``y`` are the points (centred) and ``moments`` their cumulative moments.
    """
    first, last = seg_first.copy(), seg_last.copy()
    while len(first) > 1:
        pair = np.flatnonzero(last[:-1] == first[1:])
        if pair.size == 0:
            break
        lo, hi = first[pair], last[pair + 1]
        mx, my, ux, uy = _tls_lines(moments, lo, hi)
        idx, owner = _ranges_index(lo, hi)
        residual = np.abs((x[idx] - mx[owner]) * uy[owner] - (y[idx] - my[owner]) * ux[owner])
        worst = np.maximum.reduceat(residual, np.cumsum(hi - lo + 1) - (hi - lo + 1))
        score = np.where(worst <= tolerance, worst, np.inf)
        # Pairs k and k+1 share a segment exactly when pair[k+1] == pair[k] + 1.
        left = np.full(pair.size, np.inf)
        right = np.full(pair.size, np.inf)
        touch = pair[1:] == pair[:-1] + 1
        left[1:] = np.where(touch, score[:-1], np.inf)
        right[:-1] = np.where(touch, score[1:], np.inf)
        qualifies = score <= tolerance
        chosen_mask = qualifies & (score < left) & (score <= right)
        chosen = pair[chosen_mask]
        if chosen.size == 0:
            break
        last[chosen] = last[chosen + 1]
        keep = np.ones(len(first), dtype=bool)
        keep[chosen + 1] = False
        first, last = first[keep], last[keep]
        if np.array_equal(qualifies, chosen_mask):
            break  # nothing was held back: another pass would find nothing new
    return first, last


def _pieces(vertex: BoolArray, first: IntArray, last: IntArray) -> tuple[IntArray, IntArray]:
    """Consecutive vertex pairs inside one cluster: each segment's first and last point."""
    v = np.flatnonzero(vertex)
    cluster_of = np.searchsorted(first, v, side="right") - 1
    same = cluster_of[:-1] == cluster_of[1:]
    return v[:-1][same].astype(np.int64), v[1:][same].astype(np.int64)


def _max_covered_distance(
    x: FloatArray, y: FloatArray, segments: FloatArray, first: IntArray, last: IntArray
) -> FloatArray:
    """For each segment, the largest distance from one of its points (first..last) to it."""
    idx, owner = _ranges_index(first, last)
    seg = segments[owner]
    dist = point_segment_distance(x[idx], y[idx], seg[:, 0], seg[:, 1], seg[:, 2], seg[:, 3])
    return np.asarray(np.maximum.reduceat(dist, np.cumsum(last - first + 1) - (last - first + 1)))


def _fit_lines(
    x: FloatArray, y: FloatArray, moments: FloatArray, seg_first: IntArray, seg_last: IntArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, IntArray]:
    """TLS line of each segment's points, directed along the scan, spanning all their projections.

    Returns the centroids and directions, the segments, each covered point's distance to its
    line, and the offset of each segment's first point in that distance array.
    """
    mx, my, ux, uy = _tls_lines(moments, seg_first, seg_last)
    flip = ux * (x[seg_last] - x[seg_first]) + uy * (y[seg_last] - y[seg_first]) < 0.0
    ux[flip] = -ux[flip]
    uy[flip] = -uy[flip]
    # The segment spans the projections of all its points: in a folded cluster (a chair leg
    # seen edge-on) a middle point can project beyond the first and last ones.
    idx, owner = _ranges_index(seg_first, seg_last)
    dx, dy = x[idx] - mx[owner], y[idx] - my[owner]
    along = dx * ux[owner] + dy * uy[owner]
    across = np.abs(dx * uy[owner] - dy * ux[owner])
    offsets = np.cumsum(seg_last - seg_first + 1) - (seg_last - seg_first + 1)
    t0 = np.minimum.reduceat(along, offsets)
    t1 = np.maximum.reduceat(along, offsets)
    segments = np.column_stack((mx + t0 * ux, my + t0 * uy, mx + t1 * ux, my + t1 * uy))
    return mx, my, ux, uy, segments, across, offsets


def drop_corner_slivers(seg_first: IntArray, seg_last: IntArray) -> tuple[IntArray, IntArray]:
    """Remove two-point segments inside a chain: the two beams that straddle a corner.

    When a corner falls between two beams, recursive split makes both of them vertices and
    leaves a segment from the last point of one wall to the first point of the next. Without it
    the two walls' segments touch (their point ranges are adjacent) and meet at the corner.
    """
    if len(seg_first) < 3:
        return seg_first, seg_last
    sliver = np.zeros(len(seg_first), dtype=bool)
    sliver[1:-1] = (
        (seg_last[1:-1] - seg_first[1:-1] == 1)
        & (seg_last[:-2] == seg_first[1:-1])
        & (seg_last[1:-1] == seg_first[2:])
    )
    # Two slivers in a row are a short wall, not a corner: keep both.
    sliver[1:] &= ~sliver[:-1]
    return seg_first[~sliver], seg_last[~sliver]


def refit_segments(
    x: FloatArray,
    y: FloatArray,
    moments: FloatArray,
    cluster_first: IntArray,
    seg_first: IntArray,
    seg_last: IntArray,
    tolerance: float,
    enforce_tolerance: bool = True,
) -> tuple[FloatArray, BoolArray, IntArray, IntArray]:
    """Total-least-squares line of each segment's points; ends and shared corners on those lines.

    With ``enforce_tolerance`` a segment whose fitted line leaves a point farther than
    ``tolerance + REFIT_SLACK`` is split again there, or one point inwards of an end point (the
    split bounded the distance to the chord, and the fitted line may tilt away from it). Sums
    over each
    segment's (inclusive) point range come from cumulative sums, so a corner point shared by
    two segments is fitted by both. Returns the segments, ``joined_to_next`` and the (possibly
    refined) point spans, in the (centred) frame of ``x``, ``y``.
    """
    while True:
        mx, my, ux, uy, segments, across, offsets = _fit_lines(x, y, moments, seg_first, seg_last)
        if not enforce_tolerance:
            break
        count = seg_last - seg_first + 1
        worst = np.maximum.reduceat(across, offsets)
        over = np.flatnonzero(worst > tolerance + REFIT_SLACK)
        if over.size == 0:
            break
        # Each offending segment's farthest point (first of ties), as an offset in its range;
        # an end point is split off by cutting one point inwards.
        hit = np.flatnonzero(across == np.repeat(worst, count))
        owner = np.searchsorted(offsets, hit, side="right") - 1
        wanted = np.isin(owner, over)
        hit, owner = hit[wanted], owner[wanted]
        leader = np.concatenate(([True], owner[1:] != owner[:-1]))
        hit, owner = hit[leader], owner[leader]
        local = np.clip(hit - offsets[owner], 1, count[owner] - 2)
        new_vertex = seg_first[owner] + local
        at = np.searchsorted(seg_first, new_vertex, side="right")
        seg_first = np.insert(seg_first, at, new_vertex)
        seg_last = np.insert(seg_last, at - 1, new_vertex)

    # Consecutive pieces of one polyline share a corner point, or (after a corner sliver was
    # dropped) hold adjacent points of one cluster.
    cluster_of_first = np.searchsorted(cluster_first, seg_first, side="right")
    joined = np.zeros(len(seg_first), dtype=bool)
    joined[:-1] = (seg_first[1:] - seg_last[:-1] <= 1) & (
        cluster_of_first[1:] == np.searchsorted(cluster_first, seg_last[:-1], side="right")
    )
    i = np.flatnonzero(joined)
    if i.size:
        plain = segments.copy()
        plain_worst = np.maximum.reduceat(across, offsets)
        j = i + 1
        sine = ux[i] * uy[j] - uy[i] * ux[j]
        steep = np.abs(sine) > _MIN_CORNER_SINE
        t = ((mx[j] - mx[i]) * uy[j] - (my[j] - my[i]) * ux[j]) / np.where(steep, sine, 1.0)
        cross_x = mx[i] + t * ux[i]
        cross_y = my[i] + t * uy[i]
        # The corner lies near the shared point, or between the two adjacent points.
        ax, ay = x[seg_last[i]], y[seg_last[i]]
        bx, by = x[seg_first[j]], y[seg_first[j]]
        reach = tolerance + 0.5 * np.hypot(bx - ax, by - ay)
        near = np.hypot(cross_x - 0.5 * (ax + bx), cross_y - 0.5 * (ay + by)) <= reach
        use_crossing = steep & near
        corner_x = np.where(use_crossing, cross_x, 0.5 * (segments[i, 2] + segments[j, 0]))
        corner_y = np.where(use_crossing, cross_y, 0.5 * (segments[i, 3] + segments[j, 1]))
        segments[i, 2] = corner_x
        segments[i, 3] = corner_y
        segments[j, 0] = corner_x
        segments[j, 1] = corner_y
        # A short segment between two corners can be dragged off its own points; where a
        # shared corner pushes a covered point beyond kappa (and the plain fit did not), that
        # segment keeps its own projected ends and its neighbours keep theirs.
        worse = _max_covered_distance(x, y, segments, seg_first, seg_last) > np.maximum(
            plain_worst, tolerance
        )
        undo = i[worse[i] | worse[j]]
        segments[undo, 2:] = plain[undo, 2:]
        segments[undo + 1, :2] = plain[undo + 1, :2]
    return segments, joined, seg_first, seg_last


def extract_scan(scan: LaserScanData, config: ExtractionConfig) -> tuple[SegmentScan, ScanPoints]:
    """Front end of one laser scan: validated points (with notices), then segments.

    Raises :class:`~multi_robot_mapper.core.scan.ScanError` for a scan that cannot be used.
    """
    valid = scan_points(scan, max_beams=config.max_beams)
    return extract_segments(valid.points, config), valid
