"""The global map: placed maps fused (Amigoni Alg. 5)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.geometry import point_segment_distance
from multi_robot_mapper.core.matching.scoring import PairTolerance

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def fuse_maps(
    segments1: FloatArray,
    owner1: IntArray,
    segments2: FloatArray,
    owner2: IntArray,
    pair: PairTolerance,
    tolerance: float,
) -> tuple[FloatArray, IntArray]:
    """S1 fused with S2 (already in S1's frame), Amigoni Alg. 5 (core.fusion), wall by wall,
    with INTEGRATE's ``pair`` tolerances and the fusion ``tolerance`` (``fusion_tolerance``).

    Fusion compares every pair of segments it is given, yet a segment only ever fuses with
    (or is covered by) segments of the other set lying within the fusion distance (three
    ``fusion_tolerance``) and, unless it is covered whole, running the same way: the two sets
    are cut into groups connected by such pairs (:func:`_related_pairs`), the groups are fused
    a few at a time (their segments never interact), and segments related to nothing in the
    other set are kept as they are. The result is the fusion of the whole sets (in another
    order), at a cost that grows with the overlap, not with the product of the maps' sizes."""
    if len(segments1) == 0 or len(segments2) == 0:
        return (
            np.vstack((segments1.reshape(-1, 4), segments2.reshape(-1, 4))),
            np.concatenate((owner1, owner2)).astype(np.int64),
        )
    limit = 3.0 * tolerance  # fuse()'s default max_distance
    first, second = _related_pairs(segments1, segments2, limit, pair.max_angle)
    n1, n2 = len(segments1), len(segments2)
    graph = coo_matrix((np.ones(first.size), (first, n1 + second)), shape=(n1 + n2, n1 + n2))
    _, label = connected_components(graph, directed=False)
    linked = np.zeros(n1 + n2, dtype=bool)
    linked[first] = True
    linked[n1 + second] = True
    parts = [segments1[~linked[:n1]], segments2[~linked[n1:]]]
    owners = [owner1[~linked[:n1]], owner2[~linked[n1:]]]
    groups = np.unique(label[linked])
    order = np.argsort(label, kind="stable")
    starts = np.searchsorted(label[order], groups, side="left")
    stops = np.searchsorted(label[order], groups, side="right")
    batch: list[IntArray] = []
    size = 0
    for k, (start, stop) in enumerate(zip(starts, stops, strict=True)):
        batch.append(order[start:stop])
        size += stop - start
        if size < _BATCH and k < len(groups) - 1:
            continue
        members = np.concatenate(batch)
        in1, in2 = members[members < n1], members[members >= n1] - n1
        fused, owner = fuse(
            segments1[in1],
            owner1[in1],
            segments2[in2],
            owner2[in2],
            pair,
            tolerance,
        )
        parts.append(fused)
        owners.append(owner)
        batch, size = [], 0
    return np.vstack(parts).reshape(-1, 4), np.concatenate(owners).astype(np.int64)


_CELL = 2.0  # m, the grid that finds the pairs of nearby bounding boxes
_BATCH = 64  # segments of unrelated groups fused in one call (fusion's cost is per pair)


def _related_pairs(
    segments1: FloatArray, segments2: FloatArray, limit: float, max_angle: float
) -> tuple[IntArray, IntArray]:
    """Every pair (i, j) of an S1 and an S2 segment that fusion may relate: within ``limit``
    of each other (they touch, cross or an end point lies that close to the other) and
    running the same way within ``max_angle``, or the S2 segment within ``limit`` of the S1
    segment at both ends (covered, whatever its direction). Candidates come from bounding
    boxes drawn on a grid of ``_CELL``."""
    low1 = np.minimum(segments1[:, :2], segments1[:, 2:]) - limit
    high1 = np.maximum(segments1[:, :2], segments1[:, 2:]) + limit
    low2 = np.minimum(segments2[:, :2], segments2[:, 2:])
    high2 = np.maximum(segments2[:, :2], segments2[:, 2:])
    origin = np.minimum(low1.min(axis=0), low2.min(axis=0))
    cells1, index1 = _cells(low1, high1, origin)
    cells2, index2 = _cells(low2, high2, origin)
    order = np.argsort(cells2, kind="stable")
    cells2, index2 = cells2[order], index2[order]
    lo = np.searchsorted(cells2, cells1, side="left")
    hi = np.searchsorted(cells2, cells1, side="right")
    count = hi - lo
    first = np.repeat(index1, count)
    start = np.repeat(np.cumsum(count) - count, count)
    second = index2[np.repeat(lo, count) + np.arange(first.size) - start]
    key = np.unique(first * len(segments2) + second)
    a, b = key // len(segments2), key % len(segments2)
    box = (low1[a] <= high2[b]).all(axis=1) & (high1[a] >= low2[b]).all(axis=1)
    a, b = a[box], b[box]
    s1, s2 = segments1[a], segments2[b]

    def to_first(x: FloatArray, y: FloatArray) -> FloatArray:
        return point_segment_distance(x, y, s1[:, 0], s1[:, 1], s1[:, 2], s1[:, 3])

    def to_second(x: FloatArray, y: FloatArray) -> FloatArray:
        return point_segment_distance(x, y, s2[:, 0], s2[:, 1], s2[:, 2], s2[:, 3])

    end1, end2 = to_first(s2[:, 0], s2[:, 1]), to_first(s2[:, 2], s2[:, 3])
    covered = (end1 <= limit) & (end2 <= limit)
    gap = np.minimum.reduce(
        [end1, end2, to_second(s1[:, 0], s1[:, 1]), to_second(s1[:, 2], s1[:, 3])]
    )
    touching = (gap <= limit) | _cross(s1, s2)
    angle1 = np.arctan2(s1[:, 3] - s1[:, 1], s1[:, 2] - s1[:, 0])
    angle2 = np.arctan2(s2[:, 3] - s2[:, 1], s2[:, 2] - s2[:, 0])
    turn = np.abs(np.mod(angle1 - angle2 + 0.5 * np.pi, np.pi) - 0.5 * np.pi)
    related = covered | (touching & (turn <= max_angle + 1e-9))
    return a[related], b[related]


def _cross(s1: FloatArray, s2: FloatArray) -> BoolArray:
    """Row-wise: do the segments of ``s1`` and ``s2`` cross?"""

    def side(p: FloatArray, q: FloatArray, r: FloatArray) -> FloatArray:
        return np.asarray(
            (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
        )

    a, b, c, d = s1[:, :2], s1[:, 2:], s2[:, :2], s2[:, 2:]
    return np.asarray(
        (side(a, b, c) * side(a, b, d) <= 0.0) & (side(c, d, a) * side(c, d, b) <= 0.0)
    )


def _cells(low: FloatArray, high: FloatArray, origin: FloatArray) -> tuple[IntArray, IntArray]:
    """The grid cells each box covers: (cell ids, box index) of every (box, cell)."""
    a = np.floor((low - origin) / _CELL).astype(np.int64)
    b = np.floor((high - origin) / _CELL).astype(np.int64)
    nx, ny = b[:, 0] - a[:, 0] + 1, b[:, 1] - a[:, 1] + 1
    count = nx * ny
    box = np.repeat(np.arange(len(low)), count)
    step = np.arange(box.size) - np.repeat(np.cumsum(count) - count, count)
    x = a[box, 0] + step % nx[box]
    y = a[box, 1] + step // nx[box]
    return x * 1_000_003 + y, box


def as_map(segments: FloatArray) -> FloatArray:
    array = np.asarray(segments, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 4:
        if array.size == 0:
            return np.zeros((0, 4))
        raise ValueError(f"a partial map must be an (N, 4) segment array, got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("a partial map holds NaN or infinite coordinates")
    return array
