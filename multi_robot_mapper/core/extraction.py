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
split loop runs once per recursion depth, not once per segment. What makes it fast is few
numpy calls per scan (see the cost model after the imports).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.geometry import (
    arange_view as _arange,
)
from multi_robot_mapper.core.geometry import (
    ranges_index as _ranges_index,
)
from multi_robot_mapper.core.geometry import (
    segment_distance_1d as _segment_distance,
)
from multi_robot_mapper.core.scan import LaserScanData, ScanError, ScanPoints, scan_points

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# The refit may leave a point this much beyond kappa before the segment is split again: at a
# sparse corner the line tilts towards the corner point (which lies on the other wall), and
# splitting there would only carve a two-point sliver.
REFIT_SLACK = 0.005  # m

# Below this |sin| between two consecutive segments their lines are too close to parallel for a
# stable intersection; the corner is then the midpoint of the two projected ends. (A 0-d array:
# see the cost model just below.)
_MIN_CORNER_SINE = np.asarray(np.sin(np.radians(2.0)))

# Cost model: a numpy call on a few hundred elements costs about a microsecond whatever it
# computes, and a 180-beam scan has only ~150 points and ~13 segments, so the front end's speed
# is the number of numpy calls it makes, not its arithmetic. Hence every step works on all
# pieces of the scan at once, settled pieces leave the split's working set, numpy's
# Python-level wrappers (np.clip, np.arange, np.cumsum, np.flatnonzero, ...) give way to the
# ufuncs and methods underneath, and the constants of the hot loops are 0-d arrays: a Python
# number as an operand costs a ufunc ~0.3 us more (NEP 50 promotion). None of this changes a
# single float of the results.
_ZERO, _HALF, _ONE = np.array(0.0), np.array(0.5), np.array(1.0)
_INT_ONE = np.array(1)


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
    n = len(points)
    if n == 0:
        return empty_segment_scan(points)
    cluster_first, cluster_last = cluster_bounds(points, config.cluster_distance)
    size = cluster_last - cluster_first + 1
    big = (size >= config.min_cluster_points).nonzero()[0]
    if big.size == 0:
        return empty_segment_scan(points, n)
    first, last = cluster_first[big], cluster_last[big]
    dropped = n - int(np.add.reduce(size[big]))  # clusters tile the points
    # Centred coordinates keep the cumulative moments well conditioned far from the laser.
    # (np.add.reduce / n is points.mean(axis=0) bit for bit, without its Python overhead.)
    origin = np.add.reduce(points, axis=0) / n
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
    segments.reshape(-1, 2)[...] += origin  # both end points of every segment
    point_span = np.empty((len(seg_first), 2), dtype=np.int64)
    point_span[:, 0] = seg_first
    point_span[:, 1] = seg_last
    return SegmentScan(
        segments=segments,
        joined_to_next=joined,
        point_span=point_span,
        points=points,
        dropped_points=dropped,
    )


