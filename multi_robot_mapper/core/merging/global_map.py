"""The global map of the joint graph's merge: every merged keyframe's segments at its
optimised pose, fused map by map in placing order (Amigoni Alg. 5, :func:`fuse_maps`).

Fusing is most of an update's cost once the places are matched (0.25 s of about 1 s for 8
robots of 110 keyframes), and most updates move few keyframes: one robot's new keyframe
changes that robot's map, and the graph moves the other maps' keyframes by a few millimetres
at most (intel cut into 8 robots: 0.0-2.3 mm, up to 1 mrad). The fusion of the maps before
the first one in the placing order that changed (its content, or a keyframe whose walls moved
by more than a quarter of ``fusion_tolerance``) is therefore the previous update's, kept here
for the last merge made in this process. Fusion joins walls within ``fusion_tolerance`` of
each other, so walls that moved a quarter of that would fuse the same, and the map shown
never lies further than that from the keyframes' optimised poses.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.merging.compose import fuse_maps
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass(frozen=True)
class _Fused:
    """The global map after fusing the maps of a placing order up to one map: that map, its
    content and the poses it was fused at (what the next update may reuse)."""

    key: UnitKey
    content: str
    poses: FloatArray
    segments: FloatArray
    owner: IntArray


@dataclasses.dataclass
class FusionCache:
    """The last global map's fusion, map by map: (robots, config, prefix states). An update
    fuses again only from the first map in the placing order that changed or moved (module
    doc). It travels with the merge's state (``JointState.fusion``): two mergers in one
    process share nothing."""

    last: tuple[tuple[str, ...], MergeConfig, tuple[_Fused, ...]] | None = None


# A keyframe whose walls moved less than this share of fusion_tolerance since the last
# fusion is not fused again (module doc).
_STILL_SHARE = 0.25


def fuse_keyframes(
    robots: list[str],
    units: Mapping[UnitKey, MapUnit],
    order: Sequence[UnitKey],
    poses: Mapping[UnitKey, FloatArray],
    config: MergeConfig,
    cache: FusionCache | None = None,
) -> tuple[FloatArray, IntArray, IntArray]:
    """Every merged keyframe's segments at its optimised pose, fused map by map in placing
    order; each fused segment's robot (index into ``robots``) and owning keyframe. With
    ``cache``, the fusion of the maps before the first one that changed (content, or a
    keyframe whose walls moved by more than a quarter of ``fusion_tolerance``) is the
    previous update's, and this one's is left in it."""
    last = None if cache is None else cache.last
    previous = last[2] if last is not None and last[:2] == (tuple(robots), config) else ()
    segments = np.zeros((0, 4))
    owner = np.zeros(0, dtype=np.int64)
    base: list[tuple[int, int]] = []  # global owner id -> (robot index, keyframe index)
    states: list[_Fused] = []
    reusing = True
    for position, key in enumerate(order):
        unit = units[key]
        placed = poses[key]
        content = hashlib.sha1(
            unit.index.tobytes() + unit.owner.tobytes() + unit.segments.tobytes()
        ).hexdigest()
        ids = len(base) + unit.owner
        base += [(robots.index(key[0]), int(k)) for k in unit.index]
        old = previous[position] if reusing and position < len(previous) else None
        if (
            old is not None
            and old.key == key
            and old.content == content
            and _still(old, placed, unit, _STILL_SHARE * config.fusion_tolerance)
        ):
            segments, owner = old.segments, old.owner
            states.append(old)
            continue
        reusing = False
        if len(unit.segments):
            stacked = np.vstack(unit.local)
            moved = se2.transform_segments_each(placed[unit.owner], stacked)
            segments, owner = fuse_maps(
                segments,
                owner,
                moved,
                ids.astype(np.int64),
                pair_tolerance(config.integrate),
                config.fusion_tolerance,
            )
        states.append(_Fused(key, content, placed, segments, owner))
    if cache is not None:
        cache.last = (tuple(robots), config, tuple(states))
    table = np.array(base, dtype=np.int64).reshape(-1, 2)
    if len(owner) == 0:
        return segments.reshape(-1, 4), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return segments, table[owner, 0], table[owner, 1]


def _still(fused: _Fused, poses: FloatArray, unit: MapUnit, allowed: float) -> bool:
    """Have a map's keyframes stayed where they were fused: has no wall moved by more than
    ``allowed`` (its keyframe's shift plus its turn times the wall's farthest end point)?"""
    if fused.poses.shape != poses.shape:
        return False
    shift = np.hypot(*(fused.poses[:, :2] - poses[:, :2]).T)
    turn = np.abs(se2.wrap_angle(fused.poses[:, 2] - poses[:, 2]))
    reach = np.zeros(len(poses))
    if len(unit.segments):
        ends = np.vstack(unit.local).reshape(-1, 2)
        np.maximum.at(reach, np.repeat(unit.owner, 2), np.hypot(ends[:, 0], ends[:, 1]))
    return bool(np.all(shift + turn * reach <= allowed))
