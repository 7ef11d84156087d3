"""The global map as an occupancy grid (what Nav2 and explorers read).

Occupied cells are the cells the global map's segments pass through. Free cells are what the
robots saw: each placed robot's own map ray cast from its keyframe poses (:class:`MapViews`,
the same views the merge judges links on), a cell being free when it lies nearer its viewpoint
than the robot's own wall on that bearing, by one cell; and where the robots drove (within
``path_radius`` of the path through their keyframes). Everything else is unknown. A bearing
on which the robot's map has no wall within ``view_range`` (an open door, a hall wider than
the range) claims nothing: a partial map carries no scans, and nothing says how far the laser
saw there.

Frames: the grid is in ``map`` (the reference robot's map frame); each robot's map and
viewpoints are moved by its placement ``T_map_robot`` first. Cell ``(row, col)`` covers
``origin + (col, row) * resolution`` to one resolution more (row = y, as in
``nav_msgs/OccupancyGrid``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.geometry import sample_segments
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.free_space import MapViews
from multi_robot_mapper.core.merging.link_graph import MergeResult
from multi_robot_mapper.core.merging.methods import merge_method

FloatArray = NDArray[np.float64]
CellArray = NDArray[np.int8]

UNKNOWN = -1
FREE = 0
OCCUPIED = 100
_VIEW_CHUNK = 16  # viewpoints tested against their cells at once (bounds the memory per step)


@dataclasses.dataclass(frozen=True)
class GridConfig:
    """The occupancy grid the merger publishes beside the segment map (``grid.*``)."""

    enabled: bool = param(
        True,
        unit="",
        doc="publish global_grid (nav_msgs/OccupancyGrid)",
        tune="nothing reads global_grid (it costs a ray cast per view and merge): false",
    )
    resolution: float = param(
        0.05,
        unit="m",
        doc="cell size of global_grid (coarsened when the map would need more than max_cells)",
        minimum=0.005,
        maximum=10.0,
        tune="your planner's costmap has another cell size",
    )
    max_cells: int = param(
        4_000_000,
        unit="cells",
        doc="largest grid published: a larger map gets a coarser resolution (doubled until it "
        "fits) rather than an unbounded message",
        minimum=100,
        maximum=100_000_000,
        tune="a larger site at full resolution: raise it (the message grows with it)",
    )
    view_spacing: float = param(
        0.5,
        unit="m",
        doc="a keyframe pose closer than this to one already kept (of any robot) and facing "
        "the same way adds no free space to the grid (robots on the same ground see the same)",
        minimum=0.0,
        maximum=100.0,
    )
    max_views: int = param(
        200,
        unit="",
        doc="at most this many viewpoints per robot mark free space (evenly spread)",
        minimum=1,
        maximum=100_000,
    )
    path_radius: float = param(
        0.25,
        unit="m",
        doc="cells this close to the path through a robot's keyframe poses are free (the robot "
        "drove there; its laser does not see right beside and behind itself); 0: off",
        minimum=0.0,
        maximum=5.0,
        tune="a robot whose radius is not about 0.25 m: its radius (the ground it drove over is "
        "free)",
    )
    view_field: float = param(
        1.5 * math.pi,
        unit="rad",
        doc="field of view marked free around each keyframe's heading: the laser's (270 "
        "degrees: Hokuyo UTM/UST, SICK TiM and LMS1xx; set 3.14 for a 180-degree laser, "
        "which would otherwise mark unseen cells behind it free)",
        minimum=0.01,
        maximum=2.0 * math.pi,
        tune="a laser other than 270 degrees: its field of view (3.14 for 180 degrees)",
    )

    def __post_init__(self) -> None:
        validate(self)


@dataclasses.dataclass(frozen=True)
class OccupancyGrid:
    """Cells of -1 (unknown), 0 (free) or 100 (occupied) over a rectangle of ``map``."""

    origin: tuple[float, float]  # map coordinates of cell (0, 0)'s lower-left corner (m)
    resolution: float  # m per cell
    cells: CellArray  # (height, width): row = y index, column = x index

    @property
    def width(self) -> int:
        return int(self.cells.shape[1])

    @property
    def height(self) -> int:
        return int(self.cells.shape[0])


def global_grid(
    result: MergeResult,
    maps: Mapping[str, FloatArray],
    viewpoints: Mapping[str, FloatArray],
    config: GridConfig,
    merging: MergeConfig,
) -> OccupancyGrid:
    """The occupancy grid of a merge: ``result.segments`` occupied, each placed robot's views
    free: the global map ray cast from its merged keyframes' poses in ``map`` (the joint
    graph's), else its map ``maps[robot]`` ray cast from ``viewpoints[robot]``, both in its own
    frame, moved by its placement."""
    placed_views = []
    for robot in result.robots:
        if robot in result.keyframe_poses:
            placed_views.append((result.segments, result.keyframe_poses[robot]))
            continue
        T_map_robot = result.matrix(robot)
        poses = np.asarray(viewpoints.get(robot, np.zeros((0, 3))), dtype=np.float64)
        segments = np.asarray(maps.get(robot, np.zeros((0, 4))), dtype=np.float64)
        if T_map_robot is None or len(poses.reshape(-1, 3)) == 0 or len(segments) == 0:
            continue
        placed_views.append(
            (se2.transform_segments(T_map_robot, segments), _moved(T_map_robot, poses))
        )
    return occupancy_grid(result.segments, placed_views, config, merging)


def occupancy_grid(
    segments: FloatArray,
    views: list[tuple[FloatArray, FloatArray]],
    config: GridConfig,
    merging: MergeConfig,
) -> OccupancyGrid:
    """The grid of ``segments`` (occupied) and of each ``(own segments, viewpoints)`` pair's
    free space, all in one frame."""
    walls = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    corners = [walls.reshape(-1, 2)] + [poses[:, :2] for _, poses in views]
    points = np.vstack([c for c in corners if len(c)] or [np.zeros((1, 2))])
    resolution = config.resolution
    low = points.min(axis=0) - resolution
    span = points.max(axis=0) + resolution - low
    while math.ceil(span[0] / resolution) * math.ceil(span[1] / resolution) > config.max_cells:
        resolution *= 2.0
    width, height = (max(1, math.ceil(float(s) / resolution)) for s in span)
    origin = (float(low[0]), float(low[1]))
    cells = np.full((height, width), UNKNOWN, dtype=np.int8)
    view_config = dataclasses.replace(
        merging,
        view_spacing=0.0,  # thinned here, over every robot at once
        max_views=config.max_views,
        view_field=config.view_field,
        free_space_margin=resolution,
    )
    for own, poses in _thinned(views, config.view_spacing):
        reach_of = (view_config.view_spread, view_config.free_space_margin, view_config.view_range)
        _mark_free(
            cells, origin, resolution, MapViews.of(own, poses, view_config.view_fan()), reach_of
        )
    if config.path_radius > 0.0:
        for _, poses in views:
            _mark_path(cells, origin, resolution, poses, config.path_radius)
    if len(walls):
        # Samples at most half a cell apart touch every cell a segment passes through.
        wall_points, _ = sample_segments(walls, 0.5 * resolution)
        column, row = _cell_of(wall_points, origin, resolution)
        inside = (column >= 0) & (column < width) & (row >= 0) & (row < height)
        cells[row[inside], column[inside]] = OCCUPIED
    return OccupancyGrid(origin, resolution, cells)


HEADING_TOLERANCE = 0.5  # rad: two views closer than this in heading see the same side


def _thinned(
    views: list[tuple[FloatArray, FloatArray]], spacing: float
) -> list[tuple[FloatArray, FloatArray]]:
    """Each ``(segments, viewpoints)`` pair with only the viewpoints that are at least
    ``spacing`` from every viewpoint kept before them (of any robot) or face another way
    (HEADING_TOLERANCE): robots driving the same corridor see the same free space, and casting
    it once per place is enough. Greedy, in order."""
    kept: list[FloatArray] = []
    out = []
    for segments, poses in views:
        mine = []
        for pose in poses.reshape(-1, 3):
            if kept:
                others = np.asarray(kept)
                close = np.hypot(others[:, 0] - pose[0], others[:, 1] - pose[1]) < spacing
                facing = np.abs(se2.wrap_angle(others[:, 2] - pose[2])) < HEADING_TOLERANCE
                if np.any(close & facing):
                    continue
            kept.append(pose)
            mine.append(pose)
        if mine:
            out.append((segments, np.asarray(mine, dtype=np.float64)))
    return out


def _moved(T_map_robot: FloatArray, poses: FloatArray) -> FloatArray:
    """``(K, 3)`` poses in a robot's frame moved into ``map``."""
    poses = poses.reshape(-1, 3)
    xy = se2.transform_points(T_map_robot, poses[:, :2])
    theta = poses[:, 2] + math.atan2(T_map_robot[1, 0], T_map_robot[0, 0])
    return np.column_stack((xy, theta))


