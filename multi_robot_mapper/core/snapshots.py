"""The outputs of an offline run as they evolved: every ``period`` s of bag time, the keyframes
mapped so far merged as the merger node would have merged them, with each robot's newest pose
and placed scans (:class:`Snapshot`), handed to a sink (``mrm replay --record`` writes them to
an MCAP file)."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.core.merging import MergeConfig, MergeResult
from multi_robot_mapper.core.merging.joint import place_scans
from multi_robot_mapper.core.merging.methods import merge_method
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass(frozen=True)
class NewestPose:
    """A robot's newest placed scan: its pose in its piece's frame, stamp and piece."""

    pose: Pose  # T_piece_laser
    stamp: float
    piece: int


@dataclasses.dataclass(frozen=True)
class Snapshot:
    """The outputs at one moment of bag time, as a merger running beside the robots would have
    had them: every robot's keyframes so far merged, each robot's newest pose and its placed
    scans. ``final``: the replay's own result (the last snapshot)."""

    stamp: float  # bag time: the newest scan mapped so far
    result: MergeResult
    poses: dict[str, NewestPose]  # robot -> newest pose in its own piece's frame
    trajectories: dict[str, tuple[FloatArray, FloatArray]]  # merged robot -> placed scans in map
    final: bool = False


SnapshotSink = Callable[[Snapshot], None]


@dataclasses.dataclass
class Timeline:
    """Snapshots every ``period`` s of bag time while the robots map
    (:func:`~multi_robot_mapper.core.pipeline.run_offline`)."""

    sink: SnapshotSink
    period: float
    method: str
    config: MergeConfig
    due: float | None = None  # bag time of the next snapshot
    newest: float | None = None  # the newest stamp mapped since the last snapshot
    previous: MergeResult | None = None
    taken: int = 0
    merge_s: float = 0.0

    def before(self, stamp: float, mappers: Mapping[str, LocalMapper]) -> None:
        """Called before a scan stamped ``stamp`` is mapped: a snapshot of what was mapped
        before it when one is due (none over a stretch of time with nothing new)."""
        if self.due is None:
            self.due = stamp + self.period
        if not stamp >= self.due:  # also a NaN stamp: never due
            return
        if self.newest is not None:
            self.take(mappers, self.newest)
        self.due += self.period * (math.floor((stamp - self.due) / self.period) + 1)

    def mapped(self, stamp: float) -> None:
        self.newest = stamp if self.newest is None else max(self.newest, stamp)

    def take(self, mappers: Mapping[str, LocalMapper], stamp: float) -> None:
        keyframes = {robot: mapper.keyframes() for robot, mapper in mappers.items()}
        keyframes = {robot: frames for robot, frames in keyframes.items() if frames}
        if not keyframes:
            return
        started = time.perf_counter()
        merge_keyframes = merge_method(self.method)
        result = merge_keyframes(keyframes, self.config, previous=self.previous, budget=0.0)
        self.merge_s += time.perf_counter() - started
        self.previous = result
        poses = {
            robot: pose for robot, m in mappers.items() if (pose := newest_pose(m)) is not None
        }
        trajectories = {}
        for robot in keyframes:
            placed = place_scans(result, robot, all_anchors(mappers[robot]))
            if placed is not None:
                trajectories[robot] = placed
        self.sink(Snapshot(stamp, result, poses, trajectories))
        self.newest = None
        self.taken += 1


def newest_pose(mapper: LocalMapper) -> NewestPose | None:
    pose, stamp = mapper.pose, mapper.stamp
    if pose is None or stamp is None:
        return None
    return NewestPose(tuple(float(v) for v in pose), stamp, mapper.piece)  # type: ignore[arg-type]


def all_anchors(mapper: LocalMapper) -> tuple[FloatArray, IntArray, FloatArray]:
    """Every placed scan of every piece of ``mapper``'s map (:meth:`LocalMapper.anchors`)."""
    pieces = sorted({kf.piece for kf in mapper.keyframes()})
    placed = [mapper.anchors(piece) for piece in pieces]
    return (
        np.concatenate([a[0] for a in placed]) if placed else np.zeros(0),
        np.concatenate([a[1] for a in placed]) if placed else np.zeros(0, dtype=np.int64),
        np.vstack([a[2] for a in placed]) if placed else np.zeros((0, 3)),
    )
