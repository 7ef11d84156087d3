"""``map_merger``: the robots' partial maps in; one global map and every robot frame in it out.

Robots come from the ``robots`` parameter (namespaces) or, when it is empty, from the topic
list: every ``<ns>/partial_map`` that appears is a robot named ``<ns>`` (no leading slash).

Topics (the merger's own are relative to its namespace):
  sub ``/<ns>/partial_map``   visualization_msgs/MarkerArray, reliable + transient local,
                              depth 1 (what robot_mapper offers: a late merger gets the map)
  sub ``/<ns>/partial_map_updates``  MarkerArray, reliable: what changed, applied in order
                              (io/map_updates.py); a gap keeps the map held and asks, on
  pub ``/<ns>/partial_map_request``   std_msgs/Empty, the robot for a snapshot
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
  pub ``robot_frames/<ns>/probability``  std_msgs/Float64: the probability that the robot's
                              placement is right (from its paths of joins to the reference,
                              each the product of its joins' probabilities, the join model's:
                              docs/evidence_model.md), with every placement; 0 once a robot
                              placed before is placed no more (its last ``robot_frames`` pose
                              is withdrawn); reliable, transient local
  pub ``robot_poses/<ns>``    geometry_msgs/PoseStamped: the robot's newest pose moved into
                              ``map_frame`` (T_map_laser), one per pose it sends while merged,
                              stamped with that pose's stamp
  pub ``global_grid``         nav_msgs/OccupancyGrid in ``map_frame``: occupied cells from the
                              global map's segments, free cells from what each merged robot saw
                              from its keyframes (``grid.*``); reliable, transient local
  pub ``/diagnostics``        diagnostic_msgs/DiagnosticArray every ``diagnostics_period``: per
                              robot OK (merged) / WARN (unmerged) / STALE (silent for
                              ``stale_timeout``; its map stays), merge score, pose rate
  srv ``save_map``, ``load_map``  std_srvs/Trigger: write / read ``map_file`` (every robot's
                              partial map and placement, and the global map; io/saved_map.py);
                              ``save_on_shutdown``, ``load_on_start``
  TF ``map_frame`` -> ``<ns>/map`` for merged robots, when ``tf2_ros`` can be imported
                              (static broadcaster, stamped from the input)

A robot whose map starts again (another keyframe 0: its node restarted) keeps its earlier map
as ``<ns>_session<k>`` (ros/merger_state.py); the new session is merged again.

Merging runs on a timer in its own callback group, so a long merge never blocks the
subscriptions (spin with a MultiThreadedExecutor, as :func:`main` does), and by default in a
worker process (``merge_worker``): a merge is seconds of numpy work that would otherwise take
Python's interpreter lock from every other thread of the process (the subscriptions, and any
node spun in the same process). It re-merges only when some partial map changed and passes
the previous result on (pair results reused, the tree and the reference kept). Parameters:
the fields of :class:`MapMergerConfig` (``config/map_merger.yaml``).
"""

from __future__ import annotations

import sys
import threading
import time
import traceback

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.timer import Timer
from std_msgs.msg import Empty, Float64
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.core.merging.occupancy import (
    OccupancyGrid,
    merge_keeping_state,
    merge_with_grid,
)
from multi_robot_mapper.io.inputs import InputError, MapLimits, pose_from_checked_msg
from multi_robot_mapper.io.map_updates import SNAPSHOT, UPDATE
from multi_robot_mapper.io.messages import piece_of_frame, pose_stamped
from multi_robot_mapper.ros import diagnostics
from multi_robot_mapper.ros.boundary import CallbackGuard, Rejections
from multi_robot_mapper.ros.entry import run_node
from multi_robot_mapper.ros.markers import (
    MarkerCache,
    MarkerKey,
    frame_transform,
    global_map_markers,
    newest,
    occupancy_grid_msg,
    piece_transforms,
    placed_poses,
    stamp_key,
)
from multi_robot_mapper.ros.merger_config import MapMergerConfig
from multi_robot_mapper.ros.merger_state import (
    MergeInputs,
    RobotState,
    after_new_session,
    merge_inputs,
    merge_pending,
    older_than_loaded,
    received_map,
    robot_statuses,
    store_partial_map,
)
from multi_robot_mapper.ros.parameters import declare_config, on_config_change
from multi_robot_mapper.ros.saved_map_services import SavedMapServices
from multi_robot_mapper.ros.throttle import ThrottledWarnings
from multi_robot_mapper.ros.worker_process import WorkerClosedError, WorkerProcess

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
UPDATES_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
REQUEST_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
# A robot that missed updates is asked for a snapshot at most this often: its answer comes at
# its next partial_map_period (1 s by default), and updates refused meanwhile ask again.
REQUEST_INTERVAL_S = 2.0
PARTIAL_MAP_TYPE = "visualization_msgs/msg/MarkerArray"


