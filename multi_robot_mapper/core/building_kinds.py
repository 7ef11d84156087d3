"""The kinds of generated floor plan (:data:`PLAN_KINDS`), each drawn at random from a generator
and a target size: the plan's largest extent, in metres (:mod:`core.buildings` finishes them).

Every builder returns a :class:`~core.floor_plans.Layout` and the symmetry it was built with:
``"mirror"`` (the plan is its own mirror image about the y axis, x -> -x), ``"rotation_180"``
or ``"rotation_90"`` (its own copy turned by that angle about the origin), or ``"none"``.
Every plan marks where its glass would be (glass fronts and back windows of some rooms, a
stretch of an outer wall); a building without glass has walls there instead, so the same seed
gives the same plan with and without glass.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Mapping
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.floor_plans import (
    CORRIDOR,
    HALL,
    ROOM,
    Layout,
    combined,
    layout,
    mirrored,
    rotated,
    swapped,
)
from multi_robot_mapper.core.worlds import arc, box

FloatArray = NDArray[np.float64]
Rng = np.random.Generator
Span = tuple[float, float, float, float]  # x0, y0, x1, y1

# This share of rooms has a glass front, and this share a window in the back wall.
GLASS_SHARE = 0.35
_ROOM_WIDTH_M = (3.0, 6.0)  # a room's width along its corridor
_ROOM_DEPTH_M = (3.0, 6.0)
_DOOR_M = (0.9, 1.2)
_JAMB_M = 0.5  # a door keeps this much wall between it and the room's corners


@dataclasses.dataclass(frozen=True)
class _Style:
    """What the rooms and corridors of one building share."""

    door: float  # m, door width
    corridor: float  # m, corridor width
    depth: float  # m, room depth


def _style(rng: Rng, corridor: tuple[float, float] = (1.8, 3.0)) -> _Style:
    return _Style(
        door=float(rng.uniform(*_DOOR_M)),
        corridor=float(rng.uniform(*corridor)),
        depth=float(rng.uniform(*_ROOM_DEPTH_M)),
    )


def _partition(rng: Rng, lo: float, hi: float, equal: bool) -> FloatArray:
    """Room boundaries from ``lo`` to ``hi``: equal rooms, or widths drawn at random."""
    if equal:
        count = max(1, round((hi - lo) / rng.uniform(*_ROOM_WIDTH_M)))
        edges = lo + (hi - lo) * np.arange(count + 1) / count
    else:
        widths = [rng.uniform(*_ROOM_WIDTH_M)]
        while sum(widths) < hi - lo:
            widths.append(rng.uniform(*_ROOM_WIDTH_M))
        if len(widths) > 1 and sum(widths) - (hi - lo) > 0.5 * widths[-1]:
            widths.pop()  # nearer the length without the last room than with it
        edges = lo + (hi - lo) * np.concatenate(([0.0], np.cumsum(widths))) / sum(widths)
    edges[-1] = hi
    return np.asarray(edges)


def _rooms(
    rng: Rng, style: _Style, edges: FloatArray, front: float, side: int, door_at: float | None
) -> Layout:
    """Rooms between consecutive ``edges`` (along x), their fronts on the line y = ``front``
    and their backs ``style.depth`` beyond it on ``side`` (+1 above, -1 below), each with a
    door in its front: at the same place in every room (``door_at``, a share of the room's
    free front), or anywhere."""
    y0, y1 = (front, front + style.depth) if side > 0 else (front - style.depth, front)
    rects, doors, glass = [], [], []
    for a, b in itertools.pairwise(edges):
        share = door_at if door_at is not None else rng.random()
        free = max(0.0, b - a - 2.0 * _JAMB_M - style.door)
        middle = a + _JAMB_M + 0.5 * style.door + share * free
        rects.append((a, y0, b, y1))
        doors.append((middle - 0.5 * style.door, front, middle + 0.5 * style.door, front))
        if rng.random() < GLASS_SHARE:  # a glass front onto the corridor
            glass.append((a, front, b, front))
        if rng.random() < GLASS_SHARE:  # a window in the back wall
            back = front + side * style.depth
            glass.append((a + _JAMB_M, back, b - _JAMB_M, back))
    return layout(rects, [ROOM] * len(rects), doors, glass)


def _wing(
    rng: Rng, style: _Style, x0: float, x1: float, middle: float, sides: tuple[int, ...]
) -> Layout:
    """A corridor along x from ``x0`` to ``x1`` (its middle line at y = ``middle``) with rooms
    of random widths on ``sides`` (+1 above, -1 below)."""
    half = 0.5 * style.corridor
    parts = [layout([(x0, middle - half, x1, middle + half)], [CORRIDOR])]
    for side in sides:
        edges = _partition(rng, x0, x1, equal=False)
        parts.append(_rooms(rng, style, edges, middle + side * half, side, None))
    return combined(parts)


def _outer_glass(rng: Rng, start: tuple[float, float], stop: tuple[float, float]) -> list[Span]:
    """A glass stretch of 30-90 % of the outer wall from ``start`` to ``stop``."""
    share = rng.uniform(0.3, 0.9)
    offset = rng.uniform(0.0, 1.0 - share)
    a = np.asarray(start) + offset * (np.asarray(stop) - np.asarray(start))
    b = a + share * (np.asarray(stop) - np.asarray(start))
    return [(float(a[0]), float(a[1]), float(b[0]), float(b[1]))]


def room_row(rng: Rng, size: float) -> tuple[Layout, str]:
    """A corridor ``size`` m long with a row of equal rooms on one or both sides, every door
    at the same place in its room (the same view from every doorway)."""
    style = _style(rng)
    half = 0.5 * style.corridor
    edges = _partition(rng, 0.0, size, equal=True)
    door_at = float(rng.random())
    parts = [layout([(0.0, -half, size, half)], [CORRIDOR])]
    parts.append(_rooms(rng, style, edges, half, +1, door_at))
    if rng.random() < 0.6:
        parts.append(_rooms(rng, style, edges, -half, -1, door_at))
    elif rng.random() < 0.5:  # the bare side, a glass wall in part
        parts.append(layout([], [], glass=_outer_glass(rng, (0.0, -half), (size, -half))))
    return combined(parts), "none"


def mirror_wings(rng: Rng, size: float) -> tuple[Layout, str]:
    """A wing of rooms of random widths along a corridor, and its mirror image about the y
    axis; in larger plans the wing may end in a cross wing (an H-shaped building)."""
    style = _style(rng)
    half, end = 0.5 * style.corridor, 0.5 * size
    cross_depth = float(rng.uniform(*_ROOM_DEPTH_M))
    cross = size >= 40.0 and rng.random() < 0.5
    length = end - style.corridor - cross_depth if cross else end
    parts = [_wing(rng, style, 0.0, length, 0.0, (+1, -1))]
    parts.append(layout([], [], openings=[(0.0, -half, 0.0, half)]))  # across the axis
    if cross:
        reach = half + style.depth
        span = reach + rng.uniform(3.0, max(3.0, 0.5 * size - reach - 1.0))
        span = min(span, 0.5 * size)
        x = length + style.corridor  # the cross wing's room fronts
        cross_style = dataclasses.replace(style, depth=cross_depth)
        edges = _partition(rng, -span, span, equal=False)
        # Rooms along y east of the cross corridor: built along x, then x <-> y.
        parts.append(swapped(_rooms(rng, cross_style, edges, x, +1, None)))
        parts.append(
            layout([(length, -span, x, span)], [CORRIDOR], openings=[(length, -half, length, half)])
        )
    base = combined(parts)
    return combined([base, mirrored(base)]), "mirror"


def rotation_wings(rng: Rng, size: float) -> tuple[Layout, str]:
    """A square hub with two (180 degree) or four (90 degree) copies of one wing: a corridor
    off the middle of the hub's side (so the plan is not also a mirror image) with rooms of
    random widths along it."""
    style = _style(rng)
    order = 4 if rng.random() < 0.5 else 2
    offset = float(rng.uniform(0.5, 1.5) * rng.choice([-1.0, 1.0]))
    half, end = 0.5 * style.corridor, 0.5 * size
    # The wing's rooms fit beside the hub's side, and the wing is at least 3 m long.
    depth = min(style.depth, end - 4.0 - abs(offset) - half)
    style = dataclasses.replace(style, depth=depth)
    reach = abs(offset) + half + depth
    hub = reach + min(rng.uniform(1.0, 4.0), end - 3.0 - reach)
    sides = (+1, -1) if rng.random() < 0.7 else (int(rng.choice([-1, 1])),)
    wing = _wing(rng, style, hub, end, offset, sides)
    base = combined(
        [
            layout([(-hub, -hub, hub, hub)], [HALL]),
            wing,
            layout([], [], openings=[(hub, offset - half, hub, offset + half)]),
        ]
    )
    copies = [rotated(base, k * 4 // order) for k in range(order)]
    return combined(copies), "rotation_90" if order == 4 else "rotation_180"


def bare_corridors(rng: Rng, size: float) -> tuple[Layout, str]:
    """Long corridors with few features: an L, a T or a loop, ``size`` m across, with up to
    three cabinets against the walls and nothing else."""
    width = float(rng.uniform(1.5, 3.0))
    shape = str(rng.choice(["L", "T", "loop"]))
    height = max(float(rng.uniform(0.3, 1.0)) * size, min(size, 10.0), 2.0 * width + 4.0)
    w, s, h = width, size, height
    if shape == "L":
        rects = [(0.0, 0.0, s, w), (0.0, w, w, h)]
        openings = [(0.0, w, w, w)]
    elif shape == "T":
        x = float(rng.uniform(0.15, 0.85)) * (s - w)
        rects = [(0.0, h - w, s, h), (x, 0.0, x + w, h - w)]
        openings = [(x, h - w, x + w, h - w)]
    else:
        rects = [(0.0, 0.0, s, w), (0.0, h - w, s, h), (0.0, w, w, h - w), (s - w, w, s, h - w)]
        openings = [(0.0, w, w, w), (s - w, w, s, w), (0.0, h - w, w, h - w)]
        openings.append((s - w, h - w, s, h - w))
    cabinets = _cabinets(rng, np.asarray(rects), np.asarray(openings), width)
    outer = h if shape == "T" else 0.0  # the first corridor's outer long side
    panes = _outer_glass(rng, (0.0, outer), (s, outer))
    return layout(rects, [CORRIDOR] * len(rects), openings, panes, cabinets), "none"


def _cabinets(rng: Rng, rects: FloatArray, openings: FloatArray, width: float) -> FloatArray:
    """Up to three boxes against corridor walls, each leaving the middle line 0.35 m clear
    and keeping 1.5 m from every junction."""
    deepest = 0.5 * width - 0.35
    boxes = []
    for _ in range(int(rng.integers(0, 4))):
        r = int(rng.integers(len(rects)))
        x0, y0, x1, y1 = rects[r]
        length, depth = float(rng.uniform(0.6, 1.5)), float(rng.uniform(0.15, 0.45))
        if depth > deepest:
            continue
        along_x = x1 - x0 >= y1 - y0
        lo, hi = (x0, x1) if along_x else (y0, y1)
        t = float(rng.uniform(lo + width + 1.5, max(lo + width + 1.5, hi - width - 1.5)))
        wall = (
            (y1 - 0.5 * depth, y0 + 0.5 * depth)
            if along_x
            else (x1 - 0.5 * depth, x0 + 0.5 * depth)
        )
        across = wall[int(rng.integers(2))]
        cx, cy = (t, across) if along_x else (across, t)
        ends = openings.reshape(-1, 2)
        if np.hypot(ends[:, 0] - cx, ends[:, 1] - cy).min(initial=np.inf) < 1.5 + length:
            continue
        boxes.append(box(cx, cy, length, depth) if along_x else box(cx, cy, depth, length))
    return np.vstack(boxes) if boxes else np.zeros((0, 4))


def _pillars(
    rng: Rng, rect: tuple[float, float, float, float], spacing: tuple[float, float]
) -> tuple[FloatArray, tuple[FloatArray, FloatArray] | None]:
    """A regular grid of square or round pillars centred in a hall, and the hall's waypoint
    lanes midway between the pillar rows (none where the hall is too small for pillars)."""
    x0, y0, x1, y1 = rect
    pitch = float(rng.uniform(*spacing))
    radius = float(rng.uniform(0.2, 0.4))
    round_pillars = rng.random() < 0.5
    lines = []
    for lo, hi in ((x0, x1), (y0, y1)):
        count = round((hi - lo) / pitch) - 1
        if count < 1:
            return np.zeros((0, 4)), None
        margin = 0.5 * (hi - lo - (count - 1) * pitch)
        at = lo + margin + pitch * np.arange(count)
        lanes = np.concatenate(([lo + 0.5 * margin], at[:-1] + 0.5 * pitch, [hi - 0.5 * margin]))
        lines.append((at, lanes))
    (px, lanes_x), (py, lanes_y) = lines
    pieces = [
        arc((x, y), radius, 0.0, 2.0 * np.pi, pieces=8)
        if round_pillars
        else box(x, y, 2.0 * radius, 2.0 * radius)
        for x in px
        for y in py
    ]
    return np.vstack(pieces), (lanes_x, lanes_y)


def pillar_hall(rng: Rng, size: float) -> tuple[Layout, str]:
    """One open hall ``size`` m long with a regular grid of pillars 5-9 m apart."""
    rect = (0.0, 0.0, size, max(10.0, float(rng.uniform(0.5, 1.0)) * size))
    pillars, lanes = _pillars(rng, rect, (5.0, 9.0))
    corners = [(0.0, 0.0), (rect[2], 0.0), (rect[2], rect[3]), (0.0, rect[3])]
    k = int(rng.integers(4))
    panes = _outer_glass(rng, corners[k], corners[(k + 1) % 4])
    return layout([rect], [HALL], glass=panes, obstacles=pillars, lanes=[lanes]), "none"


def mixed(rng: Rng, size: float) -> tuple[Layout, str]:
    """A pillared hall, then a corridor with equal rooms on one side and rooms of random
    widths on the other, then a bare corridor that may turn a corner."""
    style = _style(rng)
    half = 0.5 * style.corridor
    hall_x = float(rng.uniform(0.2, 0.3)) * size
    hall_y = max(6.0, float(rng.uniform(0.3, 0.6)) * size)
    rooms_end = hall_x + float(rng.uniform(0.3, 0.45)) * size
    hall = (0.0, -0.5 * hall_y, hall_x, 0.5 * hall_y)
    pillars, lanes = _pillars(rng, hall, (4.5, 7.0))
    parts = [
        layout([hall], [HALL], obstacles=pillars, lanes=[lanes]),
        layout([(hall_x, -half, rooms_end, half)], [CORRIDOR]),
        _rooms(rng, style, _partition(rng, hall_x, rooms_end, True), half, +1, rng.random()),
        layout([(rooms_end, -half, size, half)], [CORRIDOR]),
        layout(
            [], [], openings=[(hall_x, -half, hall_x, half), (rooms_end, -half, rooms_end, half)]
        ),
    ]
    if rng.random() < 0.7:
        edges = _partition(rng, hall_x, rooms_end, False)
        parts.append(_rooms(rng, style, edges, -half, -1, None))
    if rng.random() < 0.6:  # the bare corridor turns north at the end
        top = half + float(rng.uniform(0.2, 0.45)) * size
        w = style.corridor
        parts.append(
            layout([(size - w, half, size, top)], [CORRIDOR], [(size - w, half, size, half)])
        )
    parts.append(layout([], [], glass=_outer_glass(rng, hall[:2], (0.0, hall[3]))))
    return combined(parts), "none"


PLAN_KINDS: Mapping[str, Callable[[Rng, float], tuple[Layout, str]]] = MappingProxyType(
    {
        "room_row": room_row,
        "mirror_wings": mirror_wings,
        "rotation_wings": rotation_wings,
        "bare_corridors": bare_corridors,
        "pillar_hall": pillar_hall,
        "mixed": mixed,
    }
)
"""Every plan kind by name: ``builder(rng, size_m) -> (layout, symmetry)``."""
