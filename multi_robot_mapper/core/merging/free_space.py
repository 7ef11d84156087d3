"""Free space: what a robot saw from its keyframes, and links that contradict it."""

from __future__ import annotations

import dataclasses
import hashlib
from collections import OrderedDict
from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import lines_of, point_segment_distance, sample_segments
from multi_robot_mapper.core.simulation import raycast_fans

FloatArray = NDArray[np.float64]


class ViewFan(NamedTuple):
    """How a map's views are cast (:meth:`MapViews.of`): viewpoints at least ``spacing`` (m)
    apart, at most ``most`` of them, a full turn cut into ``beams`` bearings of which those
    within ``field`` (rad) around each heading are cast, out to ``reach`` (m). MergeConfig's
    ``view_spacing``, ``max_views``, ``view_beams``, ``view_field`` and ``view_range``
    (:meth:`~core.merging.config.MergeConfig.view_fan`)."""

    spacing: float
    most: int
    beams: int
    field: float
    reach: float


class FreeSpaceLimits(NamedTuple):
    """What a wall in free space is (:func:`seen_through_length`): a wall at least
    ``min_length`` (m) long, nearer a viewpoint than the map's own wall (the nearest within
    ``spread`` bearings either side) by ``margin`` (m). MergeConfig's
    ``free_space_min_length``, ``view_spread`` and ``free_space_margin``
    (:meth:`~core.merging.config.MergeConfig.free_space_limits`)."""

    min_length: float
    spread: int
    margin: float


class FreeDrawing(NamedTuple):
    """How a map's free space is drawn for the correlation (:meth:`MapViews.free_points`): a
    point every ``cell`` (m) along each bearing, out to ``margin`` (m) before the wall that
    ends it (the nearest within ``spread`` bearings either side) and to ``reach`` (m) at
    most. MergeConfig's ``correlation_cell``, ``view_spread``, ``free_space_margin`` and
    ``view_range`` (:meth:`~core.merging.config.MergeConfig.free_drawing`)."""

    cell: float
    spread: int
    margin: float
    reach: float


# A view's ranges by what they are cast from: the pose, the walls within reach of it, the fan.
ViewRows = OrderedDict[tuple[str, tuple[float, float, int, float]], FloatArray]
# Rows kept: 8 robots' maps of a few hundred views each, twice over.
KEPT_ROWS = 8192


def _cast(
    segments: FloatArray,
    poses: FloatArray,
    fan: tuple[float, float, int, float],
    kept: ViewRows,
) -> FloatArray:
    """(K, B) :func:`raycast_fans` of ``poses`` with the fan (first bearing, step, beams,
    range), each row taken from ``kept`` when cast before from the same pose on the same walls
    within its range (+ 1 m): a robot's map grows at its end, and the views of the rest of it
    are those of the last update (issue 50). Each (view, wall) pair is solved apart and a
    beam's range is the least hit within range, so a row cast on the walls within range is
    the row cast on all of them, bit for bit."""
    if len(segments) == 0 or len(poses) == 0:
        return raycast_fans(segments, poses, *fan)
    reach = fan[3] + 1.0
    gap = point_segment_distance(
        poses[:, None, 0],
        poses[:, None, 1],
        segments[None, :, 0],
        segments[None, :, 1],
        segments[None, :, 2],
        segments[None, :, 3],
    )
    keys = [
        (hashlib.sha1(np.concatenate((pose, segments[near].ravel())).tobytes()).hexdigest(), fan)
        for pose, near in zip(poses, gap <= reach, strict=True)
    ]
    missing = [row for row, key in enumerate(keys) if key not in kept]
    if missing:
        cast = raycast_fans(segments, poses[missing], *fan)
        for row, ranges in zip(missing, cast, strict=True):
            kept[keys[row]] = ranges
    for key in keys:
        kept.move_to_end(key)
    while len(kept) > KEPT_ROWS:
        kept.popitem(last=False)
    return np.array([kept[key] for key in keys])


