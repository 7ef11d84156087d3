"""The built-in worlds: the office as it was drawn, and a route through every world that keeps
clear of its walls."""

from __future__ import annotations

import numpy as np
import pytest
from test_simulation import CLEARANCE_M, point_wall_distance, segments_cross

from multi_robot_mapper.core.worlds import ROUTES, WORLDS, office_world, polygon


def test_office_world_is_unchanged() -> None:
    walls = office_world()
    assert walls.shape == (62, 4)
    np.testing.assert_array_equal(walls[0], [0, 0, 20, 0])
    np.testing.assert_allclose([walls[3, :2], walls[34, 2:]], [[20, 0], [20, 14]], atol=1e-12)
    np.testing.assert_array_equal(walls[35:38], [[0, 5, 4, 5], [5.2, 5, 11, 5], [12.2, 5, 17, 5]])
    assert WORLDS["office"] is office_world


@pytest.mark.parametrize("world", ["office", "corridors", "rooms"])
def test_every_world_has_a_wall_free_route(world: str) -> None:
    walls = WORLDS[world]()
    tour = polygon(ROUTES[world])  # closed
    assert not segments_cross(tour, walls).any()
    along = np.vstack([np.linspace(leg[:2], leg[2:], 200) for leg in tour])
    assert point_wall_distance(along, walls).min() >= CLEARANCE_M
