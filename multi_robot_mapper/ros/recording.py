"""The merger's outputs as they evolved, recorded to an MCAP file (``mrm replay --record``).

Each :class:`~multi_robot_mapper.core.snapshots.Snapshot` of an offline run becomes, stamped
and logged at its bag time, what ``map_merger`` publishes after a merge, built by the node's
own message builders (:mod:`multi_robot_mapper.ros.markers`, :mod:`.diagnostics`):

- ``/global_map`` (``visualization_msgs/MarkerArray``): one line list per merged keyframe,
  the robots' poses and names, DELETEs of what is gone;
- ``/global_grid`` (``nav_msgs/OccupancyGrid``): the occupancy grid (``grid.enabled``);
- ``/tf`` (``tf2_msgs/TFMessage``): ``map`` -> ``<robot>/map`` (and ``<robot>/map_<k>``) of
  each merged robot, ``<robot>/map`` -> ``<robot>/laser`` its newest pose;
- ``/trajectories/<robot>`` (``nav_msgs/Path``): a merged robot's placed scans in ``map`` (at
  most ``MAX_PATH_POSES``, evenly thinned);
- ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``): the merger's statuses
  (``map_merger``, ``map_merger/<robot>``).

Messages are serialised by ``rclpy.serialization`` (no node, no context), TF by ``rosbags``
(:func:`multi_robot_mapper.io.output_bag.tf_message`).
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.serialization import serialize_message
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from multi_robot_mapper.core.merger_config import MapMergerConfig
from multi_robot_mapper.core.merging.occupancy import global_grid
from multi_robot_mapper.core.snapshots import Snapshot
from multi_robot_mapper.io.messages import pose_msg, stamp_from_seconds
from multi_robot_mapper.io.output_bag import TF_TYPE, FrameTransform, OutputBag, tf_message, thinned
from multi_robot_mapper.ros import diagnostics
from multi_robot_mapper.ros.markers import (
    MarkerCache,
    MarkerKey,
    frame_matrix,
    global_map_markers,
    occupancy_grid_msg,
)

MAX_PATH_POSES = 1000  # poses of a recorded trajectory (its scans thinned evenly)
GLOBAL_MAP = ("/global_map", "visualization_msgs/msg/MarkerArray")
GLOBAL_GRID = ("/global_grid", "nav_msgs/msg/OccupancyGrid")
TF = "/tf"
DIAGNOSTICS = ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
PATH_TYPE = "nav_msgs/msg/Path"


def trajectory_topic(robot: str) -> str:
    return f"/trajectories/{robot}"


def laser_frame(robot: str) -> str:
    return f"{robot}/laser"


def robot_map_frame(robot: str, piece: int = 0) -> str:
    """``<robot>/map``, or ``<robot>/map_<k>`` of a piece (as the robot_mapper names them)."""
    return f"{robot}/map" if piece == 0 else f"{robot}/map_{piece}"


class SnapshotRecorder:
    """A snapshot sink writing each snapshot's outputs to ``bag`` (module doc)."""

    def __init__(self, bag: OutputBag, config: MapMergerConfig) -> None:
        self.bag = bag
        self.config = config
        self.snapshots = 0
        self._shown: set[MarkerKey] = set()
        self._cache: MarkerCache = {}
        self._merges_with: dict[str, int] = {}  # robot -> snapshots whose merge had its map

    def __call__(self, snapshot: Snapshot) -> None:
        self.snapshots += 1
        for robot in snapshot.result.robots:
            self._merges_with[robot] = self._merges_with.get(robot, 0) + 1
        self._global_map(snapshot)
        if self.config.grid.enabled:
            grid = global_grid(snapshot.result, {}, {}, self.config.grid, self.config.merge)
            message = occupancy_grid_msg(
                grid, stamp_from_seconds(snapshot.stamp), self.config.map_frame
            )
            self._write(GLOBAL_GRID, snapshot.stamp, serialize_message(message), latched=True)
        self.bag.write(TF, TF_TYPE, snapshot.stamp, tf_message(self.transforms(snapshot)), False)
        for robot, (stamps, poses) in snapshot.trajectories.items():
            path = self.path(stamps, poses, snapshot.stamp)
            self.bag.write(
                trajectory_topic(robot), PATH_TYPE, snapshot.stamp, serialize_message(path), True
            )
        array = diagnostics.diagnostic_array(
            self.statuses(snapshot), stamp_from_seconds(snapshot.stamp)
        )
        self._write(DIAGNOSTICS, snapshot.stamp, serialize_message(array), latched=False)

    def _write(self, topic: tuple[str, str], stamp: float, data: bytes, latched: bool) -> None:
        self.bag.write(topic[0], topic[1], stamp, data, latched)

    def _global_map(self, snapshot: Snapshot) -> None:
        result = snapshot.result
        shown = {r: p for r, p in snapshot.poses.items() if r in result.robots}
        array = global_map_markers(
            result,
            stamp_from_seconds(snapshot.stamp),
            {r: (np.array(p.pose), stamp_from_seconds(p.stamp)) for r, p in shown.items()},
            self.config.map_frame,
            self.config.marker_width,
            {r: p.piece for r, p in shown.items()},
            self._shown,
            self._cache,
        )
        self._shown = {(m.ns, m.id) for m in array.markers if m.action == Marker.ADD}
        self._write(GLOBAL_MAP, snapshot.stamp, serialize_message(array), latched=True)

    def transforms(self, snapshot: Snapshot) -> list[FrameTransform]:
        """``map`` -> each placed piece of a robot's map, and that frame -> the robot's laser."""
        result, stamp, map_frame = snapshot.result, snapshot.stamp, self.config.map_frame
        transforms = []
        for robot in result.robots:
            for piece in sorted(result.frames.get(robot, {0: None})):
                T_map_piece = frame_matrix(result, robot, piece)
                if T_map_piece is not None:
                    placement = (
                        float(T_map_piece[0, 2]),
                        float(T_map_piece[1, 2]),
                        float(np.arctan2(T_map_piece[1, 0], T_map_piece[0, 0])),
                    )
                    child = robot_map_frame(robot, piece)
                    transforms.append(FrameTransform(map_frame, child, placement, stamp))
        for robot, newest in snapshot.poses.items():
            parent = robot_map_frame(robot, newest.piece)
            transforms.append(FrameTransform(parent, laser_frame(robot), newest.pose, stamp))
        return transforms

    def path(self, stamps: np.ndarray, poses: np.ndarray, stamp: float) -> Path:
        """``nav_msgs/Path`` of placed scans in ``map`` (at most MAX_PATH_POSES of them)."""
        frame = self.config.map_frame
        message = Path(header=Header(frame_id=frame, stamp=stamp_from_seconds(stamp)))
        for index in thinned(len(stamps), MAX_PATH_POSES):
            message.poses.append(
                PoseStamped(
                    header=Header(frame_id=frame, stamp=stamp_from_seconds(float(stamps[index]))),
                    pose=pose_msg(poses[index].tolist()),
                )
            )
        return message

    def statuses(self, snapshot: Snapshot) -> list[diagnostics.DiagnosticStatus]:
        """The merger's statuses as its /diagnostics would say them at the snapshot's time
        (a robot whose last scan is older than ``stale_timeout`` is STALE, as live)."""
        result = snapshot.result
        scores = diagnostics.link_scores(result)
        reasons = diagnostics.unmerged_reasons(result)
        statuses = [diagnostics.merge_status(result, self.snapshots, 0, None, len(result.robots))]
        for index, robot in enumerate(result.robots):
            link_value, best = scores.get(robot, (None, 0.0))
            newest = snapshot.poses.get(robot)
            health = diagnostics.MergerRobotHealth(
                robot=robot,
                placement=result.placements.get(robot),
                reference=result.reference == robot,
                link_value=link_value,
                best_value=best,
                pose_rate=None,
                maps_received=self._merges_with.get(robot, 0),
                keyframes=len(result.keyframe_index.get(robot, ())),
                segments=int(np.count_nonzero(result.segment_robot == index)),
                silent_for=None if newest is None else snapshot.stamp - newest.stamp,
                stale_timeout=self.config.stale_timeout,
                why_unmerged=reasons.get(robot, ""),
                probability=result.probabilities.get(robot),
            )
            statuses.append(diagnostics.merger_status(health))
        return statuses