class MapMerger(SavedMapServices, Node):
    """Merges the partial maps of robots whose relative poses are unknown.

    ``config`` (default: the dataclass defaults) gives the fixed constants and the defaults of
    the ROS parameters: code that builds the node in Python (tests, experiments) changes a fixed
    constant there."""

    def __init__(
        self, node_name: str = "map_merger", config: MapMergerConfig | None = None, **kwargs: object
    ) -> None:
        super().__init__(node_name, **kwargs)  # type: ignore[arg-type]
        self.config = declare_config(self, MapMergerConfig, config)
        self.config.require_implemented()
        self.notes = ThrottledWarnings(self.get_logger().info, self.config.warning_period)
        self.warnings = ThrottledWarnings(self.get_logger().warning, self.config.warning_period)
        # A robot's bad input is rejected (counted per robot and reason, a throttled warning
        # naming robot and field, its last good map kept); no error escapes a callback.
        self.rejections = Rejections(self.warnings)
        self.guard = CallbackGuard(self.warnings, running=self.context.ok)
        self._lock = threading.Lock()
        self.robots: dict[str, RobotState] = {}
        self.result: MergeResult | None = None
        self.grid: OccupancyGrid | None = None
        self.merges = 0  # merge() runs
        self.merge_errors = 0
        self.last_merge_s: float | None = None  # wall time of the last merge (worker included)
        self.global_maps_published = 0
        self._merged_versions: dict[str, int] = {}  # partial map versions of the last merge
        self._new_sessions: list[tuple[str, str]] = []  # (robot, its earlier map's name)
        # Each robot's map as the last successful merge used it: what a robot whose new map
        # makes the merge fail falls back to.
        self._merged_inputs: dict[str, tuple[FloatArray, FloatArray, list[Keyframe]]] = {}
        self._culprits: set[str] = set()  # robots set back by the last failed merge
        self._worker = WorkerProcess("merge worker")  # started on the first merge
        self._shown: tuple[object, ...] | None = None  # what the last global_map showed
        self._marker_ids: set[MarkerKey] = set()  # its markers (deleted once gone)
        self._marker_cache: MarkerCache = {}  # each keyframe's marker, rebuilt when it changes
        self._input_groups = MutuallyExclusiveCallbackGroup()
        self._merge_group = MutuallyExclusiveCallbackGroup()
        self._map_pub = self.create_publisher(MarkerArray, "global_map", LATCHED_QOS)
        self._grid_pub = self.create_publisher(OccupancyGridMsg, "global_grid", LATCHED_QOS)
        self._diagnostics_pub = self.create_publisher(
            diagnostics.DiagnosticArray, diagnostics.TOPIC, 10
        )
        self._frame_pubs: dict[str, Publisher] = {}
        self._probability_pubs: dict[str, Publisher] = {}
        self._tf = StaticTransformBroadcaster(self) if StaticTransformBroadcaster else None
        self._transforms: dict[str, TransformStamped] = {}
        self._piece_transforms: dict[str, TransformStamped] = {}
        self._services = [
            self.create_service(
                Trigger, "save_map", self._on_save, callback_group=self._input_groups
            ),
            self.create_service(
                Trigger, "load_map", self._on_load, callback_group=self._input_groups
            ),
        ]
        self._discovery_timer = self._timer("discovery")
        self._merge_timer = self._timer("merge")
        self._diagnostics_timer = self._timer("diagnostics")
        on_config_change(self, lambda: self.config, self._reconfigure)
        if self.config.load_on_start:
            self._load_at_start()
        self.discover()

    # --- Robots and their inputs ------------------------------------------------------------

    def discover(self) -> list[str]:
        """Subscribe to every robot not yet subscribed (from ``robots``, or from the topic
        list when it is empty); returns the robots added."""
        wanted = self.config.robot_names()
        if not wanted:
            suffix = "/partial_map"
            wanted = sorted(
                name[: -len(suffix)].strip("/")
                for name, types in self.get_topic_names_and_types()
                if name.endswith(suffix) and PARTIAL_MAP_TYPE in types
            )
        with self._lock:
            added = [
                name
                for name in wanted
                if name and (name not in self.robots or not self.robots[name].subscriptions)
            ]
        for name in added:
            self._add_robot(name)
        return added

    def _add_robot(self, name: str) -> None:
        with self._lock:
            state = self.robots.setdefault(name, RobotState(name))
        state.pose_publisher = self.create_publisher(PoseStamped, f"robot_poses/{name}", POSE_QOS)
        state.request_publisher = self.create_publisher(
            Empty, f"/{name}/partial_map_request", REQUEST_QOS
        )
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
            self.create_subscription(
                MarkerArray,
                f"/{name}/partial_map_updates",
                self.guard(
                    f"{name}/partial_map_updates",
                    lambda msg, n=name: self._on_partial_map(n, msg, UPDATE),
                ),
                UPDATES_QOS,
                callback_group=self._input_groups,
            ),
        ]
        self.get_logger().info(f"merging robot '{name}' (/{name}/partial_map)")

    def _clock_ns(self) -> int:
        return int(self.get_clock().now().nanoseconds)

    def _limits(self) -> MapLimits:
        config = self.config
        return MapLimits(
            config.max_keyframes_per_map, config.max_segments_per_map, config.max_map_extent
        )

    def _on_partial_map(self, name: str, msg: MarkerArray, kind: str = SNAPSHOT) -> None:
        """A snapshot (``partial_map``) or an update (``partial_map_updates``): applied to the
        robot's stream, the whole map it gives checked, then stored; anything refused leaves
        the map held as it was."""
        what = "partial map" if kind == SNAPSHOT else "partial map update"
        with self._lock:
            state = self.robots[name]
            try:
                applied, contents = received_map(state, msg, kind, self._limits())
            except InputError as exc:  # the robot's last good map stays
                self.rejections.reject(name, exc.kind, exc.field, exc.message, what)
                if exc.kind in ("update_gap", "update_mismatch"):
                    self._ask_snapshot(state)
                return
            state.stream.commit(applied)
            if older_than_loaded(state, contents):
                self._ask_snapshot(state)  # the loaded map stays until a newer one comes
                return
            kept = store_partial_map(
                self.robots, name, contents, self._clock_ns(), self.config.keep_sessions
            )
            if kept is not None:
                self.result = after_new_session(self.result, name, kept)
                self._new_sessions.append((name, kept))
        if kept is not None:
            self.get_logger().info(
                f"robot '{name}' started a new map (another first keyframe): its earlier map "
                f"is kept as '{kept}' and the new one will be merged again"
            )

    def _ask_snapshot(self, state: RobotState) -> None:
        """Ask the robot for a snapshot (at most every REQUEST_INTERVAL_S)."""
        now, last = self._clock_ns(), state.requested_ns
        if state.request_publisher is not None and (
            last is None or not 0 <= now - last < REQUEST_INTERVAL_S * 1e9
        ):
            state.requested_ns = now
            state.request_publisher.publish(Empty())

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
            state.pose_piece = piece_of_frame(state.map_frame or None, msg.header.frame_id)
            piece = state.pose_piece
            state.heard_ns = self._clock_ns()
            state.pose_rate.add(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
            publisher = state.pose_publisher
        result = self.result
        if result is None or publisher is None:
            return
        placed = placed_poses(result, {name: (pose, msg.header.stamp)}, {name: piece}).get(name)
        if placed is not None:
            publisher.publish(pose_stamped(placed[0].tolist(), placed[1], self.config.map_frame))

    # --- Merging and output -----------------------------------------------------------------

    def merge_now(self) -> bool:
        """Merge again if some partial map changed, and publish what changed; True when a
        merge ran."""
        config = self.config
        with self._lock:
            inputs = merge_inputs(self.robots)
            sessions = len(self._new_sessions)
        merged = False
        # A merge update matches places within its time budget: while some wait, merge again.
        pending = merge_pending(self.result)
        if inputs.maps and (inputs.versions != self._merged_versions or pending):
            reference = config.merge.reference
            if reference and reference not in inputs.maps:
                self.notes.warn(
                    "no_reference", f"waiting for the reference robot '{reference}' to send a map"
                )
                return False
            began = time.perf_counter()
            try:
                result, grid = self._merge(inputs.keyframes, config)
                self._merged_inputs = {
                    n: (inputs.maps[n], inputs.viewpoints[n], inputs.keyframes[n])
                    for n in inputs.maps
                }
            except WorkerClosedError:
                return False  # the node is being destroyed: no fallback merges, nothing new
            except Exception:
                self.merge_errors += 1
                self.warnings.warn(
                    "merge_error",
                    f"merge failed (the last global map stays):\n{traceback.format_exc()}",
                )
                fallback = self._merge_without_new_maps(inputs, config)
                if fallback is None:
                    return False
                result, grid = fallback
            with self._lock:
                # A robot that started a new session while this merge ran: its pair results
                # in this merge are of its old map.
                for name, kept in self._new_sessions[sessions:]:
                    result = after_new_session(result, name, kept)
                self.result, self.grid = result, grid
            self._merged_versions = inputs.versions
            self.last_merge_s = time.perf_counter() - began
            self.merges += 1
            merged = True
            self.autosave()
        if self.result is not None:
            self._publish_result(self.result, inputs, merged)
        return merged

    def _publish_result(self, result: MergeResult, inputs: MergeInputs, merged: bool) -> None:
        """Publish the global map when what it shows changed, the grid and the robots' frames
        after a merge, and a warning per unmerged robot."""
        config = self.config
        map_stamp = newest([inputs.stamps[r] for r in result.robots if r in inputs.stamps])
        pose_key = tuple(
            sorted((n, tuple(p.tolist()), stamp_key(t)) for n, (p, t) in inputs.poses.items())
        )
        shown = (self.merges, config.map_frame, config.marker_width, pose_key)
        if shown != self._shown:
            self._publish_global_map(result, map_stamp, inputs.poses, inputs.pose_pieces)
            self._shown = shown
        if merged:
            if self.grid is not None:
                self._grid_pub.publish(occupancy_grid_msg(self.grid, map_stamp, config.map_frame))
            self._publish_frames(result, map_stamp, inputs.frames)
        for robot in result.unmerged:
            why = result.unmerged_reasons.get(robot, "its map has no valid link to the reference")
            self.notes.warn(
                f"unmerged:{robot}",
                f"robot '{robot}' is unmerged: {why} (nothing published for it)",
            )

    def _publish_global_map(
        self,
        result: MergeResult,
        map_stamp: Time,
        poses: dict[str, tuple[FloatArray, Time]],
        pieces: dict[str, int],
    ) -> None:
        """One marker per merged keyframe (a keyframe's marker rebuilt only when it changed),
        DELETEs for what the last publication showed and is gone."""
        config = self.config
        array = global_map_markers(
            result,
            map_stamp,
            poses,
            config.map_frame,
            config.marker_width,
            pieces,
            self._marker_ids,
            self._marker_cache,
        )
        self._map_pub.publish(array)
        self._marker_ids = {(m.ns, m.id) for m in array.markers if m.action == Marker.ADD}
        self.global_maps_published += 1

    def up_to_date(self) -> bool:
        """Every partial map received so far is in the last merge (and there was one), and
        that merge left no place unmatched and no pair unjudged (an update works within its
        budget)."""
        with self._lock:
            versions = merge_inputs(self.robots).versions
        result = self.result
        pending = merge_pending(result)
        return bool(versions) and versions == self._merged_versions and not pending

    def _merge_without_new_maps(
        self, inputs: MergeInputs, config: MapMergerConfig
    ) -> tuple[MergeResult, OccupancyGrid | None] | None:
        """After a failed merge, merge again with one robot whose map changed since the last
        good merge set back to its previous map (or left out), the robot that failed before
        first; failing that, with every changed robot set back. One robot's map that the merge
        cannot take must not stop the others: the robots set back are rejected (reason
        ``merge_error``) until they send a new map. The merge that succeeded (None: none did)."""
        versions = inputs.versions
        changed = [n for n in inputs.maps if versions[n] != self._merged_versions.get(n)]
        changed.sort(key=lambda n: n not in self._culprits)
        trials = [[name] for name in changed] if len(changed) > 1 else []
        trials.append(changed)
        for set_back in trials:
            kept = {
                n: (inputs.maps[n], inputs.viewpoints[n], inputs.keyframes[n])
                for n in inputs.maps
                if n not in set_back
            }
            kept.update({n: self._merged_inputs[n] for n in set_back if n in self._merged_inputs})
            if not kept:
                continue
            try:
                merged = self._merge({n: k for n, (_, _, k) in kept.items()}, config)
            except WorkerClosedError:
                return None
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
                    state.segments, state.keyframe_poses, state.all_keyframes = kept.get(
                        name, (np.zeros((0, 4)), np.zeros((0, 3)), [])
                    )
            self._merged_inputs = kept
            return merged
        return None

    def _merge(
        self, keyframes: dict[str, list[Keyframe]], config: MapMergerConfig
    ) -> tuple[MergeResult, OccupancyGrid | None]:
        """:func:`merge_with_grid` with the previous result, in the worker process when
        ``merge_worker`` is on (this thread waits without holding the interpreter lock; the
        merge's state stays there between merges: :func:`merge_keeping_state`)."""
        job = (keyframes, config.merge, config.grid, self.result, config.method)
        if not config.merge_worker:
            return merge_with_grid(*job)
        return self._worker.run_with_state(merge_keeping_state, *job)

    def destroy_node(self) -> None:
        if self.config.save_on_shutdown:
            self.save_on_exit()
        self._worker.shutdown()
        super().destroy_node()

    def _publish_frames(self, result: MergeResult, stamp: Time, frames: dict[str, str]) -> None:
        map_frame = self.config.map_frame
        for robot in result.robots:
            pose = result.placements.get(robot)
            if pose is None:
                self._transforms.pop(robot, None)  # no longer placed: out of TF from now on
                if robot in self._probability_pubs:  # placed before: withdrawn
                    self._probability_pubs[robot].publish(Float64(data=0.0))
                continue
            publisher = self._frame_pubs.get(robot)
            if publisher is None:
                publisher = self.create_publisher(PoseStamped, f"robot_frames/{robot}", LATCHED_QOS)
                self._frame_pubs[robot] = publisher
                self._probability_pubs[robot] = self.create_publisher(
                    Float64, f"robot_frames/{robot}/probability", LATCHED_QOS
                )
            publisher.publish(pose_stamped(pose, stamp, map_frame))
            probability = result.probabilities.get(robot, 1.0 if robot == result.reference else 0.0)
            self._probability_pubs[robot].publish(Float64(data=float(probability)))
            child = frames.get(robot) or f"{robot}/map"
            self._transforms[robot] = frame_transform(pose, stamp, map_frame, child)
        # The other pieces of robots' maps that the merge placed (their own frames).
        self._piece_transforms = piece_transforms(result, frames, stamp, map_frame)
        every = [*self._transforms.values(), *self._piece_transforms.values()]
        if self._tf is not None and every:
            self._tf.sendTransform(every)

    def publish_diagnostics(self) -> None:
        """Every robot's status on /diagnostics, stamped with the newest input."""
        result = self.result
        with self._lock:
            states = list(self.robots.values())
            stamps = [s.map_stamp for s in states if s.map_stamp is not None]
            stamps += [s.pose_stamp for s in states if s.pose_stamp is not None]
            statuses = robot_statuses(states, result, self._clock_ns(), self.config.stale_timeout)
        # Asked after the robots' statuses were taken: a map arriving in between says "no".
        merged = (self.merges, self.merge_errors, self.last_merge_s, len(statuses))
        statuses.insert(0, diagnostics.merge_status(result, *merged, self.up_to_date()))
        if statuses:
            self._diagnostics_pub.publish(diagnostics.diagnostic_array(statuses, newest(stamps)))

    # --- Parameters -------------------------------------------------------------------------

    def _timer(self, which: str) -> Timer:
        """A new timer of ``which`` (discovery, merge or diagnostics) at its configured period."""
        if which == "discovery":
            callback = self.guard("discover", self.discover)
            return self.create_timer(
                self.config.discovery_period, callback, callback_group=self._input_groups
            )
        if which == "merge":
            callback = self.guard("merge", self.merge_now)
            return self.create_timer(
                self.config.merge_period, callback, callback_group=self._merge_group
            )
        return self.create_timer(
            self.config.diagnostics_period,
            self.publish_diagnostics,
            callback_group=self._input_groups,
        )

    def _reconfigure(self, config: MapMergerConfig) -> None:
        """A ``ros2 param set`` change: refused (ConfigError) for a method not implemented."""
        config.require_implemented()
        self._apply_config(config)

    def _apply_config(self, config: MapMergerConfig) -> None:
        old = self.config
        self.config = config
        self.notes.period = self.warnings.period = config.warning_period
        if config.discovery_period != old.discovery_period:
            self.destroy_timer(self._discovery_timer)
            self._discovery_timer = self._timer("discovery")
        if config.merge_period != old.merge_period:
            self.destroy_timer(self._merge_timer)
            self._merge_timer = self._timer("merge")
        if config.diagnostics_period != old.diagnostics_period:
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = self._timer("diagnostics")
        if (config.merge, config.grid) != (old.merge, old.grid):
            self._merged_versions = {}  # merge again with the new settings


def main(args: list[str] | None = None) -> int:
    """Console entry point (``ros2 run multi_robot_mapper map_merger``)."""
    # Merges run on their own callback group: a second thread keeps subscriptions served.
    return run_node("map_merger", MapMerger, args, lambda: MultiThreadedExecutor(num_threads=2))


if __name__ == "__main__":
    sys.exit(main())
