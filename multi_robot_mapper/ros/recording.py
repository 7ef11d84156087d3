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
(:func:`multi_robot_mapper.io.output_bag.tf_message`). :class:`LiveRecorder` records the same
topics from running nodes (``mrm demo``).
"""

from __future__ import annotations

import struct
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid, Path
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core.geometry import stamp_seconds
from multi_robot_mapper.core.merging.occupancy import global_grid
from multi_robot_mapper.core.snapshots import Snapshot
from multi_robot_mapper.io.messages import (
    pose_from_msg,
    pose_msg,
    seconds_from_stamp,
    stamp_from_seconds,
)
from multi_robot_mapper.io.output_bag import TF_TYPE, FrameTransform, OutputBag, tf_message, thinned
from multi_robot_mapper.ros import diagnostics
from multi_robot_mapper.ros.map_merger import LATCHED_QOS, POSE_QOS
from multi_robot_mapper.ros.markers import (
    MarkerCache,
    MarkerKey,
    frame_matrix,
    global_map_markers,
    occupancy_grid_msg,
)
from multi_robot_mapper.ros.merger_config import MapMergerConfig

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


def cdr_header_stamp(data: bytes, array: bool = False) -> float | None:
    """The header stamp (s) of a serialised message that starts with a ``std_msgs/Header``
    (``array``: a ``MarkerArray``, whose first marker's header is read; None when empty): CDR
    is a 4-byte encapsulation (its second byte says little or big endian), then, for an
    array, its uint32 length, then the stamp's int32 sec and uint32 nanosec."""
    order = "<" if data[1] & 1 else ">"
    start = 4
    if array:
        if struct.unpack_from(order + "I", data, start)[0] == 0:
            return None
        start += 4
    sec, nanosec = struct.unpack_from(order + "iI", data, start)
    return stamp_seconds(sec, nanosec)


class LiveRecorder(Node):
    """Records what a running ``map_merger`` of ``robots`` publishes into ``bag`` as it arrives
    (``mrm demo``), with the topics of :class:`SnapshotRecorder`: ``/global_map``,
    ``/global_grid`` and ``/diagnostics`` as published; ``/tf`` from ``/robot_frames/<robot>``
    (``map`` -> ``<robot>/map``) and ``/<robot>/pose`` (its frame -> ``<robot>/laser``);
    ``/trajectories/<robot>`` the robot's ``/robot_poses/<robot>`` so far, written with each
    global map. Each message is logged at its header stamp (the inputs' time)."""

    def __init__(
        self, robots: Sequence[str], bag: OutputBag, map_frame: str = "map", **kwargs: Any
    ):
        super().__init__("output_recorder", **kwargs)
        self.bag = bag
        self.map_frame = map_frame
        self._lock = threading.Lock()
        self._paths: dict[str, list[PoseStamped]] = {r: [] for r in robots}
        # Taken as they arrive, serialised (raw): nothing decoded or encoded again.
        for (topic, _), kind, qos in (
            (GLOBAL_MAP, MarkerArray, LATCHED_QOS),
            (GLOBAL_GRID, OccupancyGrid, LATCHED_QOS),
            (DIAGNOSTICS, DiagnosticArray, QoSProfile(depth=50)),
        ):
            self.create_subscription(
                kind, topic, lambda data, t=topic: self._on_raw(t, data), qos, raw=True
            )
        for robot in robots:
            self.create_subscription(
                PoseStamped,
                f"/robot_frames/{robot}",
                lambda msg, r=robot: self._on_frame(r, msg),
                LATCHED_QOS,
            )
            self.create_subscription(
                PoseStamped, f"/{robot}/pose", lambda msg, r=robot: self._on_pose(r, msg), POSE_QOS
            )
            self.create_subscription(
                PoseStamped,
                f"/robot_poses/{robot}",
                lambda msg, r=robot: self._on_placed(r, msg),
                POSE_QOS,
            )

    def _write(self, topic: str, msgtype: str, stamp: float, data: bytes, latched: bool) -> None:
        with self._lock:
            self.bag.write(topic, msgtype, stamp, data, latched)

    def _on_raw(self, topic: str, data: bytes) -> None:
        """A serialised /global_map, /global_grid or /diagnostics, logged at its header stamp
        (the first marker's for a MarkerArray; an empty array carries none and is skipped)."""
        kinds = {
            GLOBAL_MAP[0]: GLOBAL_MAP,
            GLOBAL_GRID[0]: GLOBAL_GRID,
            DIAGNOSTICS[0]: DIAGNOSTICS,
        }
        stamp = cdr_header_stamp(data, array=topic == GLOBAL_MAP[0])
        if stamp is None:
            return
        self._write(*kinds[topic], stamp, data, topic != DIAGNOSTICS[0])
        if topic != GLOBAL_MAP[0]:
            return
        with self._lock:
            paths = {r: list(p) for r, p in self._paths.items() if p}
        for robot, poses in paths.items():
            path = Path(header=Header(frame_id=self.map_frame, stamp=stamp_from_seconds(stamp)))
            path.poses = [poses[i] for i in thinned(len(poses), MAX_PATH_POSES)]
            self._write(trajectory_topic(robot), PATH_TYPE, stamp, serialize_message(path), True)

    def _on_frame(self, robot: str, msg: PoseStamped) -> None:
        self._transform(msg, robot_map_frame(robot))

    def _on_pose(self, robot: str, msg: PoseStamped) -> None:
        self._transform(msg, laser_frame(robot))

    def _on_placed(self, robot: str, msg: PoseStamped) -> None:
        with self._lock:
            self._paths[robot].append(msg)

    def _transform(self, msg: PoseStamped, child: str) -> None:
        stamp = seconds_from_stamp(msg.header.stamp)
        pose = pose_from_msg(msg.pose)
        placed = (float(pose[0]), float(pose[1]), float(pose[2]))
        data = tf_message([FrameTransform(msg.header.frame_id, child, placed, stamp)])
        self._write(TF, TF_TYPE, stamp, data, False)
