"""The simulator's built-in worlds: wall segments in the ``world`` frame, and the closed routes
robots drive through them (``mrm simulate``, ``make demo``, the tests).

A world is a ``(W, 4)`` segment set; :data:`WORLDS` names each world's builder and
:data:`ROUTES` its route's vertices (metres, ``world`` frame).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def polygon(vertices: list[tuple[float, float]], closed: bool = True) -> FloatArray:
    """Wall segments along a polyline of vertices."""
    v = np.asarray(vertices, dtype=np.float64)
    if closed:
        v = np.vstack((v, v[:1]))
    return np.hstack((v[:-1], v[1:]))


def arc(
    centre: tuple[float, float], radius: float, start: float, stop: float, pieces: int = 24
) -> FloatArray:
    """A curved wall: the circle arc from angle ``start`` to ``stop`` (rad) in short segments."""
    t = np.linspace(start, stop, pieces + 1)
    pts = np.column_stack((centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)))
    return np.hstack((pts[:-1], pts[1:]))


def box(cx: float, cy: float, w: float, h: float) -> FloatArray:
    """An axis-aligned rectangular obstacle (furniture, a pillar)."""
    return polygon(
        [
            (cx - w / 2, cy - h / 2),
            (cx + w / 2, cy - h / 2),
            (cx + w / 2, cy + h / 2),
            (cx - w / 2, cy + h / 2),
        ]
    )


def office_world() -> FloatArray:
    """Two rooms and a corridor, with doors, furniture and a curved wall (about 24 x 14 m)."""
    walls = [
        # Outer shell with a curved end on the east side.
        polygon([(0, 0), (20, 0)], closed=False),
        polygon([(0, 0), (0, 14), (20, 14)], closed=False),
        arc((20, 7), 7.0, -np.pi / 2, np.pi / 2, pieces=32),
        # Corridor wall at y = 5 with two doors (gaps).
        polygon([(0, 5), (4, 5)], closed=False),
        polygon([(5.2, 5), (11, 5)], closed=False),
        polygon([(12.2, 5), (17, 5)], closed=False),
        # Wall between the two upper rooms, with a door.
        polygon([(9, 5), (9, 9)], closed=False),
        polygon([(9, 10.2), (9, 14)], closed=False),
        # Furniture and pillars.
        box(3.0, 11.0, 1.6, 0.8),
        box(6.5, 7.0, 0.6, 0.6),
        box(14.0, 11.5, 2.0, 1.0),
        box(10.0, 2.5, 0.4, 0.4),
        box(16.0, 2.0, 0.5, 1.2),
        polygon([(12.0, 8.0), (13.5, 7.2), (15.0, 8.4)], closed=False),
    ]
    return np.vstack(walls)


def corridors_world() -> FloatArray:
    """A ring of 3 m corridors with a cross corridor, a curved corner and two rooms (32 x 20 m).

    The ring runs between the outer shell and two inner blocks; the north-east corner of the
    ring bends round a quarter circle. The left block holds two rooms joined by a door, one
    opening onto the south corridor, one onto the cross corridor; the right block is one hall
    with a door onto the cross corridor. Cabinets stand against the corridor walls.
    """
    walls = [
        # Outer shell; the north-east corner is the quarter circle of radius 5 round (27, 15).
        polygon([(27, 20), (0, 20), (0, 0), (32, 0), (32, 15)], closed=False),
        arc((27, 15), 5.0, 0.0, np.pi / 2, pieces=16),
        # Left block (3..14.5 x 3..17): door south (x 7..8.2), door east (y 12..13.2), and the
        # wall y = 10 between its two rooms with a door at x 10..11.2.
        polygon([(8.2, 3), (14.5, 3), (14.5, 12)], closed=False),
        polygon([(14.5, 13.2), (14.5, 17), (3, 17), (3, 3), (7, 3)], closed=False),
        polygon([(3, 10), (10, 10)], closed=False),
        polygon([(11.2, 10), (14.5, 10)], closed=False),
        # Right block (17.5..29 x 3..17) with its north-east corner rounded (radius 2 round
        # (27, 15), concentric with the outer curve) and a door west at y 6..7.2.
        polygon([(17.5, 7.2), (17.5, 17), (27, 17)], closed=False),
        arc((27, 15), 2.0, np.pi / 2, 0.0, pieces=12),
        polygon([(29, 15), (29, 3), (17.5, 3), (17.5, 6)], closed=False),
        # Clutter: cabinets against corridor walls (each leaves >= 2.4 m of corridor free).
        box(10.0, 0.3, 1.2, 0.6),
        box(0.3, 9.0, 0.6, 1.4),
        box(22.0, 19.7, 1.6, 0.6),
        box(31.7, 8.0, 0.6, 1.0),
        box(16.0, 3.3, 0.8, 0.6),
        # Furniture in the rooms and the hall.
        box(5.0, 6.5, 1.2, 2.0),
        box(12.8, 5.0, 1.4, 0.8),
        box(6.0, 14.5, 2.0, 0.8),
        box(23.0, 10.0, 3.0, 1.2),
        arc((20.5, 14.5), 0.35, 0.0, 2 * np.pi, pieces=12),  # a round pillar
    ]
    return np.vstack(walls)


def rooms_world() -> FloatArray:
    """Six rooms of 7 x 6 m in a 3 x 2 grid joined by 1.2 m doors, with furniture (21 x 12 m).

    The north-east room has a curved outer wall, the middle south room a round pillar.
    """
    walls = [
        # Outer shell; the north-east corner is the quarter circle of radius 3 round (18, 9).
        polygon([(18, 12), (0, 12), (0, 0), (21, 0), (21, 9)], closed=False),
        arc((18, 9), 3.0, 0.0, np.pi / 2, pieces=16),
        # Walls x = 7 and x = 14 with a door in each row (y 2.4..3.6 and 8.4..9.6).
        polygon([(7, 0), (7, 2.4)], closed=False),
        polygon([(7, 3.6), (7, 8.4)], closed=False),
        polygon([(7, 9.6), (7, 12)], closed=False),
        polygon([(14, 0), (14, 2.4)], closed=False),
        polygon([(14, 3.6), (14, 8.4)], closed=False),
        polygon([(14, 9.6), (14, 12)], closed=False),
        # Wall y = 6 with a door into each column (x 2.9..4.1, 9.9..11.1, 16.9..18.1).
        polygon([(0, 6), (2.9, 6)], closed=False),
        polygon([(4.1, 6), (9.9, 6)], closed=False),
        polygon([(11.1, 6), (16.9, 6)], closed=False),
        polygon([(18.1, 6), (21, 6)], closed=False),
        # Furniture, off the lines y = 3, y = 9, x = 3.5 and x = 17.5 the doors lie on.
        box(1.2, 1.0, 1.6, 1.0),
        box(5.6, 1.0, 1.2, 1.2),
        polygon([(5.0, 4.4), (6.3, 4.4), (6.3, 5.4)], closed=False),  # an L-shaped desk
        arc((10.5, 4.8), 0.4, 0.0, 2 * np.pi, pieces=12),  # round pillar
        box(12.5, 1.0, 1.4, 0.8),
        box(19.8, 1.5, 1.0, 2.0),
        box(16.0, 4.8, 1.6, 0.8),
        polygon([(0.8, 7.2), (2.2, 7.9)], closed=False),  # a free-standing shelf
        box(5.5, 11.1, 1.6, 0.8),
        box(9.0, 7.2, 0.8, 0.8),
        box(12.0, 11.0, 1.2, 1.0),
        box(15.5, 11.2, 1.0, 0.8),
    ]
    return np.vstack(walls)


WORLDS = MappingProxyType(
    {"office": office_world, "corridors": corridors_world, "rooms": rooms_world}
)

# One closed tour of waypoints (world frame, m) through each world: every leg keeps at least
# 0.3 m from every wall (test_simulation checks it), doors are crossed square on.
ROUTES: Mapping[str, tuple[tuple[float, float], ...]] = MappingProxyType(
    {
        "office": (
            (4.6, 3.6),
            (17.5, 3.6),
            (21.0, 4.2),
            (23.5, 7.0),
            (21.0, 10.5),
            (16.5, 9.6),
            (9.0, 9.6),
            (5.5, 9.0),
            (4.6, 6.5),
            (4.6, 5.0),
        ),
        "corridors": (
            (1.5, 1.5),
            (7.6, 1.5),
            (7.6, 5.0),
            (10.6, 8.5),
            (10.6, 11.5),
            (13.0, 12.6),
            (16.0, 12.6),
            (16.0, 18.5),
            (27.0, 18.5),
            *[
                (27.0 + 3.5 * float(np.cos(a)), 15.0 + 3.5 * float(np.sin(a)))
                for a in np.linspace(np.pi / 2, 0.0, 7)[1:-1]
            ],
            (30.5, 15.0),
            (30.5, 1.5),
        ),
        "rooms": ((3.5, 3.0), (10.5, 3.0), (17.5, 3.0), (17.5, 9.0), (10.5, 9.0), (3.5, 9.0)),
    }
)