def _cell_of(
    points: FloatArray, origin: tuple[float, float], resolution: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Column and row of the cell holding each ``(P, 2)`` point."""
    column = np.floor((points[:, 0] - origin[0]) / resolution).astype(np.int64)
    row = np.floor((points[:, 1] - origin[1]) / resolution).astype(np.int64)
    return column, row


PATH_JUMP = 2.0  # m: keyframes farther apart than this were not joined by a drive


def _mark_path(
    cells: CellArray,
    origin: tuple[float, float],
    resolution: float,
    poses: FloatArray,
    radius: float,
) -> None:
    """Set to FREE every cell within ``radius`` of the path through consecutive keyframe
    poses (where the robot drove; legs longer than PATH_JUMP are skipped)."""
    poses = poses.reshape(-1, 3)
    if len(poses) == 0:
        return
    legs = np.hstack((poses[:-1, :2], poses[1:, :2]))
    legs = legs[np.hypot(legs[:, 2] - legs[:, 0], legs[:, 3] - legs[:, 1]) <= PATH_JUMP]
    stops = np.hstack((poses[:, :2], poses[:, :2]))  # every keyframe, even a lone one
    points, _ = sample_segments(np.vstack((legs, stops)), 0.5 * resolution)
    reach = math.ceil(radius / resolution)
    offsets = np.arange(-reach, reach + 1, dtype=np.int64)
    d_col, d_row = (a.ravel() for a in np.meshgrid(offsets, offsets))
    disc = np.hypot(d_col, d_row) * resolution <= radius
    column, row = _cell_of(points, origin, resolution)
    column = (column[:, None] + d_col[disc][None, :]).ravel()
    row = (row[:, None] + d_row[disc][None, :]).ravel()
    height, width = cells.shape
    inside = (column >= 0) & (column < width) & (row >= 0) & (row < height)
    cells[row[inside], column[inside]] = FREE


def _mark_free(
    cells: CellArray,
    origin: tuple[float, float],
    resolution: float,
    views: MapViews,
    reach_of: tuple[int, float, float],
) -> None:
    """Set to FREE every cell whose centre lies in the free space of ``views``: within the
    field of view, nearer the viewpoint than the map's wall on that bearing (the nearest
    within ``spread`` bearings) by ``margin``, and within ``view_range`` (``reach_of``:
    spread, margin, view_range)."""
    spread, margin, view_range = reach_of
    reach = views.free_limits(spread) - margin
    radius = min(view_range, float(np.max(reach, initial=0.0)))
    if radius <= 0.0 or len(views.poses) == 0:
        return
    # The same disc of cell offsets around every viewpoint, its distances and bearings
    # computed once and sorted by distance: each viewpoint stands at its cell's centre (at
    # most half a cell off), and a chunk of views tests only the cells nearer than the
    # farthest wall any of them sees (a room's view needs a room's disc, not a corridor's).
    half = math.ceil(radius / resolution)
    offsets = np.arange(-half, half + 1, dtype=np.int64)
    d_col, d_row = (a.ravel() for a in np.meshgrid(offsets, offsets))
    distance = np.hypot(d_col, d_row) * resolution
    nearest_first = np.argsort(distance, kind="stable")
    nearest_first = nearest_first[distance[nearest_first] <= radius]
    d_col, d_row, distance = d_col[nearest_first], d_row[nearest_first], distance[nearest_first]
    direction = np.arctan2(d_row, d_col)
    farthest = np.max(reach, axis=1, initial=0.0)
    by_reach = np.argsort(farthest, kind="stable")  # views of alike reach share a chunk
    for start in range(0, len(by_reach), _VIEW_CHUNK):
        chunk = by_reach[start : start + _VIEW_CHUNK]
        cells_in_reach = int(np.searchsorted(distance, np.max(farthest[chunk]), side="left"))
        _mark_chunk(
            cells,
            (origin, resolution),
            views.poses[chunk],
            reach[chunk],
            (d_col[:cells_in_reach], d_row[:cells_in_reach], distance[:cells_in_reach]),
            (direction[:cells_in_reach], views.angle_min, views.angle_increment),
        )


def _mark_chunk(
    cells: CellArray,
    frame: tuple[tuple[float, float], float],
    poses: FloatArray,
    limits: FloatArray,
    disc: tuple[NDArray[np.int64], NDArray[np.int64], FloatArray],
    bearings: tuple[FloatArray, float, float],
) -> None:
    """:func:`_mark_free` for a few views (``poses``, their free ``limits`` per bearing) over
    the ``disc`` of cell offsets and distances around each (``bearings``: each offset's
    direction, the views' first bearing and step)."""
    (origin, resolution), (d_col, d_row, distance) = frame, disc
    direction, angle_min, angle_increment = bearings
    height, width = cells.shape
    bearing = se2.wrap_angle(direction[None, :] - poses[:, 2, None])
    beam = np.rint((bearing - angle_min) / angle_increment).astype(np.int64)
    in_field = (beam >= 0) & (beam < limits.shape[1])
    wall = np.take_along_axis(limits, np.where(in_field, beam, 0), axis=1)
    view, cell = np.nonzero(in_field & (distance[None, :] < wall))
    home_col, home_row = _cell_of(poses[:, :2], origin, resolution)
    column = home_col[view] + d_col[cell]
    row = home_row[view] + d_row[cell]
    inside = (column >= 0) & (column < width) & (row >= 0) & (row < height)
    cells[row[inside], column[inside]] = FREE


def merge_with_grid(
    keyframes: Mapping[str, Sequence[Keyframe]],
    config: MergeConfig,
    grid: GridConfig,
    previous: MergeResult | None = None,
    method: str = "pivot",
    kept: dict[str, Any] | None = None,
) -> tuple[MergeResult, OccupancyGrid | None]:
    """One merge update by ``method`` ('pivot': :func:`merge_joint`, within
    ``config.update_budget``; 'ffs': the same, then Force Field Simulation) and, when
    ``grid.enabled``, the :func:`global_grid` of its result: what ``map_merger`` computes in
    its worker process after each change of a partial map. ``kept``: where the last grid and
    what it showed are kept between updates; an update that moved nothing (places or verdicts
    still pending, a retry) answers that grid (made again it cost 1-2 s at 1000 keyframes,
    issue 50)."""
    result = merge_method(method)(keyframes, config, previous=previous)
    if not grid.enabled:
        return result, None
    if kept is None:
        return result, global_grid(result, {}, {}, grid, config)
    shown = _shown_digest(result, grid, config)
    if kept.get("grid_of") != shown:
        kept["grid"], kept["grid_of"] = global_grid(result, {}, {}, grid, config), shown
    return result, kept["grid"]


def _shown_digest(result: MergeResult, grid: GridConfig, config: MergeConfig) -> str:
    """What a merge's :func:`global_grid` is made of (its global map, every merged keyframe's
    pose, the configs), as a digest."""
    digest = hashlib.sha1(repr((grid, config)).encode())
    digest.update(np.ascontiguousarray(result.segments, dtype=np.float64).tobytes())
    for robot in sorted(result.keyframe_poses):
        digest.update(robot.encode())
        digest.update(np.ascontiguousarray(result.keyframe_poses[robot]).tobytes())
    return digest.hexdigest()


@dataclasses.dataclass(frozen=True)
class StateInWorker:
    """In place of a merge result's state: the state stays in the merge worker that made it
    (:func:`merge_keeping_state`), under this serial number."""

    serial: int


def merge_keeping_state(
    kept: dict[str, Any],
    keyframes: Mapping[str, Sequence[Keyframe]],
    config: MergeConfig,
    grid: GridConfig,
    previous: MergeResult | None = None,
    method: str = "pivot",
) -> tuple[MergeResult, OccupancyGrid | None]:
    """:func:`merge_with_grid` in a worker that keeps the merge's state (``kept``: the
    worker's own dict, kept between jobs) and answers the result with a
    :class:`StateInWorker` in its place. The state (places, targets with their rasters, the
    fusion: 60 MB at 800 keyframes, issue 50) then never crosses the pipe, where it cost a
    pickling each way per update. ``previous`` gets the kept state back when it names it; any
    other (a map loaded from a file, a worker started again) is merged without one, afresh.
    The grid is kept too, and made again only when what it shows changed."""
    if previous is not None and isinstance(previous.state, StateInWorker):
        serial = previous.state.serial
        state = kept.get("state") if kept.get("serial") == serial else None
        previous = dataclasses.replace(previous, state=state)
    result, occupancy = merge_with_grid(keyframes, config, grid, previous, method, kept)
    kept["serial"] = kept.get("serial", 0) + 1
    kept["state"] = result.state
    return dataclasses.replace(result, state=StateInWorker(kept["serial"])), occupancy
