"""A grid index of wall segments: which walls can a laser at ``(x, y)`` reach?

A generated building of 200 m holds thousands of segments, but a laser sees only those within
its maximum range. :class:`SegmentGrid` lists, for each square cell of a grid built once per
building, every segment whose bounding box comes within ``reach`` of the cell; a query looks up
the cell of the laser and keeps the listed segments within ``reach`` of it. Casting only
against those gives bitwise the ranges of casting against all segments (a segment farther than
the maximum range is never hit, and the ray caster solves each beam-wall pair on its own, so a
minimum over fewer walls is the same number), at the cost of a small world.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.geometry import point_segment_distance, ranges_index

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Cells are this share of the reach: a cell then lists about 4.7 reach^2 of walls for the
# pi reach^2 a query keeps, and each segment sits in about 50 cells.
_CELLS_PER_REACH = 3.0
_MIN_CELL_M = 1.0
# Slack on the reach so that rounding never drops a segment a beam can just reach.
_REACH_SLACK_M = 1e-6
_FEW = 128  # segments listed in a cell: below this, near() skips measuring them
_NONE = np.zeros(0, dtype=np.int64)
_NONE.flags.writeable = False


@dataclasses.dataclass(frozen=True)
class SegmentGrid:
    """Segments bucketed on a square grid for "within ``reach`` of a point" queries.

    Cell ``(i, j)`` covers ``origin + cell * [i, i + 1) x [j, j + 1)``; its segments are
    ``members[starts[i * rows + j]:starts[i * rows + j + 1]]``, in ascending order.
    """

    segments: FloatArray  # (W, 4) x1, y1, x2, y2
    reach: float  # m
    origin: FloatArray  # (2,) m, lower-left corner of cell (0, 0)
    cell: float  # m, side of a cell
    columns: int
    rows: int
    starts: IntArray  # (columns * rows + 1,) offsets into members
    members: IntArray  # segment indices, cell after cell

    def listed(self, x: float, y: float) -> IntArray:
        """The segments listed for the cell holding ``(x, y)`` (none outside the grid): every
        segment within ``reach`` of the point, and some farther ones."""
        i = int(np.floor((x - self.origin[0]) / self.cell))
        j = int(np.floor((y - self.origin[1]) / self.cell))
        if not (0 <= i < self.columns and 0 <= j < self.rows):
            return _NONE
        k = i * self.rows + j
        return self.members[self.starts[k] : self.starts[k + 1]]

    def near(self, x: float, y: float) -> IntArray:
        """Every segment within ``reach`` of ``(x, y)``: :meth:`within` when the cell lists
        many, the cell's whole list when it lists few (measuring them would cost more than
        a ray caster spends on the farther ones, which it never hits)."""
        listed = self.listed(x, y)
        return listed if listed.size <= _FEW else self.within(x, y)

    def within(self, x: float, y: float) -> IntArray:
        """Indices (ascending) of the segments within ``reach`` of ``(x, y)``."""
        listed = self.listed(x, y)
        if listed.size == 0:
            return listed
        s = self.segments[listed]
        distance = point_segment_distance(
            np.asarray(x), np.asarray(y), s[:, 0], s[:, 1], s[:, 2], s[:, 3]
        )
        return listed[distance <= self.reach + _REACH_SLACK_M]


def segment_grid(segments: FloatArray, reach: float, cell: float | None = None) -> SegmentGrid:
    """Index ``segments`` for queries of radius ``reach`` (m) on cells of side ``cell`` m
    (default a third of the reach, at least 1 m)."""
    if not (np.isfinite(reach) and reach > 0.0):
        raise ValueError(f"reach must be a positive number of metres, got {reach}")
    side = float(cell) if cell is not None else max(_MIN_CELL_M, reach / _CELLS_PER_REACH)
    if not (np.isfinite(side) and side > 0.0):
        raise ValueError(f"cell must be a positive number of metres, got {cell}")
    segs = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    if len(segs) == 0:
        return SegmentGrid(segs, reach, np.zeros(2), side, 0, 0, np.zeros(1, np.int64), _NONE)
    margin = reach + _REACH_SLACK_M
    lo = np.minimum(segs[:, :2], segs[:, 2:]) - margin
    hi = np.maximum(segs[:, :2], segs[:, 2:]) + margin
    origin = lo.min(axis=0)
    columns, rows = (np.floor((hi.max(axis=0) - origin) / side).astype(np.int64) + 1).tolist()
    cells, owners = cells_of_boxes(np.hstack((lo, hi)), origin, side, columns, rows)
    order = np.argsort(cells, kind="stable")  # segments stay ascending within a cell
    counts = np.bincount(cells, minlength=columns * rows)
    starts = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    return SegmentGrid(segs, reach, origin, side, columns, rows, starts, owners[order])


def cells_of_boxes(
    boxes: FloatArray, origin: FloatArray, cell: float, columns: int, rows: int
) -> tuple[IntArray, IntArray]:
    """Every (cell, box) pair of a grid whose cell the box ``(x0, y0, x1, y1)`` touches:
    flat cell indices ``i * rows + j`` and the box of each, box after box."""
    i0 = np.clip(np.floor((boxes[:, 0] - origin[0]) / cell).astype(np.int64), 0, columns - 1)
    j0 = np.clip(np.floor((boxes[:, 1] - origin[1]) / cell).astype(np.int64), 0, rows - 1)
    i1 = np.clip(np.floor((boxes[:, 2] - origin[0]) / cell).astype(np.int64), 0, columns - 1)
    j1 = np.clip(np.floor((boxes[:, 3] - origin[1]) / cell).astype(np.int64), 0, rows - 1)
    height = j1 - j0 + 1
    count = (i1 - i0 + 1) * height
    entry, owner, _ = ranges_index(np.zeros_like(count), count)
    i = i0[owner] + entry // height[owner]
    j = j0[owner] + entry % height[owner]
    return i * rows + j, owner


def segment_distances(a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance between segment ``a[k]`` and segment ``b[k]`` for each row (0 where they
    cross): the nearest of the four end-to-segment distances otherwise."""
    d = np.minimum.reduce(
        [
            point_segment_distance(a[:, 0], a[:, 1], b[:, 0], b[:, 1], b[:, 2], b[:, 3]),
            point_segment_distance(a[:, 2], a[:, 3], b[:, 0], b[:, 1], b[:, 2], b[:, 3]),
            point_segment_distance(b[:, 0], b[:, 1], a[:, 0], a[:, 1], a[:, 2], a[:, 3]),
            point_segment_distance(b[:, 2], b[:, 3], a[:, 0], a[:, 1], a[:, 2], a[:, 3]),
        ]
    )

    def side(p: FloatArray, q: FloatArray, r: FloatArray) -> FloatArray:
        """Sign of the turn p -> q -> r."""
        turn = (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
        return np.asarray(np.sign(turn))

    a1, a2, b1, b2 = a[:, :2], a[:, 2:], b[:, :2], b[:, 2:]
    crossing = (side(a1, a2, b1) * side(a1, a2, b2) < 0) & (side(b1, b2, a1) * side(b1, b2, a2) < 0)
    return np.asarray(np.where(crossing, 0.0, d))


def clearances(paths: FloatArray, obstacles: FloatArray, limit: float) -> FloatArray:
    """For each segment of ``paths`` (P, 4): its distance to the nearest of ``obstacles``
    (W, 4), or ``inf`` when none is within ``limit`` m of it (vectorised: only obstacles whose
    bounding box comes within ``limit`` of the path's are measured)."""
    result = np.full(len(paths), np.inf)
    if len(paths) == 0 or len(obstacles) == 0:
        return result
    side = max(_MIN_CELL_M, 2.0 * limit)
    path_boxes = np.hstack(
        (np.minimum(paths[:, :2], paths[:, 2:]) - limit, np.maximum(paths[:, :2], paths[:, 2:]))
    )
    path_boxes[:, 2:] += limit
    wall_boxes = np.hstack(
        (
            np.minimum(obstacles[:, :2], obstacles[:, 2:]),
            np.maximum(obstacles[:, :2], obstacles[:, 2:]),
        )
    )
    origin = np.minimum(path_boxes[:, :2].min(axis=0), wall_boxes[:, :2].min(axis=0))
    top = np.maximum(path_boxes[:, 2:].max(axis=0), wall_boxes[:, 2:].max(axis=0))
    columns, rows = (np.floor((top - origin) / side).astype(np.int64) + 1).tolist()
    path_cells, path_owner = cells_of_boxes(path_boxes, origin, side, columns, rows)
    wall_cells, wall_owner = cells_of_boxes(wall_boxes, origin, side, columns, rows)
    order = np.argsort(wall_cells, kind="stable")
    wall_cells, wall_owner = wall_cells[order], wall_owner[order]
    first = np.searchsorted(wall_cells, path_cells, side="left")
    stop = np.searchsorted(wall_cells, path_cells, side="right")
    shared = stop > first
    if not shared.any():
        return result
    index, owner, _ = ranges_index(first[shared], stop[shared])
    pair = np.unique(path_owner[shared][owner] * len(obstacles) + wall_owner[index])
    path_index, wall_index = np.divmod(pair, len(obstacles))
    distance = segment_distances(paths[path_index], obstacles[wall_index])
    near = distance <= limit
    np.minimum.at(result, path_index[near], distance[near])
    return result
