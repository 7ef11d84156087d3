"""The ``reference`` method of an offline run: every scan with a reference (ground-truth)
pose placed at it. A labelled tool for checking the evaluator and the pictures, never a mapping
result."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.front_end import FrontEnd
from multi_robot_mapper.core.offline import OfflineMap, TimedLaserScan
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def run_reference(
    recordings: Mapping[str, Sequence[TimedLaserScan]], front_end: FrontEnd, method: str
) -> OfflineMap:
    """The ``reference`` method of an offline run: every scan with a reference pose placed
    at it."""
    robots = sorted(recordings)
    segment_sets: list[FloatArray] = []
    owners: list[IntArray] = []
    trajectories: dict[str, tuple[FloatArray, FloatArray]] = {}
    started = time.perf_counter()
    for index, robot in enumerate(robots):
        stamps: list[float] = []
        poses: list[Pose] = []
        # 'reference' can only place scans that have a reference pose.
        # A reset changes nothing here: every scan is placed in the reference frame.
        for item, segments, _ in front_end.scans(robot, recordings[robot], needs_reference=True):
            assert item.reference_pose is not None
            T_map_laser = se2.matrix_from_pose(*item.reference_pose)
            segment_sets.append(se2.transform_segments(T_map_laser, segments.segments))
            owners.append(np.full(len(segments), index, dtype=np.int64))
            stamps.append(item.stamp)
            poses.append(item.reference_pose)
        trajectories[robot] = (
            np.asarray(stamps, dtype=np.float64),
            np.asarray(poses, dtype=np.float64).reshape(-1, 3),
        )
    map_segments = np.vstack(segment_sets) if segment_sets else np.zeros((0, 4))
    segment_robot = np.concatenate(owners) if owners else np.zeros(0, dtype=np.int64)
    posed = sum(len(t[0]) for t in trajectories.values())
    stats: dict[str, object] = {
        "method": method,
        "scans_posed": posed,
        "segments": len(map_segments),
        **front_end.counts(),
        "total_s": round(time.perf_counter() - started, 4),
    }
    # With reference poses every robot frame is the reference world frame.
    frames: dict[str, Pose | None] = {r: (0.0, 0.0, 0.0) for r in robots}
    return OfflineMap(robots, map_segments, segment_robot, trajectories, frames, stats)
