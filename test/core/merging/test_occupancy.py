"""The occupancy grid of a merge: known rooms, known viewpoints, exact cells."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging import MergeConfig, MergeResult
from multi_robot_mapper.core.merging.occupancy import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    GridConfig,
    OccupancyGrid,
    global_grid,
    occupancy_grid,
)
from multi_robot_mapper.core.worlds import polygon

ROOM = polygon([(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)])  # closed 4 x 4 m room
CONFIG = GridConfig(resolution=0.1)


def cell_at(grid: OccupancyGrid, x: float, y: float) -> int:
    column = math.floor((x - grid.origin[0]) / grid.resolution)
    row = math.floor((y - grid.origin[1]) / grid.resolution)
    return int(grid.cells[row, column])


def centres(grid: OccupancyGrid, value: int) -> np.ndarray:
    rows, columns = np.nonzero(grid.cells == value)
    return np.column_stack(
        (
            grid.origin[0] + (columns + 0.5) * grid.resolution,
            grid.origin[1] + (rows + 0.5) * grid.resolution,
        )
    )


def test_a_room_seen_from_its_centre_is_free_inside_walled_and_unknown_outside() -> None:
    view = np.array([[2.0, 2.0, 0.0]])  # facing +x, a 270-degree laser
    grid = occupancy_grid(ROOM, [(ROOM, view)], CONFIG, MergeConfig())
    assert grid.resolution == 0.1
    # The extent: the walls plus one cell each side.
    assert grid.origin == pytest.approx((-0.1, -0.1))
    assert (grid.width, grid.height) == (42, 42)
    # Every wall cell is occupied, at both ends and midway.
    for x, y in [(0.0, 2.0), (4.0, 2.0), (2.0, 0.0), (2.0, 4.0), (0.05, 0.05), (3.95, 3.95)]:
        assert cell_at(grid, x, y) == OCCUPIED, (x, y)
    # In front and to the sides of the laser: free, up to the walls.
    for x, y in [(3.5, 2.0), (2.0, 3.5), (2.0, 0.5), (3.5, 3.5), (3.5, 0.5), (2.5, 2.0)]:
        assert cell_at(grid, x, y) == FREE, (x, y)
    # Behind it (beyond +-135 degrees) nothing was seen.
    assert cell_at(grid, 0.5, 2.0) == UNKNOWN
    # Every free cell is inside the room, every known cell in the room or on its walls.
    free = centres(grid, FREE)
    assert len(free) > 0.5 * 40 * 40
    assert np.all((free > 0.0) & (free < 4.0))
    assert np.all(np.isin(grid.cells, (UNKNOWN, FREE, OCCUPIED)))


def test_a_gap_between_walls_is_not_seen_through() -> None:
    # A room whose east wall has a 0.3 m gap: nothing is claimed along the bearings through
    # it (the map has no wall there to say how far the laser saw), even inside the room.
    east = polygon([(4.0, 0.0), (4.0, 1.85)], closed=False)
    east_top = polygon([(4.0, 2.15), (4.0, 4.0)], closed=False)
    others = polygon([(4.0, 4.0), (0.0, 4.0), (0.0, 0.0), (4.0, 0.0)], closed=False)
    walls = np.vstack((others, east, east_top))
    grid = occupancy_grid(walls, [(walls, np.array([[2.0, 2.0, 0.0]]))], CONFIG, MergeConfig())
    assert cell_at(grid, 3.8, 2.0) == UNKNOWN  # in front of the gap
    assert cell_at(grid, 3.5, 3.0) == FREE  # beside it the east wall bounds what was seen
    assert np.all(centres(grid, FREE)[:, 0] < 4.0)  # never past the wall


def test_a_robot_placed_by_the_merge_marks_the_cells_where_it_is_placed() -> None:
    # The same room in a robot frame turned and shifted; placed back by its T_map_robot.
    T_map_robot = se2.matrix_from_pose(1.5, -0.7, 0.6)
    in_robot = se2.transform_segments(se2.invert(T_map_robot), ROOM)
    view_map = np.array([2.0, 2.0, 0.0])
    view_robot = se2.pose_from_matrix(se2.invert(T_map_robot) @ se2.matrix_from_pose(*view_map))
    result = MergeResult(
        robots=["a"],
        placements={"a": se2.pose_from_matrix(T_map_robot)},
        reference="a",
        links=[],
        pairs={},
        segments=ROOM,
        segment_robot=np.zeros(len(ROOM), dtype=np.int64),
        timings={},
        stats={},
    )
    placed = global_grid(
        result, {"a": in_robot}, {"a": np.array([view_robot])}, CONFIG, MergeConfig()
    )
    direct = occupancy_grid(ROOM, [(ROOM, view_map[None, :])], CONFIG, MergeConfig())
    assert placed.origin == pytest.approx(direct.origin)
    # Free space is the same up to cells that the viewpoint's field edge or the walls graze.
    differ = np.count_nonzero(placed.cells != direct.cells)
    assert differ <= 0.01 * placed.cells.size


def test_unmerged_robots_and_robots_without_viewpoints_add_only_their_placed_walls() -> None:
    result = MergeResult(
        robots=["a", "b"],
        placements={"a": (0.0, 0.0, 0.0), "b": None},
        reference="a",
        links=[],
        pairs={},
        segments=ROOM,
        segment_robot=np.zeros(len(ROOM), dtype=np.int64),
        timings={},
        stats={},
    )
    far = ROOM + 50.0
    grid = global_grid(
        result, {"a": ROOM, "b": far}, {"b": np.array([[52.0, 52.0, 0.0]])}, CONFIG, MergeConfig()
    )
    assert np.count_nonzero(grid.cells == FREE) == 0  # a has no viewpoint, b is not placed
    assert grid.width == 42 and np.count_nonzero(grid.cells == OCCUPIED) > 100


def test_a_map_too_large_for_max_cells_gets_a_coarser_grid() -> None:
    big = ROOM * 100.0  # 400 x 400 m
    grid = occupancy_grid(big, [], GridConfig(resolution=0.05, max_cells=10_000), MergeConfig())
    assert grid.width * grid.height <= 10_000
    assert grid.resolution == pytest.approx(0.05 * 2 ** grid_doublings(grid.resolution, 0.05))
    assert cell_at(grid, 200.0, 0.0) == OCCUPIED


def grid_doublings(resolution: float, start: float) -> int:
    return round(math.log2(resolution / start))


@settings(max_examples=25, deadline=None)
@given(
    x=st.floats(0.3, 3.7),
    y=st.floats(0.3, 3.7),
    heading=st.floats(-math.pi, math.pi),
)
def test_free_cells_never_lie_outside_a_closed_room_or_on_its_walls(
    x: float, y: float, heading: float
) -> None:
    grid = occupancy_grid(ROOM, [(ROOM, np.array([[x, y, heading]]))], CONFIG, MergeConfig())
    free = centres(grid, FREE)
    assert np.all((free > 0.0) & (free < 4.0))
    # The cell the laser stands in is free whenever the walls leave room for it.
    if min(x, y, 4.0 - x, 4.0 - y) > 0.3:
        assert cell_at(grid, x, y) in (FREE, UNKNOWN)
        assert np.count_nonzero(grid.cells == FREE) > 0


def test_robots_seeing_the_same_place_cast_it_once_with_the_same_cells() -> None:
    from multi_robot_mapper.core.merging.occupancy import _thinned

    views = np.array([[2.0, 2.0, 0.0], [2.2, 2.0, 0.1], [2.0, 2.0, math.pi]])
    thinned = _thinned([(ROOM, views), (ROOM, views + np.array([0.05, 0.0, 0.0]))], spacing=0.5)
    assert len(thinned) == 1  # the second robot stood where the first did, facing the same way
    np.testing.assert_array_equal(thinned[0][1], views[[0, 2]])  # facing back is another view
    one = occupancy_grid(ROOM, [(ROOM, views)], CONFIG, MergeConfig())
    two = occupancy_grid(ROOM, [(ROOM, views), (ROOM, views)], CONFIG, MergeConfig())
    np.testing.assert_array_equal(one.cells, two.cells)


def test_where_the_robots_drove_is_free_even_where_no_laser_looked() -> None:
    # A 20 m corridor, open at both ends, driven along its axis: straight ahead no wall
    # bounds what was seen (nothing claimed there), but the path itself is free.
    corridor = np.array([[0.0, -1.0, 20.0, -1.0], [0.0, 1.0, 20.0, 1.0]])
    views = np.column_stack((np.arange(1.0, 19.0, 0.5), np.zeros(36), np.zeros(36)))
    without = occupancy_grid(
        corridor, [(corridor, views)], GridConfig(resolution=0.1, path_radius=0.0), MergeConfig()
    )
    with_path = occupancy_grid(corridor, [(corridor, views)], CONFIG, MergeConfig())
    on_path = [(x, 0.0) for x in np.arange(1.05, 18.5, 0.1)]
    assert any(cell_at(without, x, y) == UNKNOWN for x, y in on_path)
    assert all(cell_at(with_path, x, y) == FREE for x, y in on_path)
    assert cell_at(with_path, 10.0, 0.5) == FREE and cell_at(with_path, 10.0, 1.0) == OCCUPIED
    assert with_path.height == 22  # the walls and one cell beyond: nothing outside


def test_a_merge_worker_keeps_the_state_and_answers_without_it() -> None:
    # map_merger's worker (merge_keeping_state): the merge's state (60 MB at 800 keyframes)
    # stays in the worker; the answer carries its serial number, and the next job with that
    # result gets the state back (nothing changed: no place searched again, the same merge).
    # A result naming another state (a worker started again) is merged afresh.
    import pickle

    from test_merge_reuse import CONFIG as MERGE
    from test_merge_reuse import corridor_maps

    from multi_robot_mapper.core.merging.joint import JointState
    from multi_robot_mapper.core.merging.occupancy import StateInWorker, merge_keeping_state

    keyframes, grid, kept = corridor_maps(), GridConfig(enabled=False), {}
    merge = dataclasses.replace(MERGE, update_budget=0.0)  # every place matched: the known answer
    first, none = merge_keeping_state(kept, keyframes, merge, grid)
    assert none is None and first.state == StateInWorker(1)
    assert isinstance(kept["state"], JointState) and first.stats["matches_computed"] > 0
    assert len(pickle.dumps(first)) < len(pickle.dumps(kept["state"]))
    again, _ = merge_keeping_state(kept, keyframes, merge, grid, first)
    assert again.state == StateInWorker(2) and again.stats["matches_computed"] == 0
    assert again.placements == first.placements
    stranger = dataclasses.replace(first, state=StateInWorker(7))
    afresh, _ = merge_keeping_state(kept, keyframes, merge, grid, stranger)
    assert afresh.stats["matches_computed"] == first.stats["matches_computed"]
    assert afresh.placements == first.placements


def test_a_merge_worker_makes_the_grid_again_only_when_what_it_shows_changed() -> None:
    # An update that moved nothing (places or verdicts pending, a retry) answers the grid it
    # made last (1-2 s at 1000 keyframes); a map that changed gets its own grid, the one
    # global_grid makes of that merge.
    from test_merge_reuse import CONFIG as MERGE
    from test_merge_reuse import corridor_maps

    from multi_robot_mapper.core.merging.occupancy import merge_keeping_state

    keyframes, grid, kept = corridor_maps(), GridConfig(resolution=0.1), {}
    merge = dataclasses.replace(MERGE, update_budget=0.0)
    first, first_grid = merge_keeping_state(kept, keyframes, merge, grid)
    again, again_grid = merge_keeping_state(kept, keyframes, merge, grid, first)
    assert first_grid is not None and again_grid is first_grid
    robot = sorted(keyframes)[0]
    shorter = {**keyframes, robot: list(keyframes[robot])[:-1]}
    changed, changed_grid = merge_keeping_state(kept, shorter, merge, grid, again)
    assert changed_grid is not None and changed_grid is not first_grid
    made = global_grid(dataclasses.replace(changed, state=None), {}, {}, grid, merge)
    assert np.array_equal(changed_grid.cells, made.cells) and changed_grid.origin == made.origin
    assert not np.array_equal(changed_grid.cells, first_grid.cells)