@dataclasses.dataclass(frozen=True)
class MapViews:
    """Free space a robot saw: its own map ray cast from its viewpoints (``view_field``
    around each keyframe's heading).

    A partial map carries no scans, but its keyframe poses say where the laser stood; the
    robot's own walls seen from there bound the space its beams crossed (a door the map does
    not close leaves no wall on that bearing, and nothing is claimed there). Another robot's
    wall placed inside that space contradicts the placement: the two buildings only look alike
    (the look-alike rooms and corridors segment overlap cannot tell apart).
    """

    poses: FloatArray  # (K, 3) viewpoints (laser poses) in the robot's map frame
    ranges: FloatArray  # (K, B) the map's range at each bearing of each view (inf: no wall)
    angle_min: float  # bearing of column 0 in each viewpoint's frame (rad)
    angle_increment: float  # rad between columns

    @staticmethod
    def of(
        segments: FloatArray,
        keyframe_poses: FloatArray,
        fan: ViewFan,
        rows: ViewRows | None = None,
    ) -> MapViews:
        """The views of a map from its keyframe poses, at least ``fan.spacing`` apart and at
        most ``fan.most`` of them, ``fan.field`` wide around each heading. ``rows``: rows
        cast before, by pose and the walls within ``fan.reach`` of it (:func:`_cast`)."""
        poses = np.asarray(keyframe_poses, dtype=np.float64).reshape(-1, 3)
        kept: list[int] = []
        for index in range(len(poses)):  # greedy thinning over keyframes (a few hundred)
            if not kept or np.min(np.hypot(*(poses[kept, :2] - poses[index, :2]).T)) >= fan.spacing:
                kept.append(index)
        if len(kept) > fan.most:
            kept = [kept[i] for i in np.linspace(0, len(kept) - 1, fan.most).astype(int)]
        chosen = poses[kept]
        step = 2.0 * np.pi / fan.beams
        beams = max(2, round(fan.field / step) + 1)
        first = -0.5 * step * (beams - 1)
        cast_fan = (first, step, beams, fan.reach)
        if rows is None:
            return MapViews(chosen, raycast_fans(segments, chosen, *cast_fan), first, step)
        return MapViews(chosen, _cast(segments, chosen, cast_fan, rows), first, step)

    def free_limits(self, spread: int) -> FloatArray:
        """(K, B) how far free space reaches along each bearing: the nearest wall within
        ``spread`` bearings either side (a gap between two segments is not seen through), and
        nothing (-inf) where some bearing of that window hits no wall or lies beyond the edge
        of the field of view (the field does not wrap round, even at 2 pi: its first and last
        ``spread`` bearings claim nothing)."""
        limits = np.where(np.isfinite(self.ranges), self.ranges, -np.inf)
        if spread > 0 and limits.shape[1]:
            padded = np.pad(limits, ((0, 0), (spread, spread)), constant_values=-np.inf)
            windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * spread + 1, axis=1)
            limits = windows.min(axis=2)
        return np.asarray(limits)

    def free_points(
        self, spacing: float, spread: int, margin: float, view_range: float
    ) -> FloatArray:
        """Points every ``spacing`` metres along every bearing of every view, out to
        ``margin`` before the wall that ends it (:meth:`free_limits` of ``spread``) and to
        ``view_range`` at most: where the robot's laser saw nothing."""
        reach = self.free_limits(spread) - margin
        steps = np.arange(spacing, view_range, spacing)
        view, bearing, step = np.nonzero(reach[:, :, None] > steps[None, None, :])
        if view.size == 0:
            return np.zeros((0, 2))
        heading = self.poses[view, 2] + self.angle_min + self.angle_increment * bearing
        distance = steps[step]
        return np.column_stack(
            (
                self.poses[view, 0] + distance * np.cos(heading),
                self.poses[view, 1] + distance * np.sin(heading),
            )
        )


def seen_through_length(views: MapViews, segments: FloatArray, limits: FreeSpaceLimits) -> float:
    """Length of the walls among ``segments`` (in the views' map frame; those at least
    ``limits.min_length`` long) lying in the free space of ``views``: nearer some
    viewpoint than the map's own wall on that bearing by ``limits.margin``."""
    spacing = 0.2  # m between the points tested along each wall
    walls = segments[lines_of(segments).length >= limits.min_length]
    if len(walls) == 0 or len(views.poses) == 0:
        return 0.0
    points, owner = sample_segments(walls, spacing)
    # Each point stands for its wall's length over its points (a wall's two ends both count).
    weight = (lines_of(walls).length / np.bincount(owner, minlength=len(walls)))[owner]
    reaches = views.free_limits(limits.spread)
    # Every point in every viewpoint's frame at once: (K, P) bearings and distances.
    dx = points[None, :, 0] - views.poses[:, 0, None]
    dy = points[None, :, 1] - views.poses[:, 1, None]
    bearing = se2.wrap_angle(np.arctan2(dy, dx) - views.poses[:, 2, None])
    distance = np.hypot(dx, dy)
    column = np.rint((bearing - views.angle_min) / views.angle_increment).astype(np.int64)
    inside = (column >= 0) & (column < reaches.shape[1])
    reach = np.take_along_axis(reaches, np.where(inside, column, 0), axis=1)
    seen = inside & (distance < reach - limits.margin)
    return float(weight[seen.any(axis=0)].sum())


ViewSource = Callable[[str], "MapViews | None"]


def no_views(robot: str) -> MapViews | None:
    return None


def view_source(
    maps: Mapping[str, FloatArray], viewpoints: Mapping[str, FloatArray], fan: ViewFan
) -> ViewSource:
    """Each robot's :class:`MapViews` (None without viewpoints or without a map: no free
    space known), cast on first use: a re-run whose pairs are all reused casts none."""
    cache: dict[str, MapViews | None] = {}

    def views(robot: str) -> MapViews | None:
        if robot not in cache:
            poses = np.asarray(viewpoints.get(robot, np.zeros((0, 3))), dtype=np.float64)
            known = len(poses.reshape(-1, 3)) > 0 and len(maps[robot]) > 0
            cache[robot] = MapViews.of(maps[robot], poses, fan) if known else None
        return cache[robot]

    return views


def seen_through_allowance(value: float, least: float, fraction: float) -> float:
    """How much wall in the other robot's free space a link of ``value`` m tolerates:
    ``least`` m (``link_max_seen_through``), or ``fraction`` of the value when larger
    (drifting maps)."""
    return max(least, fraction * value)


def free_space_conflict(
    map_a: FloatArray,
    views_a: MapViews | None,
    map_b: FloatArray,
    views_b: MapViews | None,
    T_a_b: FloatArray,
    limits: FreeSpaceLimits,
) -> float:
    """The larger of: map b (moved by ``T_a_b``) in a's free space, map a in b's (metres;
    ``limits``: what a wall in free space is)."""
    through = 0.0
    if views_a is not None:
        through = seen_through_length(views_a, se2.transform_segments(T_a_b, map_b), limits)
    if views_b is not None:
        back = se2.transform_segments(se2.invert(T_a_b), map_a)
        through = max(through, seen_through_length(views_b, back, limits))
    return through
