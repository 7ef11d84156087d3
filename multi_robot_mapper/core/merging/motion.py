"""How far a robot can have driven between two of its keyframes: the one thing that ties a
robot's pieces together when no match does.

A robot lost by its front end starts a new piece at its next scan, so its pieces follow each
other in time, and the wire stamps every keyframe. Between two keyframes of one piece the
robot moved as the piece says; between keyframes of two pieces it drove at most
``max_speed`` times the time between them. Along the robot's keyframes in time order these
steps add up to a reach: an upper bound on the distance between any two of its keyframes
(the triangle inequality along its path). A merge that places two of a robot's pieces so
that two of their keyframes lie farther apart than that has placed one of them at a
look-alike: in the symmetric corridors of aces, sets of four to six confident links, all
consistent, turn one piece of a robot half round tens of metres from the piece it followed
seconds before.

Only keyframes next to each other in time among those placed need checking: the reach is
additive along time, so the bound between any two follows from the bounds between
neighbours.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.confidence import RIGHT_DISTANCE
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass(frozen=True)
class RobotReach:
    """One robot's keyframes in time order (the map each is in and its row there) and the
    reach: ``reach[j] - reach[i]`` bounds the distance between keyframes ``i`` and ``j``."""

    maps: list[UnitKey]  # the robot's maps
    map_of: IntArray  # (K,) index into ``maps`` of each keyframe's map
    rows: IntArray  # (K,) its row in that map
    reach: FloatArray  # (K,) cumulative bound (m) from the robot's first keyframe


def robot_reaches(units: Mapping[UnitKey, MapUnit], max_speed: float) -> dict[str, RobotReach]:
    """Each robot's :class:`RobotReach`: a step between two keyframes of one map is the
    distance the map puts between them; a step between maps is ``max_speed`` (m/s) times the
    time between their stamps. Keyframes are taken in index order (the order the robot made
    them); a robot whose stamps do not increase with it (no clock, a replay gone wrong) gets
    no bound between its maps: its time says nothing."""
    by_robot: dict[str, list[UnitKey]] = {}
    for key in sorted(units):
        by_robot.setdefault(key[0], []).append(key)
    reaches: dict[str, RobotReach] = {}
    for robot, keys in by_robot.items():
        map_of = np.concatenate([np.full(len(units[k].index), i) for i, k in enumerate(keys)])
        rows = np.concatenate([np.arange(len(units[k].index)) for k in keys])
        index = np.concatenate([units[k].index for k in keys])
        stamps = np.concatenate([units[k].stamps for k in keys])
        xy = np.vstack([units[k].poses[:, :2] for k in keys])
        order = np.argsort(index, kind="stable")
        map_of, rows, stamps, xy = map_of[order], rows[order], stamps[order], xy[order]
        elapsed = np.diff(stamps)
        clock = bool(np.isfinite(stamps).all() and (elapsed > 0.0).all())
        step = np.where(
            map_of[1:] == map_of[:-1],
            np.hypot(*np.diff(xy, axis=0).T),
            max_speed * elapsed if clock else np.inf,
        )
        reaches[robot] = RobotReach(
            keys,
            map_of.astype(np.int64),
            rows.astype(np.int64),
            np.concatenate([[0.0], np.cumsum(step)]),
        )
    return reaches


def _steps(
    placed: Mapping[UnitKey, FloatArray], units: Mapping[UnitKey, MapUnit], reach: RobotReach
) -> tuple[IntArray, FloatArray, FloatArray] | None:
    """The robot's keyframes in ``placed`` in time order: the map of each (index into
    ``reach.maps``), and between each and the next the distance ``placed`` puts and the
    bound; None with fewer than two maps."""
    in_group = [i for i, key in enumerate(reach.maps) if key in placed]
    if len(in_group) < 2:
        return None
    keep = np.isin(reach.map_of, in_group)
    map_of, rows = reach.map_of[keep], reach.rows[keep]
    xy = np.empty((len(rows), 2))
    for i in in_group:
        mine = map_of == i
        key = reach.maps[i]
        xy[mine] = se2.transform_points(placed[key], units[key].poses[rows[mine], :2])
    with np.errstate(invalid="ignore"):  # inf - inf: no bound after a robot without a clock
        bound = np.nan_to_num(np.diff(reach.reach[keep]), nan=np.inf)
    return map_of, np.hypot(*np.diff(xy, axis=0).T), bound


def motion_excess(
    placed: Mapping[UnitKey, FloatArray],
    units: Mapping[UnitKey, MapUnit],
    reaches: Mapping[str, RobotReach],
    slack: float,
) -> float:
    """The most (m) by which ``placed`` (maps -> 3x3 T_group_map, one group of maps) puts two
    keyframes of one robot in different maps farther apart than the robot can have driven
    between them, beyond the correctness tolerance plus ``slack`` per metre of reach (the
    maps' own drift); 0.0 when every robot's placed pieces follow each other."""
    worst = 0.0
    for robot in sorted({key[0] for key in placed}):
        steps = None if robot not in reaches else _steps(placed, units, reaches[robot])
        if steps is None:
            continue
        map_of, apart, bound = steps
        between_maps = map_of[1:] != map_of[:-1]
        if between_maps.any():
            excess = apart - bound * (1.0 + slack) - RIGHT_DISTANCE
            worst = max(worst, float(excess[between_maps].max()))
    return worst
