"""``map_merger``: the robots' partial maps in; one global map and every robot frame in it out.

Robots come from the ``robots`` parameter (namespaces) or, when it is empty, from the topic
list: every ``<ns>/partial_map`` that appears is a robot named ``<ns>`` (no leading slash).

Topics (the merger's own are relative to its namespace):
  sub ``/<ns>/partial_map``   visualization_msgs/MarkerArray, reliable + transient local,
                              depth 1 (what robot_mapper offers: a late merger gets the map)
  sub ``/<ns>/pose``          geometry_msgs/PoseStamped, the robot's current pose in its map
  pub ``global_map``          visualization_msgs/MarkerArray in ``map_frame``: a DELETEALL
                              marker, then the fused segments as one LINE_LIST per robot
                              (coloured per robot), each merged robot's current pose as an
                              ARROW and its name as TEXT_VIEW_FACING; stamped with the newest
                              input (partial map or pose) it shows, never now(); reliable,
                              transient local, depth 1
  pub ``robot_frames/<ns>``   geometry_msgs/PoseStamped: T_map_robotmap, the robot's map frame
                              in ``map_frame``, for merged robots only (an unmerged robot gets
                              nothing, and a throttled log line); reliable, transient local
  TF ``map_frame`` -> ``<ns>/map`` for merged robots, when ``tf2_ros`` can be imported
                              (static broadcaster, stamped from the input)

Merging runs on a timer in its own callback group, so a long merge never blocks the
subscriptions (spin with a MultiThreadedExecutor, as :func:`main` does), and by default in a
worker process (``merge_worker``): a merge is seconds of numpy work that would otherwise take
Python's interpreter lock from every other thread of the process (the subscriptions, and any
node spun in the same process). It re-merges only when some partial map changed and passes
the previous result on (pair results reused, the tree and the reference kept). Parameters:
the fields of :class:`MapMergerConfig` (``config/map_merger.yaml``).
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import sys
import threading
import traceback
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.config import ConfigError, config_from_flat, field_specs
from multi_robot_mapper.core.merger_config import MapMergerConfig
from multi_robot_mapper.core.merging import MergeResult, merge
from multi_robot_mapper.io.inputs import (
    InputError,
    MapLimits,
    partial_map_from_msg,
    pose_from_checked_msg,
)
from multi_robot_mapper.io.messages import (
    pose_msg,
    pose_stamped,
    segments_marker,
)
from multi_robot_mapper.ros.boundary import CallbackGuard, Rejections
from multi_robot_mapper.ros.entry import run_node
from multi_robot_mapper.ros.parameters import declare_config
from multi_robot_mapper.ros.throttle import ThrottledWarnings

try:  # PyPI has no tf2_ros; with an apt-installed ROS 2 the frames go to TF as well.
    from tf2_ros import StaticTransformBroadcaster
except ImportError:  # pragma: no cover - depends on the installation
    StaticTransformBroadcaster = None

FloatArray = np.typing.NDArray[np.float64]

LATCHED_QOS = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
POSE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
PARTIAL_MAP_TYPE = "visualization_msgs/msg/MarkerArray"

# Tableau-like colours, one per robot (by the robot's place in the sorted list of robots).
PALETTE = (
    (0.12, 0.47, 0.71),
    (1.00, 0.50, 0.05),
    (0.17, 0.63, 0.17),
    (0.84, 0.15, 0.16),
    (0.58, 0.40, 0.74),
    (0.55, 0.34, 0.29),
    (0.89, 0.47, 0.76),
    (0.50, 0.50, 0.50),
    (0.74, 0.74, 0.13),
    (0.09, 0.75, 0.81),
)


def robot_color(index: int) -> tuple[float, float, float, float]:
    """The colour of the ``index``-th robot (RGBA)."""
    r, g, b = PALETTE[index % len(PALETTE)]
    return (r, g, b, 1.0)


def _key(stamp: Time) -> tuple[int, int]:
    return (int(stamp.sec), int(stamp.nanosec))


def newest(stamps: list[Time]) -> Time:
    """The latest of ``stamps`` (a zero stamp when there are none)."""
    return max(stamps, key=_key) if stamps else Time()


@dataclasses.dataclass
class RobotState:
    """What the merger knows of one robot (guarded by the node's lock)."""

    name: str
    segments: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 4)))
    keyframe_poses: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    map_stamp: Time | None = None  # header stamp of the last partial map
    map_frame: str = ""  # the robot's own map frame (the partial map's frame_id)
    version: int = 0  # partial maps received
    pose: FloatArray | None = None  # T_robotmap_laser of the newest pose message
    pose_stamp: Time | None = None
    subscriptions: list[Subscription] = dataclasses.field(default_factory=list)


