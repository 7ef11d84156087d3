"""A robot's keyframes and the fused partial map they own.

Every keyframe keeps its own scan (segments and beams, in its own frame: what matching needs)
and owns part of the fused map, also in its own frame, so that a keyframe moved by the pose
graph carries its walls with it: the map in the robot's frame is always the owned segments
placed at the owners' current poses (:meth:`KeyframeMap.map_segments`). A new keyframe's
segments are fused (Amigoni Alg. 5, :func:`core.fusion.fuse`) with the map near it, so a wall
seen many times stays one wall; a fused polyline belongs to the oldest keyframe among its
members.

Keyframes belong to *pieces*: a robot that loses track maps on in a new piece, with a frame of
its own (its first keyframe). A closure between two pieces joins them: the younger piece is
expressed in the older one's frame (:meth:`KeyframeMap.join`). Pieces never fuse with each
other until joined.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.geometry import point_segment_distance
from multi_robot_mapper.core.matching.scoring import PairTolerance
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.segment_map import SegmentMap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


@dataclasses.dataclass(frozen=True)
class Keyframe:
    """One keyframe as the wire carries it: its pose in its piece's frame and the fused map
    segments it owns, in its own frame."""

    index: int
    stamp: float
    T_robotmap_keyframe: FloatArray  # (3,) x, y, theta in its piece's frame
    segments: FloatArray  # (N, 4) in the keyframe's frame
    piece: int = 0  # the piece's first keyframe index (0: the robot's main map frame)


@dataclasses.dataclass(frozen=True)
class KeyframeScan:
    """What matching needs of a keyframe: its scan, in its own frame."""

    index: int
    stamp: float
    segments: FloatArray  # (N, 4) the scan's segments
    view: LaserScanData  # the scan's beams

    @functools.cached_property
    def segment_map(self) -> SegmentMap:
        """The scan's segments as a map, made once: what matching reads of them."""
        return SegmentMap.of(self.segments)