def cluster_bounds(points: FloatArray, cluster_distance: float) -> tuple[IntArray, IntArray]:
    """First and last point index of each cluster of consecutive points closer than tau."""
    step = points[1:] - points[:-1]
    breaks = (np.hypot(step[:, 0], step[:, 1]) > cluster_distance).nonzero()[0]
    first = np.empty(breaks.size + 1, dtype=np.int64)
    last = np.empty(breaks.size + 1, dtype=np.int64)
    first[0] = 0
    np.add(breaks, 1, out=first[1:])
    last[:-1] = breaks
    last[-1] = len(points) - 1
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
    end point lies on the other wall, fails it, and the classic test decides. Pieces that pass
    are settled and leave the working set, so each pass costs only what is still open.
    ``x``, ``y`` are centred coordinates and ``moments`` their cumulative moments.
    """
    vertex = _cluster_vertex_mask(len(x), first, last)
    tol = np.array(tolerance)
    # The open pieces, as first and last point. A piece without a point between its ends
    # passes at once; filtering such pieces out would cost more numpy calls than it saves.
    a, b = first, last
    while a.size:
        # Every point of every open piece, end points included: an end point lies on the chord
        # (distance 0, so it is never the farthest point) and counts towards the line test.
        stop = b + _INT_ONE
        index, piece, start = _ranges_index(a, stop)
        px, py = x[index], y[index]
        pa, pb = a[piece], b[piece]
        dist = _segment_distance(px, py, x[pa], y[pa], x[pb], y[pb])
        farthest = np.maximum.reduceat(dist, start)
        off_chord = farthest > tol
        if not np.count_nonzero(off_chord):
            break  # every open piece is settled (often so in the last pass): no line needed
        mx, my, ux, uy = _tls_lines(moments, a, stop)
        residual = np.abs((px - mx[piece]) * uy[piece] - (py - my[piece]) * ux[piece])
        off_line = np.maximum.reduceat(residual, start) > tol
        failing = (off_chord & off_line).nonzero()[0]
        if failing.size == 0:
            break
        # The farthest point from the chord in every failing piece (ties: the first).
        count = dist.size
        at = np.where(dist == farthest[piece], _arange(count), count)
        new_vertex = index[np.minimum.reduceat(at, start)[failing]]
        vertex[new_vertex] = True
        a = np.concatenate((a[failing], new_vertex))
        b = np.concatenate((new_vertex, b[failing]))
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


def _tls_lines(
    moments: FloatArray, first: IntArray, stop: IntArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Centroid and unit direction of the total-least-squares line of each point range.

    The range of line k is ``first[k]`` up to, not including, ``stop[k]``; ``moments`` are
    the cumulative sums of ``_cumulative_moments``.
    """
    sums = moments.take(stop, axis=1) - moments.take(first, axis=1)
    mean = sums[:5] / sums[5]  # of x, y, x^2, xy, y^2
    # cxx, cxy, cyy in one operation each for all three
    cov = mean[2:] - mean.take(_COVARIANCE_LEFT, axis=0) * mean.take(_COVARIANCE_RIGHT, axis=0)
    cxy = cov[1]
    phi = _HALF * np.arctan2(cxy + cxy, cov[0] - cov[2])  # direction of largest variance
    return mean[0], mean[1], np.cos(phi), np.sin(phi)


# Rows of the means multiplied for the covariances: x x, x y, y y.
_COVARIANCE_LEFT = np.array([0, 0, 1])
_COVARIANCE_RIGHT = np.array([0, 1, 1])


def _cumulative_moments(x: FloatArray, y: FloatArray) -> FloatArray:
    """Running sums of x, y, x^2, xy, y^2 and of the point count, one row each, with a leading
    zero column: the sums over points i..j-1 are ``moments[:, j] - moments[:, i]``."""
    n = len(x)
    moments = np.empty((6, n + 1))
    moments[:5, 0] = 0.0
    body = moments[:5, 1:]
    body[0] = x
    body[1] = y
    np.multiply(x, x, out=body[2])
    np.multiply(x, y, out=body[3])
    np.multiply(y, y, out=body[4])
    np.add.accumulate(body, axis=1, out=body)  # np.cumsum
    moments[5] = _arange(n + 1)
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
    first, last = seg_first, seg_last
    tol = np.array(tolerance)
    while len(first) > 1:
        pair = (last[:-1] == first[1:]).nonzero()[0]
        if pair.size == 0:
            break
        lo, stop = first[pair], last[pair + _INT_ONE] + _INT_ONE
        mx, my, ux, uy = _tls_lines(moments, lo, stop)
        idx, owner, start = _ranges_index(lo, stop)
        residual = np.abs((x[idx] - mx[owner]) * uy[owner] - (y[idx] - my[owner]) * ux[owner])
        worst = np.maximum.reduceat(residual, start)
        qualifies = worst <= tol
        n_qualify = np.count_nonzero(qualifies)
        if n_qualify == 0:
            break
        score = np.where(qualifies, worst, np.inf)
        # Pairs k and k+1 share a segment exactly when pair[k+1] == pair[k] + 1.
        left = np.full(pair.size, np.inf)
        right = np.full(pair.size, np.inf)
        touch = pair[1:] == pair[:-1] + 1
        left[1:] = np.where(touch, score[:-1], np.inf)
        right[:-1] = np.where(touch, score[1:], np.inf)
        chosen = pair[qualifies & (score < left) & (score <= right)]
        if chosen.size == 0:
            break
        last = last.copy()
        last[chosen] = last[chosen + 1]
        keep = np.ones(len(first), dtype=bool)
        keep[chosen + 1] = False
        first, last = first[keep], last[keep]
        if chosen.size == n_qualify:
            break  # nothing was held back: another pass would find nothing new
    return first, last


