"""Walls from rectangles, a known answer: two rooms with a door and a glass front, a corridor
opening onto another."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core.floor_plans import CORRIDOR, ROOM, layout, walls_and_glass


def segment_set(segments: np.ndarray) -> set[tuple[float, ...]]:
    """Segments as a set, each with its ends in a fixed order, rounded to 1e-9 m."""
    out = set()
    for x1, y1, x2, y2 in np.round(segments, 9).tolist():
        a, b = (x1 + 0.0, y1 + 0.0), (x2 + 0.0, y2 + 0.0)
        out.add((*min(a, b), *max(a, b)))
    return out


def test_two_rooms_with_a_door_and_a_glass_front_give_known_walls() -> None:
    plan = layout(
        [(0, 0, 4, 3), (4, 0, 8, 3)],
        [ROOM, ROOM],
        openings=[(4, 1, 4, 2)],
        glass=[(0, 3, 4, 3)],
    )
    walls, glass = walls_and_glass(plan)
    assert segment_set(walls) == segment_set(
        np.array(
            [
                [0, 0, 8, 0],  # the two rooms' south walls: one run
                [4, 3, 8, 3],
                [0, 0, 0, 3],
                [8, 0, 8, 3],
                [4, 0, 4, 1],  # the wall between them, broken by the door
                [4, 2, 4, 3],
            ]
        )
    )
    assert segment_set(glass) == {(0.0, 3.0, 4.0, 3.0)}


def test_a_corridor_opening_onto_another_has_no_wall_between() -> None:
    plan = layout([(0, 0, 10, 2), (0, 2, 2, 8)], [CORRIDOR, CORRIDOR], openings=[(0, 2, 2, 2)])
    walls, glass = walls_and_glass(plan)
    expected = [[0, 0, 10, 0], [2, 2, 10, 2], [0, 0, 0, 8], [10, 0, 10, 2], [2, 2, 2, 8]]
    assert segment_set(walls) == segment_set(np.array([*expected, [0, 8, 2, 8]]))
    assert len(glass) == 0
