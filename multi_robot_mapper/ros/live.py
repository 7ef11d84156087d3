"""Playing recorded scans live into running nodes and watching what comes out (no launch files).

:class:`ScanPlayer` publishes LaserScans on ``/<robot>/scan`` at the pace of their stamps (or
a chosen multiple of it) from its own thread, as a laser driver or ``ros2 bag play`` would,
and ``/clock`` when asked. :class:`Observer` is a node that subscribes to everything the
system publishes and keeps it for pictures, tests and benches. ``mrm demo``, the node tests
and ``bench/live_load.py`` use both.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Iterable, Mapping, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Float64
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.io.bags import TimedScan
from multi_robot_mapper.io.inputs import InputError
from multi_robot_mapper.io.map_updates import SNAPSHOT, UPDATE, MapStream
from multi_robot_mapper.io.messages import (
    partial_map_contents,
    pose_from_msg,
    scan_to_msg,
    seconds_from_stamp,
    segments_from_marker,
    stamp_from_seconds,
)
from multi_robot_mapper.ros.map_merger import LATCHED_QOS, POSE_QOS
from multi_robot_mapper.ros.markers import GLOBAL_MAP_NAMESPACE

FloatArray = np.typing.NDArray[np.float64]
Timeline = Iterable[tuple[float, str, LaserScan]]  # (stamp s, robot, message), by stamp


def timeline(scans: Mapping[str, Sequence[TimedScan]], scan_time: float = 0.0) -> Timeline:
    """Every robot's scans as messages, merged in stamp order (built as they are played)."""
    items = sorted(
        (
            (item.stamp, robot, index)
            for robot, run in scans.items()
            for index, item in enumerate(run)
        ),
    )
    for stamp, robot, index in items:
        item = scans[robot][index]
        yield (
            stamp,
            robot,
            scan_to_msg(item.scan, item.frame_id, stamp_from_seconds(stamp), scan_time),
        )


@dataclasses.dataclass
class PlayStats:
    """What a :class:`ScanPlayer` did."""

    published: dict[str, int] = dataclasses.field(default_factory=dict)
    late_s: list[float] = dataclasses.field(default_factory=list)  # behind schedule per scan
    wall_s: float = 0.0


class ScanPlayer:
    """Publishes a :func:`timeline` on ``/<robot>/scan`` (sensor-data QoS) from a thread,
    each message when ``(stamp - first stamp) / speed`` seconds have passed, and ``/clock``
    (the stamp) before each scan when ``clock`` is set."""

    def __init__(
        self, node: Node, robots: Sequence[str], speed: float = 1.0, clock: bool = False
    ) -> None:
        if not speed > 0.0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.node = node
        self.speed = speed
        self._publishers = {
            robot: node.create_publisher(LaserScan, f"/{robot}/scan", qos_profile_sensor_data)
            for robot in robots
        }
        self._clock = node.create_publisher(Clock, "/clock", 10) if clock else None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.stats = PlayStats(published={robot: 0 for robot in robots})

    def subscribed(self) -> bool:
        """Every robot's scan topic has a subscriber (the mappers are listening)."""
        return all(p.get_subscription_count() > 0 for p in self._publishers.values())

    def play(self, messages: Timeline) -> PlayStats:
        """Publish every message at its time; returns when done or stopped."""
        started = time.monotonic()
        first: float | None = None
        for stamp, robot, msg in messages:
            if self._stop.is_set():
                break
            first = stamp if first is None else first
            due = started + (stamp - first) / self.speed
            wait = due - time.monotonic()
            if wait > 0.0 and self._stop.wait(wait):
                break
            self.stats.late_s.append(max(0.0, -wait))
            if self._clock is not None:
                self._clock.publish(Clock(clock=msg.header.stamp))
            self._publishers[robot].publish(msg)
            self.stats.published[robot] += 1
        self.stats.wall_s = time.monotonic() - started
        return self.stats

    def start(self, messages: Timeline) -> None:
        """:meth:`play` in a thread of its own."""
        self._thread = threading.Thread(target=self.play, args=(messages,), daemon=True)
        self._thread.start()

    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)


@dataclasses.dataclass(frozen=True)
class GlobalMapView:
    """One ``global_map`` message as plain data."""

    received_s: float  # time.monotonic() when it arrived
    stamp: Time
    segments: dict[str, FloatArray]  # robot -> (N, 4) in map
    poses: dict[str, FloatArray]  # robot -> (x, y, theta) of its newest pose in map


def global_map_view(msg: MarkerArray, received_s: float) -> GlobalMapView:
    """The segments and robot poses a ``global_map`` MarkerArray shows, by robot name: its
    line lists are one per keyframe (namespace ``global_map/<robot>``), each placed in ``map``
    by its marker pose."""
    shown = [m for m in msg.markers if m.action == Marker.ADD]
    names = {m.id: m.text for m in shown if m.type == Marker.TEXT_VIEW_FACING}
    pieces: dict[str, list[FloatArray]] = {}
    prefix = GLOBAL_MAP_NAMESPACE + "/"
    for m in shown:
        if m.type == Marker.LINE_LIST and m.ns.startswith(prefix):
            T_map_marker = se2.matrix_from_pose(*pose_from_msg(m.pose))
            placed = se2.transform_segments(T_map_marker, segments_from_marker(m))
            pieces.setdefault(m.ns[len(prefix) :], []).append(placed)
    segments = {robot: np.vstack(parts) for robot, parts in pieces.items()}
    poses = {
        names.get(m.id, f"robot #{m.id}"): pose_from_msg(m.pose)
        for m in shown
        if m.type == Marker.ARROW
    }
    stamp = msg.markers[0].header.stamp if msg.markers else Time()
    return GlobalMapView(received_s, stamp, segments, poses)


