"""Keyframes fused into one reference: the window the back end matches, and the local map a
scan is tracked against (issue 47 item 5).

One keyframe's scan sees a stretch of corridor; the keyframes before it saw its doors, its
end, the room behind: fused in the last keyframe's frame they fix what the last scan alone
leaves open, and a scan tracked against them is one match against one reference (it settles
alone, as a match against the last keyframe does), not the best of several tries against
older keyframes (which needs another to corroborate it).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeScan
from multi_robot_mapper.core.matching.beams import Viewpoint
from multi_robot_mapper.core.matching.scoring import PairTolerance, pair_tolerance
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.segment_map import SegmentMap

FloatArray = NDArray[np.float64]


class _Known(Protocol):
    """Where the keyframes are and what they saw (the front end's copy: ``References``)."""

    @property
    def poses(self) -> dict[int, Pose]: ...

    @property
    def scans(self) -> dict[int, KeyframeScan]: ...


def fused_keyframes(
    center: int,
    members: Sequence[int],
    pose: Callable[[int], Pose],
    scan: Callable[[int], KeyframeScan],
    pair: PairTolerance,
    tolerance: float,
) -> tuple[FloatArray, list[Viewpoint]]:
    """The scans of keyframes ``members`` fused in keyframe ``center``'s frame (Alg. 5, in
    the order of the keyframes, with INTEGRATE's ``pair`` tolerances and the fusion
    ``tolerance``), and their viewpoints there."""
    T_center = se2.invert(se2.matrix_from_pose(*pose(center)))
    fused, owner = np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
    viewpoints = []
    for k in sorted(int(m) for m in members):
        member = scan(k)
        T = T_center @ se2.matrix_from_pose(*pose(k))
        placed = se2.transform_segments(T, member.segments)
        fused, owner = fuse(
            fused,
            owner,
            placed,
            np.full(len(placed), k, dtype=np.int64),
            pair,
            tolerance,
        )
        viewpoints.append(Viewpoint(member.view, T))
    return fused, viewpoints


@dataclasses.dataclass(frozen=True)
class LocalMap:
    """The last keyframe and the recent keyframes of its piece, fused in its frame."""

    keyframe: int
    segments: FloatArray
    viewpoints: list[Viewpoint]

    @functools.cached_property
    def segment_map(self) -> SegmentMap:
        """The fused segments as a map, made once: what a scan is tracked against."""
        return SegmentMap.of(self.segments)


class LocalMaps:
    """The local map of the robot's last keyframe, made again only when its keyframes or
    their poses change (a new keyframe, an optimisation of the graph)."""

    def __init__(self) -> None:
        self._key: tuple[tuple[int, Pose], ...] | None = None
        self._map: LocalMap | None = None

    def around(
        self, keyframe: int, recent: Sequence[int], known: _Known, config: LocalMapperConfig
    ) -> LocalMap | None:
        """``keyframe`` and the ``recent`` keyframes of its piece (newest first) fused in its
        frame, ``local_map_keyframes`` in all, at the poses and with the scans ``known`` has;
        None when that is the keyframe alone (its own reference)."""
        recent = list(recent)[: config.local_map_keyframes - 1]
        if not recent:
            return None
        poses, scans = known.poses, known.scans
        members = (keyframe, *recent)
        key = tuple((k, poses[k]) for k in members)
        if key != self._key or self._map is None:
            segments, viewpoints = fused_keyframes(
                keyframe,
                members,
                poses.__getitem__,
                scans.__getitem__,
                pair_tolerance(config.integrate),
                config.fusion_tolerance,
            )
            self._key, self._map = key, LocalMap(keyframe, segments, viewpoints)
        return self._map
