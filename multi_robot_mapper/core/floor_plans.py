"""Floor plans as free-space rectangles: the walls and glass where spaces meet, and the graph of
waypoints robots drive on (used by :mod:`core.buildings`).

A :class:`Layout` is a set of axis-aligned rectangles, each one space (a room, a corridor or a
hall), plus openings (doors: gaps in the wall between two spaces), glass spans (the wall pieces
along them are glass panes) and obstacles (pillars, cabinets). Walls go wherever two spaces
meet, or a space meets solid ground, except across an opening; they are found on the grid of
every distinct coordinate, so a mirrored or rotated layout gives exactly the mirrored or
rotated walls. Coordinates are metres in the ``world`` frame.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

ROOM, CORRIDOR, HALL = 0, 1, 2  # kinds of space
SPACE_KINDS = ("room", "corridor", "hall")
NODE_KINDS = ("room", "door", "corridor", "hall")  # kinds of waypoint, indices as below
_NODE_ROOM, _NODE_DOOR, _NODE_CORRIDOR, _NODE_HALL = 0, 1, 2, 3
# Corridor waypoints are at most this far apart (m), so a robot can turn round mid-corridor.
CORRIDOR_SPACING_M = 4.0
# A door is crossed square on: its waypoint, then one this far (m) inside a room or hall.
APPROACH_M = 0.7
_HALL_INSET_M = 1.0  # default hall waypoints keep this far from the hall's walls
_HALL_LINKS = 4  # a door into a hall links to this many of the hall's nearest waypoints
_EMPTY = np.zeros((0, 4))


@dataclasses.dataclass(frozen=True)
class Layout:
    """Free space as rectangles, with the doors, glass and obstacles that go with them."""

    rects: FloatArray  # (R, 4) x0, y0, x1, y1 (x0 < x1, y0 < y1), each one space
    kinds: IntArray  # (R,) ROOM, CORRIDOR or HALL
    openings: FloatArray  # (D, 4) axis-aligned spans between two spaces: no wall
    glass: FloatArray  # (G, 4) axis-aligned spans whose wall pieces are glass
    obstacles: FloatArray  # (P, 4) returning segments in free space
    # Per rectangle: a hall's waypoint lines (x's, y's), or None for rooms, corridors and
    # halls with the default grid.
    lanes: tuple[tuple[FloatArray, FloatArray] | None, ...]

    def lanes_of(self, r: int) -> tuple[FloatArray, FloatArray] | None:
        return self.lanes[r] if r < len(self.lanes) else None


def layout(
    rects: Sequence[Sequence[float]],
    kinds: Sequence[int],
    openings: Sequence[Sequence[float]] = (),
    glass: Sequence[Sequence[float]] = (),
    obstacles: FloatArray | None = None,
    lanes: Sequence[tuple[FloatArray, FloatArray] | None] = (),
) -> Layout:
    """A :class:`Layout` from lists (empty lists allowed)."""
    return Layout(
        np.asarray(rects, dtype=np.float64).reshape(-1, 4),
        np.asarray(kinds, dtype=np.int64).reshape(-1),
        np.asarray(openings, dtype=np.float64).reshape(-1, 4),
        np.asarray(glass, dtype=np.float64).reshape(-1, 4),
        _EMPTY if obstacles is None else np.asarray(obstacles, dtype=np.float64).reshape(-1, 4),
        tuple(lanes) + (None,) * (len(rects) - len(lanes)),
    )


def mirrored(plan: Layout) -> Layout:
    """The layout mirrored about the y axis (x -> -x, exact in floating point)."""
    rects = plan.rects[:, [2, 1, 0, 3]] * [-1.0, 1.0, -1.0, 1.0]
    flip = np.array([-1.0, 1.0, -1.0, 1.0])
    lanes = tuple(None if ln is None else (-ln[0][::-1], ln[1]) for ln in plan.lanes)
    return Layout(
        rects,
        plan.kinds,
        plan.openings * flip,
        plan.glass * flip,
        plan.obstacles * flip,
        lanes,
    )


def swapped(plan: Layout) -> Layout:
    """The layout reflected about the line y = x (x <-> y): a row of rooms along x becomes
    one along y."""
    order = [1, 0, 3, 2]
    return Layout(
        plan.rects[:, order],
        plan.kinds,
        plan.openings[:, order],
        plan.glass[:, order],
        plan.obstacles[:, order],
        tuple(None if ln is None else (ln[1], ln[0]) for ln in plan.lanes),
    )


def rotated(plan: Layout, quarter_turns: int) -> Layout:
    """The layout turned by ``quarter_turns`` x 90 degrees about the origin (exact)."""
    out = plan
    for _ in range(quarter_turns % 4):
        # (x, y) -> (-y, x): a rectangle's corners (x0, y0), (x1, y1) -> (-y1, x0), (-y0, x1).
        out = Layout(
            np.column_stack((-out.rects[:, 3], out.rects[:, 0], -out.rects[:, 1], out.rects[:, 2])),
            out.kinds,
            _turn_segments(out.openings),
            _turn_segments(out.glass),
            _turn_segments(out.obstacles),
            tuple(None if ln is None else (-ln[1][::-1], ln[0]) for ln in out.lanes),
        )
    return out


def _turn_segments(segments: FloatArray) -> FloatArray:
    return np.column_stack((-segments[:, 1], segments[:, 0], -segments[:, 3], segments[:, 2]))


def combined(plans: Sequence[Layout]) -> Layout:
    """All the plans' spaces and features in one layout; identical rectangles (a hub every
    copy shares) are kept once, as are identical openings, glass spans and obstacles."""
    rects = np.vstack([p.rects for p in plans])
    kinds = np.concatenate([p.kinds for p in plans])
    lanes = [p.lanes_of(r) for p in plans for r in range(len(p.rects))]
    _, first = np.unique(_canonical(rects), axis=0, return_index=True)
    keep = np.sort(first)
    return Layout(
        rects[keep],
        kinds[keep],
        _unique_segments(np.vstack([p.openings for p in plans])),
        _unique_segments(np.vstack([p.glass for p in plans])),
        _unique_segments(np.vstack([p.obstacles for p in plans])),
        tuple(lanes[k] for k in keep),
    )


def _canonical(values: FloatArray) -> FloatArray:
    """Rounded to 1e-9 m with -0.0 made 0.0, so equal coordinates compare equal."""
    return np.asarray(np.round(values, 9) + 0.0)


def _unique_segments(segments: FloatArray) -> FloatArray:
    if len(segments) == 0:
        return segments
    ends = _canonical(segments)
    swap = (ends[:, 0] > ends[:, 2]) | ((ends[:, 0] == ends[:, 2]) & (ends[:, 1] > ends[:, 3]))
    ends[swap] = ends[swap][:, [2, 3, 0, 1]]
    _, first = np.unique(ends, axis=0, return_index=True)
    return segments[np.sort(first)]


# ---------------------------------------------------------------------------------------------
# Walls and glass.
# ---------------------------------------------------------------------------------------------


def walls_and_glass(plan: Layout) -> tuple[FloatArray, FloatArray]:
    """The layout's returning walls (with its obstacles) and its glass panes, ``(W, 4)`` and
    ``(G, 4)``: one segment per straight run of wall between two spaces (or a space and solid
    ground), broken at openings and where glass starts or ends."""
    if len(plan.rects) == 0:
        return plan.obstacles.copy(), _EMPTY.copy()
    spans = (plan.rects[:, [0, 2]], plan.openings[:, [0, 2]], plan.glass[:, [0, 2]])
    xs = np.unique(_canonical(np.concatenate([s.ravel() for s in spans])))
    spans = (plan.rects[:, [1, 3]], plan.openings[:, [1, 3]], plan.glass[:, [1, 3]])
    ys = np.unique(_canonical(np.concatenate([s.ravel() for s in spans])))
    nx, ny = len(xs), len(ys)
    # Cell (i, j) of the padded grid lies between xs[i - 1] and xs[i] (outside at the ends).
    label = np.full((nx + 1, ny + 1), -1, dtype=np.int64)
    for r, (i0, j0, i1, j1) in enumerate(_grid_boxes(plan.rects, xs, ys)):
        label[i0 + 1 : i1 + 1, j0 + 1 : j1 + 1] = r
    between_v = label[:nx, 1:ny] != label[1:, 1:ny]  # (nx, ny - 1): on line x = xs[i]
    between_h = label[1:nx, :ny] != label[1:nx, 1:]  # (nx - 1, ny): on line y = ys[j]
    open_v, open_h = _painted(plan.openings, xs, ys)
    glass_v, glass_h = _painted(plan.glass, xs, ys)
    kind_v = np.where(between_v & ~open_v, 1 + glass_v, 0)  # 0 none, 1 wall, 2 glass
    kind_h = np.where(between_h & ~open_h, 1 + glass_h, 0)
    walls, glass = [plan.obstacles], [_EMPTY]
    for kind in (1, 2):
        runs_v = _runs(kind_v == kind)  # (line, first, last) along y
        runs_h = _runs((kind_h == kind).T)  # along x
        pieces = np.vstack(
            (
                np.column_stack(
                    (xs[runs_v[:, 0]], ys[runs_v[:, 1]], xs[runs_v[:, 0]], ys[runs_v[:, 2] + 1])
                ),
                np.column_stack(
                    (xs[runs_h[:, 1]], ys[runs_h[:, 0]], xs[runs_h[:, 2] + 1], ys[runs_h[:, 0]])
                ),
            )
        )
        (walls if kind == 1 else glass).append(pieces)
    return np.vstack(walls), np.vstack(glass)


def _grid_boxes(boxes: FloatArray, xs: FloatArray, ys: FloatArray) -> IntArray:
    """Grid indices ``(i0, j0, i1, j1)`` of boxes whose coordinates are all grid lines."""
    b = _canonical(boxes)
    return np.column_stack(
        (
            np.searchsorted(xs, np.minimum(b[:, 0], b[:, 2])),
            np.searchsorted(ys, np.minimum(b[:, 1], b[:, 3])),
            np.searchsorted(xs, np.maximum(b[:, 0], b[:, 2])),
            np.searchsorted(ys, np.maximum(b[:, 1], b[:, 3])),
        )
    ).astype(np.int64)


def _painted(spans: FloatArray, xs: FloatArray, ys: FloatArray) -> tuple[BoolArray, BoolArray]:
    """Which grid edges the axis-aligned ``spans`` cover: (on vertical lines, on horizontal)."""
    on_v = np.zeros((len(xs), len(ys) - 1), dtype=bool)
    on_h = np.zeros((len(xs) - 1, len(ys)), dtype=bool)
    for i0, j0, i1, j1 in _grid_boxes(spans, xs, ys):
        if i0 == i1:
            on_v[i0, j0:j1] = True
        elif j0 == j1:
            on_h[i0:i1, j0] = True
    return on_v, on_h


def _runs(mask: BoolArray) -> IntArray:
    """``(K, 3)`` runs of True along each row of ``mask``: (row, first column, last column)."""
    padded = np.pad(mask, ((0, 0), (1, 1)))
    step = np.diff(padded.astype(np.int8), axis=1)
    rows, first = np.nonzero(step == 1)
    _, after = np.nonzero(step == -1)
    return np.column_stack((rows, first, after - 1)).astype(np.int64)


# ---------------------------------------------------------------------------------------------
# The waypoint graph.
# ---------------------------------------------------------------------------------------------


def waypoint_graph(plan: Layout) -> tuple[FloatArray, IntArray, IntArray]:
    """Waypoints ``(N, 2)``, their kinds ``(N,)`` (index into :data:`NODE_KINDS`) and edges
    ``(E, 2)`` of the layout's free space, before any clearance check.

    A room has a waypoint at its centre, a corridor a line of them along its middle (at most
    :data:`CORRIDOR_SPACING_M` apart, one abreast of each door), a hall a grid (its lanes, or
    one every 4 m). A door has one at its middle, joined square on to the corridor's middle
    line, or to a waypoint :data:`APPROACH_M` inside a room (then on to its centre) or hall
    (then to the hall's nearest waypoints).
    """
    graph = _GraphBuilder()
    sides = [_spaces_beside(plan.rects, o) for o in plan.openings]
    anchors: dict[int, list[int]] = {}  # waypoints of each space a door can link to
    for r, (x0, y0, x1, y1) in enumerate(plan.rects):
        kind = int(plan.kinds[r])
        if kind == ROOM:
            anchors[r] = [graph.node(0.5 * (x0 + x1), 0.5 * (y0 + y1), _NODE_ROOM)]
        elif kind == CORRIDOR:
            doors = [o for o, beside in enumerate(sides) if r in beside]
            line = _corridor_line(plan.rects[r], plan.openings[doors])
            ids = [graph.node(x, y, _NODE_CORRIDOR) for x, y in line]
            graph.edges.extend(itertools.pairwise(ids))
            anchors[r] = ids
        else:
            xs, ys = plan.lanes_of(r) or _default_lanes(plan.rects[r])
            grid = np.array([[graph.node(x, y, _NODE_HALL) for y in ys] for x in xs])
            graph.edges.extend(zip(grid[:-1].ravel(), grid[1:].ravel(), strict=True))
            graph.edges.extend(zip(grid[:, :-1].ravel(), grid[:, 1:].ravel(), strict=True))
            anchors[r] = grid.ravel().tolist()
    for o, beside in enumerate(sides):
        cx, cy = 0.5 * (plan.openings[o, :2] + plan.openings[o, 2:])
        door = graph.node(cx, cy, _NODE_DOOR)
        for r in beside:
            graph.link_door(plan, r, door, anchors[r])
    return graph.merged()


@dataclasses.dataclass
class _GraphBuilder:
    """Waypoints and edges as they are made (merged and indexed by :meth:`merged`)."""

    points: list[tuple[float, float]] = dataclasses.field(default_factory=list)
    kinds: list[int] = dataclasses.field(default_factory=list)
    edges: list[tuple[int, int]] = dataclasses.field(default_factory=list)

    def node(self, x: float, y: float, kind: int) -> int:
        self.points.append((float(x), float(y)))
        self.kinds.append(kind)
        return len(self.points) - 1

    def link_door(self, plan: Layout, r: int, door: int, anchors: list[int]) -> None:
        """Join a door's waypoint to space ``r``'s waypoints (see :func:`waypoint_graph`)."""
        x0, y0, x1, y1 = plan.rects[r]
        cx, cy = self.points[door]
        kind = int(plan.kinds[r])
        if kind == CORRIDOR:  # abreast of the door on the middle line (a waypoint is there)
            if (x1 - x0) >= (y1 - y0):
                self.edges.append((door, self.node(cx, 0.5 * (y0 + y1), _NODE_CORRIDOR)))
            else:
                self.edges.append((door, self.node(0.5 * (x0 + x1), cy, _NODE_CORRIDOR)))
            return
        # Square on into the room or hall: along the inward normal of the door's side.
        if np.isclose(cx, x0) or np.isclose(cx, x1):
            inward, depth = (1.0 if np.isclose(cx, x0) else -1.0, 0.0), x1 - x0
        else:
            inward, depth = (0.0, 1.0 if np.isclose(cy, y0) else -1.0), y1 - y0
        step = min(APPROACH_M, 0.5 * depth)
        inside = self.node(cx + step * inward[0], cy + step * inward[1], _NODE_DOOR)
        self.edges.append((door, inside))
        if kind == ROOM:
            self.edges.append((inside, anchors[0]))
            return
        # A hall: on to its nearest waypoints (those a pillar blocks are dropped later).
        where = np.asarray([self.points[a] for a in anchors])
        distance = np.hypot(
            where[:, 0] - self.points[inside][0], where[:, 1] - self.points[inside][1]
        )
        for k in np.argsort(distance, kind="stable")[:_HALL_LINKS]:
            self.edges.append((inside, anchors[int(k)]))

    def merged(self) -> tuple[FloatArray, IntArray, IntArray]:
        """Coinciding waypoints as one; edges without loops or repeats."""
        points = np.asarray(self.points, dtype=np.float64).reshape(-1, 2)
        nodes, index = np.unique(_canonical(points), axis=0, return_inverse=True)
        index = index.reshape(-1).astype(np.int64)
        kinds = np.zeros(len(nodes), dtype=np.int64)
        kinds[index] = self.kinds  # a merged waypoint keeps the kind of its last source
        pairs = index[np.asarray(self.edges, dtype=np.int64).reshape(-1, 2)]
        pairs = np.sort(pairs[pairs[:, 0] != pairs[:, 1]], axis=1)
        return nodes, kinds, np.unique(pairs, axis=0).reshape(-1, 2)


def _spaces_beside(rects: FloatArray, opening: FloatArray) -> list[int]:
    """The rectangles whose side holds the whole opening (two for a door)."""
    r, o = _canonical(rects), _canonical(opening)
    if o[0] == o[2]:  # on a vertical line
        lo, hi = min(o[1], o[3]), max(o[1], o[3])
        on = ((r[:, 0] == o[0]) | (r[:, 2] == o[0])) & (r[:, 1] <= lo) & (r[:, 3] >= hi)
    else:
        lo, hi = min(o[0], o[2]), max(o[0], o[2])
        on = ((r[:, 1] == o[1]) | (r[:, 3] == o[1])) & (r[:, 0] <= lo) & (r[:, 2] >= hi)
    return np.flatnonzero(on).tolist()


def _corridor_line(rect: FloatArray, doors: FloatArray) -> list[tuple[float, float]]:
    """Waypoints along a corridor's middle: its ends (half a width in), one abreast of each
    door, and more between so that none are farther apart than CORRIDOR_SPACING_M."""
    x0, y0, x1, y1 = rect
    along_x = (x1 - x0) >= (y1 - y0)
    lo, hi = (x0, x1) if along_x else (y0, y1)
    half = 0.5 * ((y1 - y0) if along_x else (x1 - x0))
    middle = 0.5 * (y0 + y1) if along_x else 0.5 * (x0 + x1)
    ends = [lo + half, hi - half] if hi - lo > 2.0 * half else [0.5 * (lo + hi)]
    centres = 0.5 * (doors[:, 0] + doors[:, 2]) if along_x else 0.5 * (doors[:, 1] + doors[:, 3])
    stops = np.unique(_canonical(np.clip(np.concatenate((ends, centres)), lo, hi)))
    filled = [stops[:1]]
    for a, b in itertools.pairwise(stops):
        pieces = max(1, int(np.ceil((b - a) / CORRIDOR_SPACING_M - 1e-9)))
        filled.append(a + (b - a) * np.arange(1, pieces + 1) / pieces)
    t = np.concatenate(filled)
    return [(float(v), middle) if along_x else (middle, float(v)) for v in t]


def _default_lanes(rect: FloatArray) -> tuple[FloatArray, FloatArray]:
    """A grid of hall waypoints every 4 m or less, inset from the walls."""
    out = []
    for lo, hi in ((rect[0], rect[2]), (rect[1], rect[3])):
        inset = min(_HALL_INSET_M, 0.5 * (hi - lo))
        count = max(1, int(np.ceil((hi - lo - 2.0 * inset) / 4.0)) + 1)
        out.append(np.linspace(lo + inset, hi - inset, count))
    return out[0], out[1]