class Observer(Node):
    """Subscribes to what a mapping system of ``robots`` publishes and keeps it (``poses``
    and ``partial_maps`` off: not the robots' own topics, which are heavy with many robots)."""

    def __init__(
        self,
        robots: Sequence[str],
        keep_maps: bool = True,
        poses: bool = True,
        partial_maps: bool = True,
        **kwargs: object,
    ) -> None:
        super().__init__("observer", **kwargs)  # type: ignore[arg-type]
        self.robots = list(robots)
        self.keep_maps = keep_maps
        self.global_maps: list[GlobalMapView] = []  # every one, when keep_maps, else the last
        self.grid: OccupancyGridMsg | None = None
        self.frames: dict[str, list[PoseStamped]] = {r: [] for r in robots}
        # The newest placement probability per robot (robot_frames/<ns>/probability): 0 once
        # the merger withdrew a placement (its last frame stays latched, but no longer holds).
        self.probabilities: dict[str, float] = {}
        self.frame_times: dict[str, float] = {}  # monotonic time of each robot's first frame
        self.poses: dict[str, list[tuple[float, FloatArray]]] = {r: [] for r in robots}
        self.partial_maps: dict[str, MarkerArray] = {}  # the whole map, snapshots and updates
        self._streams: dict[str, MapStream] = {}
        self.partial_map_times: dict[str, float] = {}  # monotonic time of the newest
        self.diagnostics: dict[str, DiagnosticStatus] = {}  # by status name, the newest
        self.diagnostic_stamps: list[Time] = []
        self.create_subscription(MarkerArray, "/global_map", self._on_global_map, LATCHED_QOS)
        self.create_subscription(OccupancyGridMsg, "/global_grid", self._on_grid, LATCHED_QOS)
        self.create_subscription(
            DiagnosticArray, "/diagnostics", self._on_diagnostics, QoSProfile(depth=50)
        )
        for robot in robots:
            self._watch(robot, poses, partial_maps)

    def _watch(self, robot: str, poses: bool, partial_maps: bool) -> None:
        """Subscribe to what the merger publishes of ``robot`` and, when asked, to its
        own poses and partial maps."""
        self.create_subscription(
            PoseStamped,
            f"/robot_frames/{robot}",
            lambda msg: self._on_frame(robot, msg),
            LATCHED_QOS,
        )
        self.create_subscription(
            Float64,
            f"/robot_frames/{robot}/probability",
            lambda msg: self.probabilities.__setitem__(robot, float(msg.data)),
            LATCHED_QOS,
        )
        if poses:
            self.create_subscription(
                PoseStamped,
                f"/{robot}/pose",
                lambda msg: self.poses[robot].append(
                    (seconds_from_stamp(msg.header.stamp), pose_from_msg(msg.pose))
                ),
                POSE_QOS,
            )
        if partial_maps:
            self._streams[robot] = MapStream()
            self.create_subscription(
                MarkerArray,
                f"/{robot}/partial_map",
                lambda msg: self._on_partial_map(robot, msg, SNAPSHOT),
                LATCHED_QOS,
            )
            self.create_subscription(
                MarkerArray,
                f"/{robot}/partial_map_updates",
                lambda msg: self._on_partial_map(robot, msg, UPDATE),
                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE),
            )

    def _on_global_map(self, msg: MarkerArray) -> None:
        view = global_map_view(msg, time.monotonic())
        if not self.keep_maps:
            self.global_maps.clear()
        self.global_maps.append(view)

    def _on_partial_map(self, robot: str, msg: MarkerArray, kind: str) -> None:
        """A snapshot or an update applied to the robot's stream: ``partial_maps`` holds the
        whole map (an update that does not follow is left out until the next snapshot)."""
        stream = self._streams[robot]
        try:
            applied = stream.apply(msg, kind)
        except InputError:
            return
        stream.commit(applied)
        self.partial_maps[robot] = applied.whole_map()
        self.partial_map_times[robot] = time.monotonic()

    def _on_grid(self, msg: OccupancyGridMsg) -> None:
        self.grid = msg

    def _on_frame(self, robot: str, msg: PoseStamped) -> None:
        self.frames[robot].append(msg)
        self.frame_times.setdefault(robot, time.monotonic())

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        self.diagnostic_stamps.append(msg.header.stamp)
        for status in msg.status:
            self.diagnostics[status.name] = status

    def status_value(self, name: str, key: str) -> str | None:
        """A value of the newest /diagnostics status ``name`` (None when not seen)."""
        status = self.diagnostics.get(name)
        if status is None:
            return None
        return next((kv.value for kv in status.values if kv.key == key), None)

    def merged(self) -> list[str]:
        """Robots that have a frame in ``map`` now (not withdrawn since)."""
        return [r for r in self.robots if self.placement(r) is not None]

    def placement(self, robot: str) -> FloatArray | None:
        """The newest ``T_map_robotmap`` of a robot, None while it has none or once the
        merger withdrew it (its probability 0)."""
        if not self.frames[robot] or self.probabilities.get(robot, 1.0) <= 0.0:
            return None
        return pose_from_msg(self.frames[robot][-1].pose)

    def partial_map(self, robot: str) -> FloatArray:
        """A robot's newest partial map, ``(N, 4)`` in its own map frame."""
        msg = self.partial_maps.get(robot)
        return np.zeros((0, 4)) if msg is None else partial_map_contents(msg).segments

    def trajectory(self, robot: str) -> tuple[FloatArray, FloatArray]:
        """A robot's poses as received: stamps (N,) and (N, 3) in its own map frame."""
        items = self.poses[robot]
        stamps = np.array([s for s, _ in items], dtype=np.float64)
        poses = np.array([p for _, p in items], dtype=np.float64).reshape(-1, 3)
        return stamps, poses