class KeyframeMap:
    """Keyframes (scan, pose, piece) and the fused partial map they own."""

    def __init__(self, pair: PairTolerance, tolerance: float, radius: float) -> None:
        self.pair = pair  # INTEGRATE's pair tolerances (scoring.pair_tolerance)
        self.tolerance = tolerance  # FUSIONTOLERANCE
        self.radius = radius  # fusion reach around a new keyframe
        self.scans: list[KeyframeScan] = []
        self._poses = np.zeros((0, 3))  # (K, 3) each keyframe in its piece's frame
        self._piece = np.zeros(0, dtype=np.int64)  # (K,) piece of each keyframe
        self._segments = np.zeros((0, 4))  # (M, 4) owned map segments, owner's frame
        self._owner = np.zeros(0, dtype=np.int64)  # (M,) owning keyframe
        self._changed: set[int] = set()  # keyframes whose pose or segments changed

    def __len__(self) -> int:
        return len(self.scans)

    # --- reading ----------------------------------------------------------------------------

    def pose(self, index: int) -> Pose:
        x, y, theta = (float(v) for v in self._poses[index])
        return (x, y, theta)

    @property
    def poses(self) -> FloatArray:
        """(K, 3) every keyframe's pose in its piece's frame."""
        return self._poses.copy()

    def piece(self, index: int) -> int:
        return int(self._piece[index])

    @property
    def pieces(self) -> IntArray:
        """(K,) the piece of every keyframe."""
        return self._piece.copy()

    def members(self, piece: int) -> IntArray:
        return np.flatnonzero(self._piece == piece)

    def map_segments(self, piece: int | None = None) -> FloatArray:
        """The fused map in its piece's frame (``piece`` None: every piece, each in its own
        frame, stacked)."""
        keep = np.ones(len(self._owner), dtype=bool)
        if piece is not None:
            keep = self._piece[self._owner] == piece
        owner = self._owner[keep]
        return se2.transform_segments_each(self._poses[owner], self._segments[keep])

    def owned_segments(self, indices: IntArray) -> FloatArray:
        """The map segments owned by keyframes ``indices``, in their piece's frame."""
        keep = np.isin(self._owner, np.asarray(indices, dtype=np.int64))
        owner = self._owner[keep]
        return se2.transform_segments_each(self._poses[owner], self._segments[keep])

    def keyframes(self, indices: list[int] | None = None) -> list[Keyframe]:
        """Keyframes (default: every one) with the map segments they own, in their frame."""
        wanted = range(len(self.scans)) if indices is None else indices
        order = np.argsort(self._owner, kind="stable")
        bounds = np.searchsorted(self._owner[order], np.arange(len(self.scans) + 1))
        return [
            Keyframe(
                self.scans[k].index,
                self.scans[k].stamp,
                self._poses[k].copy(),
                self._segments[order[bounds[k] : bounds[k + 1]]].copy(),
                int(self._piece[k]),
            )
            for k in wanted
        ]

    def take_changed(self) -> list[int]:
        """The keyframes whose pose, piece or owned segments changed since the last call."""
        changed, self._changed = sorted(self._changed), set()
        return changed

    def near(self, pose: Pose, piece: int, radius: float, before: int | None = None) -> IntArray:
        """Keyframes of ``piece`` within ``radius`` of ``pose`` (older than ``before`` when
        given), nearest first."""
        candidates = self.members(piece)
        if before is not None:
            candidates = candidates[candidates < before]
        distance = np.hypot(
            self._poses[candidates, 0] - pose[0], self._poses[candidates, 1] - pose[1]
        )
        inside = distance <= radius
        return np.asarray(candidates[inside][np.argsort(distance[inside], kind="stable")])

    # --- changing ---------------------------------------------------------------------------

    def add(self, scan: KeyframeScan, pose: Pose, piece: int) -> None:
        """A new keyframe at ``pose`` in ``piece`` (its segments join the map with
        :meth:`fuse`)."""
        if scan.index != len(self.scans):
            raise ValueError(f"keyframe {scan.index} added as keyframe {len(self.scans)}")
        self.scans.append(scan)
        self._poses = np.vstack((self._poses, np.asarray(pose, dtype=np.float64)))
        self._piece = np.append(self._piece, piece)
        self._changed.add(scan.index)

    def fuse(self, index: int) -> None:
        """Alg. 5 between the map near keyframe ``index`` (its piece only) and its scan's
        segments: a wall seen again stays one wall."""
        self._fuse(index, self.scans[index].segments)

    def set_poses(self, poses: dict[int, Pose]) -> None:
        """New poses of some keyframes (the pose graph moved them): their walls move along."""
        for index, pose in poses.items():
            if tuple(self._poses[index]) != tuple(pose):
                self._poses[index] = pose
                self._changed.add(index)

    def join(self, moved_piece: int, kept_piece: int, T_kept_moved: FloatArray) -> None:
        """Express every keyframe of ``moved_piece`` in ``kept_piece``'s frame (``T_kept_moved``
        3x3) and make it part of that piece."""
        moved = self.members(moved_piece)
        T = T_kept_moved
        for index in moved:
            self._poses[index] = se2.pose_from_matrix(T @ se2.matrix_from_pose(*self._poses[index]))
        self._piece[moved] = kept_piece
        self._changed.update(int(k) for k in moved)

    def _fuse(self, index: int, segments: FloatArray) -> None:
        """Alg. 5 between the map near keyframe ``index`` (its piece only) and its segments."""
        pose = self._poses[index]
        placed = se2.transform_segments(se2.matrix_from_pose(*pose), segments)
        reach = float(
            np.hypot(placed[:, 0::2] - pose[0], placed[:, 1::2] - pose[1]).max(initial=0.0)
        )
        world = se2.transform_segments_each(self._poses[self._owner], self._segments)
        distance = point_segment_distance(
            np.full(len(world), pose[0]),
            np.full(len(world), pose[1]),
            world[:, 0],
            world[:, 1],
            world[:, 2],
            world[:, 3],
        )
        near = (self._piece[self._owner] == self._piece[index]) & (
            distance <= max(self.radius, reach) + 0.5
        )
        fused, fused_owner = fuse(
            world[near],
            self._owner[near],
            placed,
            np.full(len(placed), index, dtype=np.int64),
            self.pair,
            self.tolerance,
        )
        local = se2.inverse_transform_segments_each(self._poses[fused_owner], fused)
        self._changed.update(int(k) for k in np.unique(self._owner[near]))
        self._changed.add(index)
        self._segments = np.vstack((self._segments[~near], local))
        self._owner = np.concatenate((self._owner[~near], fused_owner))