def _pieces(vertex: BoolArray, first: IntArray, last: IntArray) -> tuple[IntArray, IntArray]:
    """Consecutive vertex pairs inside one cluster: each segment's first and last point."""
    v = vertex.nonzero()[0]
    cluster_of = first.searchsorted(v, side="right")
    same = cluster_of[:-1] == cluster_of[1:]
    return v[:-1][same], v[1:][same]


class _LineFit(NamedTuple):
    """Total-least-squares fit of each segment, and its covered points (see ``_fit_lines``)."""

    mx: FloatArray  # centroid
    my: FloatArray
    ux: FloatArray  # unit direction, along the scan
    uy: FloatArray
    segments: FloatArray  # (K, 4): the line spanning all projections of the segment's points
    px: FloatArray  # covered points, segment after segment (a shared corner point twice)
    py: FloatArray
    owner: IntArray  # the segment of each covered point
    start: IntArray  # offset of each segment's first point in px, py
    across: FloatArray  # distance of each covered point to its segment's line


def _fit_lines(
    x: FloatArray, y: FloatArray, moments: FloatArray, seg_first: IntArray, seg_last: IntArray
) -> _LineFit:
    """TLS line of each segment's points, directed along the scan, spanning their projections."""
    seg_stop = seg_last + _INT_ONE
    mx, my, ux, uy = _tls_lines(moments, seg_first, seg_stop)
    flip = ux * (x[seg_last] - x[seg_first]) + uy * (y[seg_last] - y[seg_first]) < _ZERO
    np.negative(ux, out=ux, where=flip)
    np.negative(uy, out=uy, where=flip)
    # The segment spans the projections of all its points: in a folded cluster (a chair leg
    # seen edge-on) a middle point can project beyond the first and last ones.
    idx, owner, start = _ranges_index(seg_first, seg_stop)
    px, py = x[idx], y[idx]
    dx, dy = px - mx[owner], py - my[owner]
    uxo, uyo = ux[owner], uy[owner]
    along = dx * uxo + dy * uyo
    across = np.abs(dx * uyo - dy * uxo)
    t0 = np.minimum.reduceat(along, start)
    t1 = np.maximum.reduceat(along, start)
    segments = np.empty((len(seg_first), 4))
    np.add(mx, t0 * ux, out=segments[:, 0])
    np.add(my, t0 * uy, out=segments[:, 1])
    np.add(mx, t1 * ux, out=segments[:, 2])
    np.add(my, t1 * uy, out=segments[:, 3])
    return _LineFit(mx, my, ux, uy, segments, px, py, owner, start, across)