class MapMerger(Node):
    """Merges the partial maps of robots whose relative poses are unknown."""

    def __init__(self, node_name: str = "map_merger", **kwargs: object) -> None:
        super().__init__(node_name, **kwargs)  # type: ignore[arg-type]
        self.config = declare_config(self, MapMergerConfig)
        self.config.require_implemented()
        self.notes = ThrottledWarnings(self.get_logger().info, self.config.warning_period)
        self.warnings = ThrottledWarnings(self.get_logger().warning, self.config.warning_period)
        # A robot's bad input is rejected (counted per robot and reason, a throttled warning
        # naming robot and field, its last good map kept); no error escapes a callback.
        self.rejections = Rejections(self.warnings)
        self.guard = CallbackGuard(self.warnings)
        self._lock = threading.Lock()
        self.robots: dict[str, RobotState] = {}
        self.result: MergeResult | None = None
        self.merges = 0  # merge() runs
        self.merge_errors = 0
        self.global_maps_published = 0
        self._merged_versions: dict[str, int] = {}  # partial map versions of the last merge
        # Each robot's map as the last successful merge used it: what a robot whose new map
        # makes the merge fail falls back to.
        self._merged_inputs: dict[str, tuple[FloatArray, FloatArray]] = {}
        self._culprits: set[str] = set()  # robots set back by the last failed merge
        self._worker: ProcessPoolExecutor | None = None  # started on the first merge
        self._shown: tuple[object, ...] | None = None  # what the last global_map showed
        self._input_groups = MutuallyExclusiveCallbackGroup()
        self._merge_group = MutuallyExclusiveCallbackGroup()
        self._map_pub = self.create_publisher(MarkerArray, "global_map", LATCHED_QOS)
        self._frame_pubs: dict[str, Publisher] = {}
        self._tf = StaticTransformBroadcaster(self) if StaticTransformBroadcaster else None
        self._transforms: dict[str, TransformStamped] = {}
        self._discovery_timer = self.create_timer(
            self.config.discovery_period,
            self.guard("discover", self.discover),
            callback_group=self._input_groups,
        )
        self._merge_timer = self.create_timer(
            self.config.merge_period,
            self.guard("merge", self.merge_now),
            callback_group=self._merge_group,
        )
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.discover()

    # --- Robots and their inputs ------------------------------------------------------------

    def discover(self) -> list[str]:
        """Subscribe to every robot not yet known (from ``robots``, or from the topic list
        when it is empty); returns the robots added."""
        wanted = self.config.robot_names()
        if not wanted:
            suffix = "/partial_map"
            wanted = sorted(
                name[: -len(suffix)].strip("/")
                for name, types in self.get_topic_names_and_types()
                if name.endswith(suffix) and PARTIAL_MAP_TYPE in types
            )
        added = [name for name in wanted if name and name not in self.robots]
        for name in added:
            self._add_robot(name)
        return added

    def _add_robot(self, name: str) -> None:
        state = RobotState(name)
        with self._lock:
            self.robots[name] = state
        state.subscriptions = [
            self.create_subscription(
                MarkerArray,
                f"/{name}/partial_map",
                self.guard(f"{name}/partial_map", lambda msg, n=name: self._on_partial_map(n, msg)),
                LATCHED_QOS,
                callback_group=self._input_groups,
            ),
            self.create_subscription(
                PoseStamped,
                f"/{name}/pose",
                self.guard(f"{name}/pose", lambda msg, n=name: self._on_pose(n, msg)),
                POSE_QOS,
                callback_group=self._input_groups,
            ),
        ]
        self.get_logger().info(f"merging robot '{name}' (/{name}/partial_map)")

    def _limits(self) -> MapLimits:
        config = self.config
        return MapLimits(
            config.max_keyframes_per_map, config.max_segments_per_map, config.max_map_extent
        )

    def _on_partial_map(self, name: str, msg: MarkerArray) -> None:
        try:
            received = partial_map_from_msg(msg, self._limits())
        except InputError as exc:  # the robot's last good map stays
            self.rejections.reject(name, exc.kind, exc.field, exc.message, "partial map")
            return
        with self._lock:
            state = self.robots[name]
            state.segments = received.segments
            state.keyframe_poses = received.keyframe_poses
            state.map_stamp = received.stamp
            state.map_frame = received.frame_id
            state.version += 1

    def _on_pose(self, name: str, msg: PoseStamped) -> None:
        try:
            pose = pose_from_checked_msg(msg.pose, self.config.max_map_extent)
        except InputError as exc:
            self.rejections.reject(name, exc.kind, exc.field, exc.message, "pose")
            return
        with self._lock:
            state = self.robots[name]
            state.pose = pose
            state.pose_stamp = msg.header.stamp

    # --- Merging and output -----------------------------------------------------------------

    def merge_now(self) -> bool:
        """Merge again if some partial map changed, and publish what changed; True when a
        merge ran."""
        config = self.config
        with self._lock:
            maps = {n: s.segments for n, s in self.robots.items() if len(s.segments)}
            versions = {n: s.version for n, s in self.robots.items() if len(s.segments)}
            viewpoints = {n: s.keyframe_poses for n, s in self.robots.items() if len(s.segments)}
            stamps = {n: s.map_stamp for n, s in self.robots.items() if s.map_stamp is not None}
            frames = {n: s.map_frame for n, s in self.robots.items()}
            poses = {
                n: (s.pose, s.pose_stamp)
                for n, s in self.robots.items()
                if s.pose is not None and s.pose_stamp is not None
            }
        merged = False
        if maps and versions != self._merged_versions:
            reference = config.merge.reference
            if reference and reference not in maps:
                self.notes.warn(
                    "no_reference", f"waiting for the reference robot '{reference}' to send a map"
                )
                return False
            try:
                self.result = self._merge(maps, viewpoints, config)
            except Exception:
                self.merge_errors += 1
                self.warnings.warn(
                    "merge_error",
                    f"merge failed (the last global map stays):\n{traceback.format_exc()}",
                )
                if not self._merge_without_new_maps(maps, viewpoints, versions, config):
                    return False
            else:
                self._merged_inputs = {n: (maps[n], viewpoints[n]) for n in maps}
            self._merged_versions = versions
            self.merges += 1
            merged = True
        result = self.result
        if result is None:
            return merged
        map_stamp = newest([stamps[r] for r in result.robots if r in stamps])
        pose_key = tuple(
            sorted((n, tuple(p.tolist()), _key(t)) for n, (p, t) in poses.items() if p is not None)
        )
        shown = (self.merges, config.map_frame, config.marker_width, pose_key)
        if shown != self._shown:
            self._publish_global_map(result, map_stamp, poses)
            self._shown = shown
        if merged:
            self._publish_frames(result, map_stamp, frames)
        for robot in result.unmerged:
            self.notes.warn(
                f"unmerged:{robot}",
                f"robot '{robot}' is unmerged: its map has no valid link to the reference "
                f"'{result.reference}' yet (nothing published for it)",
            )
        return merged

    def _merge_without_new_maps(
        self,
        maps: dict[str, FloatArray],
        viewpoints: dict[str, FloatArray],
        versions: dict[str, int],
        config: MapMergerConfig,
    ) -> bool:
        """After a failed merge, merge again with one robot whose map changed since the last
        good merge set back to its previous map (or left out), the robot that failed before
        first; failing that, with every changed robot set back. One robot's map that the merge
        cannot take must not stop the others: the robots set back are rejected (reason
        ``merge_error``) until they send a new map. True when a merge succeeded."""
        changed = [n for n in maps if versions[n] != self._merged_versions.get(n)]
        changed.sort(key=lambda n: n not in self._culprits)
        trials = [[name] for name in changed] if len(changed) > 1 else []
        trials.append(changed)
        for set_back in trials:
            kept = {n: (maps[n], viewpoints[n]) for n in maps if n not in set_back}
            kept.update({n: self._merged_inputs[n] for n in set_back if n in self._merged_inputs})
            if not kept:
                continue
            try:
                self.result = self._merge(
                    {n: m for n, (m, _) in kept.items()},
                    {n: v for n, (_, v) in kept.items()},
                    config,
                )
            except Exception:
                continue
            self._culprits = set(set_back)
            for name in set_back:
                self.rejections.reject(
                    name,
                    "merge_error",
                    "partial_map",
                    "the merge failed with this robot's new map; its last good map is merged "
                    "instead until it sends another",
                    "partial map",
                )
                with self._lock:  # the map the merge took stays this robot's map
                    state = self.robots[name]
                    state.segments, state.keyframe_poses = kept.get(
                        name, (np.zeros((0, 4)), np.zeros((0, 3)))
                    )
            self._merged_inputs = kept
            return True
        return False

    def _merge(
        self,
        maps: dict[str, FloatArray],
        viewpoints: dict[str, FloatArray],
        config: MapMergerConfig,
    ) -> MergeResult:
        """:func:`merge` with the previous result, in the worker process when
        ``merge_worker`` is on (this thread waits without holding the interpreter lock)."""
        previous = self.result
        if not config.merge_worker:
            return merge(maps, config.merge, previous=previous, viewpoints=viewpoints)
        if self._worker is None:
            # spawn, not fork: forking a process that runs DDS threads is unsafe.
            context = multiprocessing.get_context("spawn")
            self._worker = ProcessPoolExecutor(max_workers=1, mp_context=context)
        try:
            job = self._worker.submit(merge, maps, config.merge, previous, None, viewpoints)
            return job.result()
        except BrokenProcessPool:
            # The worker died (killed, out of memory): a new one next time.
            self._worker.shutdown(wait=False, cancel_futures=True)
            self._worker = None
            raise

    def destroy_node(self) -> None:
        if self._worker is not None:
            self._worker.shutdown(wait=False, cancel_futures=True)
            self._worker = None
        super().destroy_node()

    def _publish_global_map(
        self,
        result: MergeResult,
        map_stamp: Time,
        poses: dict[str, tuple[FloatArray | None, Time | None]],
    ) -> None:
        frame = self.config.map_frame
        width = self.config.marker_width
        shown_poses: dict[str, FloatArray] = {}
        pose_stamps: list[Time] = []
        for robot, (pose, stamp) in poses.items():
            T_map_robot = result.matrix(robot)
            if T_map_robot is None or pose is None or stamp is None:
                continue
            T_robot_laser = se2.matrix_from_pose(*pose)
            shown_poses[robot] = np.array(se2.pose_from_matrix(T_map_robot @ T_robot_laser))
            pose_stamps.append(stamp)
        header = Header(frame_id=frame, stamp=newest([map_stamp, *pose_stamps]))
        clear = Marker(header=header, action=Marker.DELETEALL)
        markers = [clear]
        for index in range(len(result.robots)):
            own = result.segments[result.segment_robot == index]
            if len(own):
                markers.append(
                    segments_marker(own, header, "global_map", width, robot_color(index), index)
                )
        for index, robot in enumerate(result.robots):
            T_map_robot = result.matrix(robot)
            if T_map_robot is None:
                continue
            where = shown_poses.get(robot, np.array(se2.pose_from_matrix(T_map_robot)))
            color = robot_color(index)
            if robot in shown_poses:
                arrow = Marker(header=header, ns="robot_poses", id=index)
                arrow.type = Marker.ARROW
                arrow.action = Marker.ADD
                arrow.pose = pose_msg(where.tolist())
                arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.6, 0.12, 0.12
                arrow.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
                markers.append(arrow)
            text = Marker(header=header, ns="robot_names", id=index)
            text.type = Marker.TEXT_VIEW_FACING
            text.action = Marker.ADD
            text.pose = pose_msg(where.tolist())
            text.pose.position.z = 0.6
            text.scale.z = 0.4
            text.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
            text.text = robot
            markers.append(text)
        self._map_pub.publish(MarkerArray(markers=markers))
        self.global_maps_published += 1

    def _publish_frames(self, result: MergeResult, stamp: Time, frames: dict[str, str]) -> None:
        map_frame = self.config.map_frame
        for robot in result.robots:
            pose = result.placements.get(robot)
            if pose is None:
                self._transforms.pop(robot, None)  # no longer placed: out of TF from now on
                continue
            publisher = self._frame_pubs.get(robot)
            if publisher is None:
                publisher = self.create_publisher(PoseStamped, f"robot_frames/{robot}", LATCHED_QOS)
                self._frame_pubs[robot] = publisher
            publisher.publish(pose_stamped(pose, stamp, map_frame))
            if self._tf is not None:
                transform = TransformStamped()
                transform.header = Header(frame_id=map_frame, stamp=stamp)
                transform.child_frame_id = frames.get(robot) or f"{robot}/map"
                placed = pose_msg(pose)
                transform.transform.translation.x = placed.position.x
                transform.transform.translation.y = placed.position.y
                transform.transform.rotation = placed.orientation
                self._transforms[robot] = transform
        if self._tf is not None and self._transforms:
            self._tf.sendTransform(list(self._transforms.values()))

    # --- Parameters -------------------------------------------------------------------------

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        values: dict[str, Any] = {
            spec.name: self.get_parameter(spec.name).value for spec in field_specs(MapMergerConfig)
        }
        values.update({p.name: p.value for p in params})
        try:
            config = config_from_flat(MapMergerConfig, values)
            config.require_implemented()
            self._apply_config(config)
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        except Exception as exc:  # never into the executor
            return SetParametersResult(successful=False, reason=f"not applied: {exc}")
        return SetParametersResult(successful=True)

    def _apply_config(self, config: MapMergerConfig) -> None:
        old = self.config
        self.config = config
        self.notes.period = self.warnings.period = config.warning_period
        if config.discovery_period != old.discovery_period:
            self.destroy_timer(self._discovery_timer)
            self._discovery_timer = self.create_timer(
                config.discovery_period,
                self.guard("discover", self.discover),
                callback_group=self._input_groups,
            )
        if config.merge_period != old.merge_period:
            self.destroy_timer(self._merge_timer)
            self._merge_timer = self.create_timer(
                config.merge_period,
                self.guard("merge", self.merge_now),
                callback_group=self._merge_group,
            )
        if config.merge != old.merge:
            self._merged_versions = {}  # merge again with the new settings


def main(args: list[str] | None = None) -> int:
    """Console entry point (``ros2 run multi_robot_mapper map_merger``)."""
    # Merges run on their own callback group: a second thread keeps subscriptions served.
    return run_node("map_merger", MapMerger, args, lambda: MultiThreadedExecutor(num_threads=2))


if __name__ == "__main__":
    sys.exit(main())
