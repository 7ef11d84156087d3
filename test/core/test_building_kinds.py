"""The kinds of generated building with exact symmetry: mirror wings their own mirror image,
rotation wings their own turned copy, a row of equal rooms."""

from __future__ import annotations

import numpy as np
import pytest
from test_floor_plans import segment_set

from multi_robot_mapper.core.buildings import (
    generate_building,
)
from multi_robot_mapper.core.floor_plans import ROOM


@pytest.mark.parametrize(("seed", "size"), [(0, 20.0), (1, 45.0), (2, 90.0), (3, 200.0)])
def test_mirror_wings_are_their_own_mirror_image(seed: int, size: float) -> None:
    building = generate_building(seed, kind="mirror_wings", size=size, glass=True)
    assert building.symmetry == "mirror"
    for segments in (building.walls, building.glass):
        mirror = segments * np.array([-1.0, 1.0, -1.0, 1.0])
        assert segment_set(mirror) == segment_set(segments)
    assert len(building.glass) > 0


@pytest.mark.parametrize("seed", range(6))
def test_rotation_wings_are_their_own_turned_copy(seed: int) -> None:
    building = generate_building(seed, kind="rotation_wings", size=30.0 + 25.0 * seed)
    quarter = {"rotation_90": 1, "rotation_180": 2}[building.symmetry]
    turned = building.walls
    for _ in range(quarter):
        turned = np.column_stack((-turned[:, 1], turned[:, 0], -turned[:, 3], turned[:, 2]))
    assert segment_set(turned) == segment_set(building.walls)
    # The wing leaves the hub off-centre: the plan is not also its own mirror image.
    mirror = building.walls * np.array([-1.0, 1.0, -1.0, 1.0])
    assert segment_set(mirror) != segment_set(building.walls)


def test_a_row_of_rooms_has_equal_rooms() -> None:
    building = generate_building(4, kind="room_row", size=60.0)
    rooms = building.spaces[building.space_kinds == ROOM]
    widths = np.round(rooms[:, 2] - rooms[:, 0], 9)
    depths = np.round(rooms[:, 3] - rooms[:, 1], 9)
    assert len(rooms) >= 10 and len(set(widths)) == 1 and len(set(depths)) == 1
