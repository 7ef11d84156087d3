"""What an offline run (``mrm replay``, :func:`~multi_robot_mapper.core.pipeline.run_offline`)
takes and gives: each robot's scans with their stamps, and the map made of them."""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.snapshots import NewestPose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass(frozen=True)
class TimedLaserScan:
    """One scan of a robot's recording, with its reference pose when the recording has one."""

    stamp: float
    scan: LaserScanData
    reference_pose: Pose | None = None


@dataclasses.dataclass
class OfflineMap:
    """The pipeline's output, in the global ``map`` frame."""

    robots: list[str]
    map_segments: FloatArray  # (M, 4)
    segment_robot: IntArray  # (M,) index into robots
    trajectories: dict[str, tuple[FloatArray, FloatArray]]  # robot -> stamps (N,), poses (N, 3)
    robot_frames: dict[str, Pose | None]  # T_map_robotmap as (x, y, theta); None = unmerged
    stats: dict[str, object]
    # robot -> (K, 3) keyframe poses in the robot's own map frame (local mapping only)
    keyframe_poses: dict[str, FloatArray] = dataclasses.field(default_factory=dict)
    # robot -> every keyframe of every piece (pose in its piece's frame, segments in its own),
    # what the robot's partial_map carries (local mapping only)
    keyframes: dict[str, list[Keyframe]] = dataclasses.field(default_factory=dict)
    # robot -> every placed scan of every piece: stamps (N,), keyframe (N,), T_keyframe_scan
    # (N, 3) (LocalMapper.anchors; local mapping only)
    anchors: dict[str, tuple[FloatArray, IntArray, FloatArray]] = dataclasses.field(
        default_factory=dict
    )
    # robot -> the probability that its placement is right, and why an unmerged robot is not
    # placed (merging only)
    probabilities: dict[str, float] = dataclasses.field(default_factory=dict)
    unmerged_reasons: dict[str, str] = dataclasses.field(default_factory=dict)
    # robot -> its newest placed scan: T_piece_laser, the scan's stamp, the piece (local
    # mapping only)
    newest_poses: dict[str, NewestPose] = dataclasses.field(default_factory=dict)
    merge_result: MergeResult | None = None  # the merge itself (merging only)