def drop_corner_slivers(seg_first: IntArray, seg_last: IntArray) -> tuple[IntArray, IntArray]:
    """Remove two-point segments inside a chain: the two beams that straddle a corner.

    When a corner falls between two beams, recursive split makes both of them vertices and
    leaves a segment from the last point of one wall to the first point of the next. Without it
    the two walls' segments touch (their point ranges are adjacent) and meet at the corner.
    """
    if len(seg_first) < 3:
        return seg_first, seg_last
    inside_first, inside_last = seg_first[1:-1], seg_last[1:-1]
    sliver = (
        (inside_last - inside_first == 1)
        & (seg_last[:-2] == inside_first)
        & (inside_last == seg_first[2:])
    )
    if not np.count_nonzero(sliver):
        return seg_first, seg_last
    # Two slivers in a row are a short wall, not a corner: keep both of them.
    lone = sliver.copy()
    lone[1:] &= ~sliver[:-1]
    lone[:-1] &= ~sliver[1:]
    drop = np.zeros(len(seg_first), dtype=bool)
    drop[1:-1] = lone
    keep = ~drop
    return seg_first[keep], seg_last[keep]


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
    over each segment's (inclusive) point range come from cumulative sums, so a corner point
    shared by two segments is fitted by both. Returns the segments, ``joined_to_next`` and the
    (possibly refined) point spans, in the (centred) frame of ``x``, ``y``.
    """
    tol = np.array(tolerance)
    fit, worst, seg_first, seg_last = _fit_within_tolerance(
        x, y, moments, seg_first, seg_last, tol, enforce_tolerance
    )
    # Consecutive pieces of one polyline share a corner point, or (after a corner sliver was
    # dropped) hold adjacent points of one cluster. Below, index 0 of every "pair" array is
    # the pair of segments 0 and 1, and so on.
    pair = (seg_first[1:] - seg_last[:-1] <= _INT_ONE) & (
        cluster_first.searchsorted(seg_first[1:], side="right")
        == cluster_first.searchsorted(seg_last[:-1], side="right")
    )
    joined = np.zeros(len(seg_first), dtype=bool)
    joined[:-1] = pair
    if not np.count_nonzero(pair):
        return fit.segments, joined, seg_first, seg_last
    segments = _shared_corners(x, y, fit, worst, pair, seg_first, seg_last, tol)
    return segments, joined, seg_first, seg_last


def _fit_within_tolerance(
    x: FloatArray,
    y: FloatArray,
    moments: FloatArray,
    seg_first: IntArray,
    seg_last: IntArray,
    tol: FloatArray,
    enforce_tolerance: bool,
) -> tuple[_LineFit, FloatArray, IntArray, IntArray]:
    """The TLS fit of each segment (:func:`refit_segments`), each segment's farthest covered
    point from its line, and the point spans; with ``enforce_tolerance`` a segment is split
    again at its farthest point until none leaves one beyond ``tol + REFIT_SLACK``."""
    while True:
        fit = _fit_lines(x, y, moments, seg_first, seg_last)
        worst = np.maximum.reduceat(fit.across, fit.start)
        if not enforce_tolerance:
            break
        # A segment of two points lies on its line exactly; beyond the tolerance it is only
        # rounding (coordinates of a corrupt range near 1e15 m), and it cannot be split: never
        # split it, or the loop would never end.
        over = (worst > tol + REFIT_SLACK) & (seg_last - seg_first >= 2)
        if not np.count_nonzero(over):
            break
        # Each offending segment's farthest point (first of ties), as an offset in its range;
        # an end point is split off by cutting one point inwards. (Rare: a few scans a log.)
        hit = ((fit.across == worst[fit.owner]) & over[fit.owner]).nonzero()[0]
        owner = fit.owner[hit]
        leader = np.concatenate(([True], owner[1:] != owner[:-1]))
        hit, owner = hit[leader], owner[leader]
        count = seg_last - seg_first + 1
        local = np.clip(hit - fit.start[owner], 1, count[owner] - 2)
        new_vertex = seg_first[owner] + local
        at = np.searchsorted(seg_first, new_vertex, side="right")
        seg_first = np.insert(seg_first, at, new_vertex)
        seg_last = np.insert(seg_last, at - 1, new_vertex)
    return fit, worst, seg_first, seg_last


def _shared_corners(
    x: FloatArray,
    y: FloatArray,
    fit: _LineFit,
    worst: FloatArray,
    pair: BoolArray,
    seg_first: IntArray,
    seg_last: IntArray,
    tol: FloatArray,
) -> FloatArray:
    """The fitted segments with the ends of each joined ``pair`` of consecutive segments on
    their shared corner: the crossing of their lines near the shared point, else the midpoint
    of the two projected ends; where that drags a covered point farther from its segment than
    the plain fit did (and beyond ``tol``), both keep their projected ends."""
    mx, my, ux, uy = fit.mx, fit.my, fit.ux, fit.uy
    # Computed for every consecutive pair (slices, no gathers) and applied to joined ones.
    ux0, uy0, ux1, uy1 = ux[:-1], uy[:-1], ux[1:], uy[1:]
    sine = ux0 * uy1 - uy0 * ux1
    steep = np.abs(sine) > _MIN_CORNER_SINE
    t = ((mx[1:] - mx[:-1]) * uy1 - (my[1:] - my[:-1]) * ux1) / np.where(steep, sine, _ONE)
    cross_x = mx[:-1] + t * ux0
    cross_y = my[:-1] + t * uy0
    # The corner lies near the shared point, or between the two adjacent points.
    ax, ay = x[seg_last[:-1]], y[seg_last[:-1]]
    bx, by = x[seg_first[1:]], y[seg_first[1:]]
    reach = tol + _HALF * np.hypot(bx - ax, by - ay)
    near = np.hypot(cross_x - _HALF * (ax + bx), cross_y - _HALF * (ay + by)) <= reach
    use_crossing = steep & near
    # Otherwise the midpoint of the two projected ends.
    plain = fit.segments
    corner = _HALF * (plain[:-1, 2:] + plain[1:, :2])
    np.copyto(corner[:, 0], cross_x, where=use_crossing)
    np.copyto(corner[:, 1], cross_y, where=use_crossing)
    segments = plain.copy()
    np.copyto(segments[:-1, 2:], corner, where=pair[:, None])
    np.copyto(segments[1:, :2], corner, where=pair[:, None])
    # A short segment between two corners can be dragged off its own points; where a
    # shared corner pushes a covered point beyond kappa (and the plain fit did not), that
    # segment keeps its own projected ends and its neighbours keep theirs.
    seg = segments.take(fit.owner, axis=0)
    dist = _segment_distance(fit.px, fit.py, seg[:, 0], seg[:, 1], seg[:, 2], seg[:, 3])
    worse = np.maximum.reduceat(dist, fit.start) > np.maximum(worst, tol)
    undo = (pair & (worse[:-1] | worse[1:]))[:, None]
    np.copyto(segments[:-1, 2:], plain[:-1, 2:], where=undo)
    np.copyto(segments[1:, :2], plain[1:, :2], where=undo)
    return segments


def extract_scan(scan: LaserScanData, config: ExtractionConfig) -> tuple[SegmentScan, ScanPoints]:
    """Front end of one laser scan: validated points (with notices), then segments.

    Raises :class:`~multi_robot_mapper.core.scan.ScanError` for a scan that cannot be used.
    """
    valid = scan_points(scan, max_beams=config.max_beams)
    span = abs(scan.angle_increment) * (valid.beam_count - 1)
    if span < config.min_field_of_view:
        raise ScanError(
            "field_of_view",
            f"{valid.beam_count} beams at angle_increment {scan.angle_increment:.3g} rad span "
            f"{math.degrees(span):.3g} deg, less than min_field_of_view "
            f"{math.degrees(config.min_field_of_view):.3g} deg: no laser makes such a scan",
            field="angle_increment",
        )
    if len(valid.points) == 0:
        raise ScanError(
            "no_valid_ranges",
            f"none of the {valid.beam_count} ranges is a finite reading in "
            f"[range_min={scan.range_min:g}, range_max={scan.range_max:g}) m",
            field="ranges",
        )
    return extract_segments(valid.points, config), valid
