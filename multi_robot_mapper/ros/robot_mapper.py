"""``robot_mapper``: one robot's laser scans in; line segments, its pose and its partial map out.

Topics (relative, so ``-r __ns:=/robot1`` gives ``/robot1/scan`` -> ``/robot1/partial_map``):
  sub ``scan``           sensor_msgs/LaserScan, sensor-data QoS (best effort, volatile), a
                         queue of SCAN_QUEUE_DEPTH scans
  pub ``scan_segments``  visualization_msgs/Marker LINE_LIST in the scan's frame, stamped with
                         the scan's stamp
  pub ``pose``           geometry_msgs/PoseStamped, T_robotmap_laser of every accepted scan in
                         the map frame, stamped with the scan's stamp (reliable, depth 10)
  pub ``partial_map``    visualization_msgs/MarkerArray, one LINE_LIST per keyframe (id = index,
                         pose = the keyframe in the map frame, points in the keyframe's frame),
                         stamped with the newest keyframe's scan: a snapshot, the whole map, at
                         most every ``snapshot_period`` or when asked (reliable, transient
                         local, depth 1: a late subscriber gets the map)
  pub ``partial_map_updates``  MarkerArray of the keyframes changed since the last message,
                         every ``partial_map_period`` when the map changed (reliable,
                         volatile, depth 10); both carry a sequence tag (io/map_updates.py)
  sub ``partial_map_request``  std_msgs/Empty: a receiver that missed an update asks for a
                         snapshot, sent at the next ``partial_map_period``
  pub ``/diagnostics``   diagnostic_msgs/DiagnosticArray every ``diagnostics_period``: the
                         robot's status (ros/diagnostics.py), stamped with the newest scan
Parameters: the fields of :class:`RobotMapperConfig` (``config/robot_mapper.yaml``).
"""

from __future__ import annotations

import dataclasses
import sys
import time
import traceback
import uuid
from collections import Counter
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Empty, Header
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core.extraction import SegmentScan, extract_scan
from multi_robot_mapper.core.local_mapping import Keyframe, LocalMapper, LocalUpdate
from multi_robot_mapper.core.scan import LaserScanData, ScanError, ScanPoints
from multi_robot_mapper.core.scan_stream import REASON_FIELDS, ScanStreamGuard, StreamVerdict
from multi_robot_mapper.io.map_updates import SNAPSHOT, UpdatePlanner, sequence_marker
from multi_robot_mapper.io.messages import (
    keyframe_marker,
    piece_frame,
    pose_stamped,
    scan_from_msg,
    seconds_from_stamp,
    segments_marker,
    stamp_from_seconds,
)
from multi_robot_mapper.ros import diagnostics
from multi_robot_mapper.ros.boundary import CallbackGuard, Rejections
from multi_robot_mapper.ros.entry import run_node
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.parameters import declare_config, on_config_change
from multi_robot_mapper.ros.throttle import ThrottledWarnings
from multi_robot_mapper.ros.worker_process import WorkerProcess

# Notices about the laser itself (it is mounted upside down, its intensities are of another
# length): one warning, then only counted.
_ONCE = frozenset({"negative_increment", "intensities_length"})


@dataclasses.dataclass(frozen=True)
class _Extracted:
    """A scan through the front end, ready to map (now, or once the stream guard releases
    it)."""

    msg: LaserScan
    stamp: float
    view: LaserScanData
    segments: SegmentScan
    valid: ScanPoints


# Sensor-data QoS (best effort, volatile: it matches any laser driver), with a deeper queue
# than its 5. A scan that starts a keyframe takes a few hundred milliseconds (the keyframe's
# matches, the partial map), during which a 40 Hz laser sends 10-20 scans: with 5 kept, the
# rest were lost although the mapper keeps up on average (make demo on two cores under load:
# 520 of 2400 dropped; with 50 kept, 2). Without odometry every lost scan is a longer step for
# tracking. Age, not count, now decides what is set aside: a scan that waited longer than
# scan_max_queue_delay is rejected (stale_in_queue); 50 scans are 1.25 s at 40 Hz.
SCAN_QUEUE_DEPTH = 50
SCAN_QOS = QoSProfile(
    depth=SCAN_QUEUE_DEPTH,
    reliability=qos_profile_sensor_data.reliability,
    durability=qos_profile_sensor_data.durability,
)
POSE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
PARTIAL_MAP_QOS = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
# Updates build on each other: reliable, and a queue for a slow link; volatile, since a late
# subscriber starts from the latched snapshot and asks for a newer one if updates went by.
UPDATES_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
REQUEST_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)


def default_map_frame(namespace: str) -> str:
    """``/robot1`` -> ``robot1/map``; the root namespace -> ``map``."""
    prefix = namespace.strip("/")
    return f"{prefix}/map" if prefix else "map"


class RobotMapper(Node):
    """Per-robot mapper node: front end (scans to segments) and local mapper (partial map).

    ``config`` (default: the dataclass defaults) gives the fixed constants and the defaults of
    the ROS parameters: code that builds the node in Python (tests, experiments) changes a fixed
    constant there."""

    def __init__(
        self,
        node_name: str = "robot_mapper",
        config: RobotMapperConfig | None = None,
        **kwargs: object,
    ) -> None:
        super().__init__(node_name, **kwargs)  # type: ignore[arg-type]
        self.config = declare_config(self, RobotMapperConfig, config)
        self.warnings = ThrottledWarnings(self.get_logger().warning, self.config.warning_period)
        self.robot = self.get_namespace().strip("/") or self.get_name()
        # Bad input is rejected (counted per reason, a throttled warning); no callback raises.
        self.rejections = Rejections(self.warnings)
        self.guard = CallbackGuard(self.warnings, running=self.context.ok)
        # Every scan is checked against the robot's own stream (core.scan_stream) before it
        # is mapped: the same guard replay uses.
        self.stream: ScanStreamGuard[_Extracted] = ScanStreamGuard(self.config.stream_config())
        self.scans_received = 0
        self.scans_rejected = 0  # dropped before mapping: bad scan or front-end error
        self.mapping_errors = 0  # scans the local mapper failed on (map kept as it was)
        self.map_resets = 0  # maps started over after the stamps jumped back and stayed
        self.beams_dropped: Counter[str] = Counter()  # beams without a return, by kind
        self.scans_lost = 0  # never delivered (gaps in the publisher's sequence numbers)
        self.max_queue_delay = 0.0  # longest wait in the queue of a scan that was mapped, s
        self._last_sequence: int | None = None
        self.partial_maps_published = 0
        self.published_keyframes = 0  # keyframes in the last partial map published
        self.published_stamp: Time | None = None  # header stamp of the last partial map
        self.rejected: dict[str, int] = {}  # scans dropped before mapping, by reason
        self.scans_skipped = 0  # left out by max_scan_rate
        self._mapped_stamp: float | None = None  # stamp of the last scan not skipped
        self._scan_rate = diagnostics.RateMeter()
        self._last_scan_ns: int | None = None  # node clock when the last scan arrived
        self._last_stamp = Time()  # header stamp of the newest scan
        self._reported = (0, 0, 0)  # received, accepted, rejected at the last diagnostics
        # The back end (keyframe graph, loop closures, fusion) works on a thread of its own,
        # by default waiting on a worker process: a scan never waits for it.
        self.mapper = self._new_mapper()
        self._backend_errors_logged = 0
        self.last_update: LocalUpdate | None = None
        # Header stamps of the keyframes' scans, exact (a float second near 1e9 is not).
        self._keyframe_stamps: dict[float, Time] = {}
        self.published_version = 0  # mapper version last published (the empty map never is)
        # Markers of unchanged keyframes are reused: building Points is the costly part.
        self._marker_cache: dict[int, tuple[bytes, Marker]] = {}
        # What the receivers hold: snapshots now and then, updates of what changed between.
        self.planner = UpdatePlanner(uuid.uuid4().hex[:12])
        self.snapshot_requests = 0
        self._snapshot_asked = False
        self._snapshot_ns: int | None = None  # node clock at the last snapshot
        self.updates_published = 0
        self._connect()
        on_config_change(self, lambda: self.config, self._apply_config)

    def _connect(self) -> None:
        """The node's topics and timers (the module doc lists them)."""
        self._segments_pub = self.create_publisher(Marker, "scan_segments", 10)
        self._pose_pub = self.create_publisher(PoseStamped, "pose", POSE_QOS)
        self._map_pub = self.create_publisher(MarkerArray, "partial_map", PARTIAL_MAP_QOS)
        self._updates_pub = self.create_publisher(MarkerArray, "partial_map_updates", UPDATES_QOS)
        self._request_sub = self.create_subscription(
            Empty,
            "partial_map_request",
            self.guard("partial_map_request", self._asked),
            REQUEST_QOS,
        )
        self._scan_sub = self.create_subscription(
            LaserScan, "scan", self.guard("scan", self._receive_scan), SCAN_QOS
        )
        self._map_timer = self.create_timer(
            self.config.partial_map_period, self.guard("partial_map", self.publish_map)
        )
        self._diagnostics_pub = self.create_publisher(
            diagnostics.DiagnosticArray, diagnostics.TOPIC, 10
        )
        self._diagnostics_timer = self.create_timer(
            self.config.diagnostics_period, self.guard("diagnostics", self.publish_diagnostics)
        )

    @property
    def map_frame(self) -> str:
        """The frame of ``pose`` and ``partial_map``."""
        return self.config.map_frame or default_map_frame(self.get_namespace())

    @property
    def map_published(self) -> bool:
        """The partial map as it is now has gone out (or there is none yet)."""
        return self.mapper.idle and self.mapper.version in (0, self.published_version)

    def _apply_config(self, config: RobotMapperConfig) -> None:
        old = self.config
        self.config = config
        self.warnings.period = config.warning_period
        self.stream.reconfigure(config.stream_config())
        self.mapper.reconfigure(config.local_mapping)  # from the next scan; the map is kept
        if config.partial_map_period != old.partial_map_period:
            self.destroy_timer(self._map_timer)
            self._map_timer = self.create_timer(
                config.partial_map_period, self.guard("partial_map", self.publish_map)
            )
        if config.diagnostics_period != old.diagnostics_period:
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = self.create_timer(
                config.diagnostics_period, self.guard("diagnostics", self.publish_diagnostics)
            )
        if (config.map_frame, config.segment_marker_width) != (
            old.map_frame,
            old.segment_marker_width,
        ):
            self._marker_cache.clear()
            self.published_version = -1  # republish in the new frame / width
            self._snapshot_asked = True

    def _receive_scan(self, msg: LaserScan, info: dict[str, Any]) -> None:
        """The scan subscription: scans lost on the way are counted, one that waited too long
        in the queue is dropped (newer ones wait behind it), the others are mapped."""
        sequence = info.get("publication_sequence_number")
        if sequence:
            last = self._last_sequence
            if last is not None and sequence > last + 1:
                self.scans_lost += sequence - last - 1
            self._last_sequence = sequence
        received = info.get("received_timestamp")
        delay = (time.time_ns() - received) * 1e-9 if received else 0.0
        if delay > self.config.scan_max_queue_delay:
            self.scans_received += 1
            self.stream.skipped(seconds_from_stamp(msg.header.stamp))
            self._reject(
                "stale_in_queue",
                "",
                f"waited {delay * 1e3:.0f} ms in the queue, more than scan_max_queue_delay "
                f"({self.config.scan_max_queue_delay:g} s): newer scans come first",
            )
            return
        self.max_queue_delay = max(self.max_queue_delay, delay)
        self._on_scan(msg)

    def _reject(self, kind: str, field: str, message: str) -> None:
        self.scans_rejected += 1
        self.rejected[kind] = self.rejected.get(kind, 0) + 1
        self.rejections.reject(self.robot, kind, field, message, "scan")

    def _clock_seconds(self) -> float:
        return float(self.get_clock().now().nanoseconds) * 1e-9

    def _on_scan(self, msg: LaserScan) -> None:
        self.scans_received += 1
        stamp = seconds_from_stamp(msg.header.stamp)
        self._last_scan_ns = self.get_clock().now().nanoseconds
        self._last_stamp = msg.header.stamp
        self._scan_rate.add(stamp)
        if self._throttled(stamp):
            self.scans_skipped += 1
            self.stream.skipped(stamp)
            return
        try:
            view = scan_from_msg(msg)
            segments, valid = extract_scan(view, self.config.extraction)
        except ScanError as exc:
            self._reject(exc.kind, exc.field, f"(stamp {stamp:.3f}) {exc}")
            return
        except Exception:  # a bug must not take the robot's mapper down with it
            self.scans_rejected += 1
            self.rejected["internal_error"] = self.rejected.get("internal_error", 0) + 1
            self.warnings.warn(
                "internal_error",
                f"dropped scan (stamp {stamp:.3f}) after an internal error:\n"
                f"{traceback.format_exc()}",
            )
            return
        scan = _Extracted(msg, stamp, view, segments, valid)
        verdict = self.stream.check(stamp, view, scan, self._clock_seconds())
        self._act_on(verdict, scan)

    def _act_on(self, verdict: StreamVerdict[_Extracted], scan: _Extracted) -> None:
        """The stream guard's verdict: scans refused are counted and named, a map whose
        stamps jumped back (and stayed there) starts over, the scans released are mapped."""
        for kind, message in verdict.refused:
            self._reject(kind, REASON_FIELDS.get(kind, ""), message)
        for kind, notice in verdict.notices:
            self.warnings.warn(kind, f"{self.robot}: {notice}")
        if not verdict.maps:
            return
        if verdict.action == "reset":
            self._start_over()
        for held in verdict.release:
            self._map_scan(held.item)
        self._map_scan(scan)

    def _map_scan(self, scan: _Extracted) -> None:
        """One scan the stream accepted: its segments out, then the local mapper."""
        stamp, msg, valid = scan.stamp, scan.msg, scan.valid
        for kind, count in valid.dropped:
            self.beams_dropped[kind] += count
        for notice in valid.notices:
            text = f"{self.robot}: scan (stamp {stamp:.3f}): {notice.message}"
            if notice.kind in _ONCE:  # a property of the laser: said once, then counted
                self.warnings.once(notice.kind, text)
            else:
                self.warnings.warn(notice.kind, text)
        self._segments_pub.publish(
            segments_marker(
                scan.segments.segments,
                msg.header,
                namespace="scan_segments",
                width=self.config.segment_marker_width,
            )
        )
        try:
            # A scan changes the mapper only once it is placed: a failure leaves the map as
            # it was.
            update = self.mapper.add_scan(stamp, scan.segments, scan.view)
        except Exception:  # the map built so far stays; the next scan is tried as usual
            self.mapping_errors += 1
            self.last_update = None
            self.warnings.warn(
                "mapping_error",
                f"scan (stamp {stamp:.3f}) not mapped after an internal error in the local "
                f"mapper (the partial map is kept):\n{traceback.format_exc()}",
            )
            return
        self.last_update = update
        if update.keyframe_added:
            self._keyframe_stamps[stamp] = msg.header.stamp
        if update.accepted and update.pose is not None:
            frame = piece_frame(self.map_frame, update.piece)
            self._pose_pub.publish(pose_stamped(update.pose, msg.header.stamp, frame))

    def _throttled(self, stamp: float) -> bool:
        """Whether ``max_scan_rate`` leaves this scan out (too soon after the last one mapped,
        by the stamps; 1 ms of slack for stamps rounded to the nanosecond)."""
        rate = self.config.max_scan_rate
        last = self._mapped_stamp
        if rate > 0.0 and last is not None and 0.0 <= stamp - last < 1.0 / rate - 1e-3:
            return True
        self._mapped_stamp = stamp
        return False

    def _new_mapper(self) -> LocalMapper:
        """An empty local mapper, its back end started: in a worker process unless
        ``backend_process`` is off."""
        mapper = LocalMapper(self.config.local_mapping, backend=False, trajectory=False)
        process = self.config.backend_process
        mapper.start_worker(WorkerProcess(f"{self.robot} back end") if process else None)
        return mapper

    def destroy_node(self) -> None:
        self.mapper.stop_worker()
        super().destroy_node()

    def _report_backend_errors(self) -> None:
        """A back-end step that failed (a bug) is logged, throttled, with its traceback."""
        errors = self.mapper.backend_errors
        if errors > self._backend_errors_logged and self.mapper.last_backend_error:
            self._backend_errors_logged = errors
            self.warnings.warn(
                "backend_error",
                f"the local mapper's back end skipped a step after an internal error ({errors} "
                f"so far; the map is kept):\n{self.mapper.last_backend_error}",
            )

    def _start_over(self) -> None:
        """A new, empty map (the old one stays published until the new one has a keyframe);
        the stream guard's notice has said why."""
        self.map_resets += 1
        self.mapper.stop_worker()
        self.mapper = self._new_mapper()
        self._backend_errors_logged = 0
        self.last_update = None
        self._keyframe_stamps.clear()
        self._marker_cache.clear()
        self.published_version = -1  # the new map's first version is published
        self.planner = UpdatePlanner(uuid.uuid4().hex[:12])  # a new stream: a snapshot first

    def _asked(self, _msg: Empty) -> None:
        """A receiver missed an update: the next period sends a snapshot."""
        self.snapshot_requests += 1
        self._snapshot_asked = True

    def _snapshot_due(self) -> bool:
        now = self.get_clock().now().nanoseconds
        last = self._snapshot_ns
        return (
            self._snapshot_asked
            or last is None
            or now - last >= self.config.snapshot_period * 1e9
            or now < last  # the clock went back (sim time restarted)
        )

    def publish_map(self) -> bool:
        """Publish what changed since the last publication (an update), or the whole map (a
        snapshot) when one is due or asked for; True when something went out."""
        self._report_backend_errors()
        version = self.mapper.version
        if version == 0 or (version == self.published_version and not self._snapshot_asked):
            return False
        try:
            keyframes = self.mapper.keyframes()
            plan = self.planner.plan(keyframes, snapshot=self._snapshot_due())
            if plan is None:  # changed within the tolerance only: nothing to send
                self.published_version = version
                return False
            newest = max(kf.stamp for kf in keyframes)  # the newest scan in the map
            stamp = self._keyframe_stamps.get(newest)
            if stamp is None:
                stamp = stamp_from_seconds(newest)
            array = MarkerArray()
            array.markers = [
                self._marker(
                    kf, Header(frame_id=piece_frame(self.map_frame, kf.piece), stamp=stamp)
                )
                for kf in plan.keyframes
            ]
            array.markers.append(
                sequence_marker(plan.tag, Header(frame_id=self.map_frame, stamp=stamp))
            )
        except Exception:
            self.warnings.warn(
                "partial_map_error",
                f"partial map not published after an internal error:\n{traceback.format_exc()}",
            )
            return False
        if plan.tag.kind == SNAPSHOT:
            self._map_pub.publish(array)
            self._snapshot_ns = self.get_clock().now().nanoseconds
            self._snapshot_asked = False
            self.partial_maps_published += 1
        else:
            self._updates_pub.publish(array)
            self.updates_published += 1
        self.planner.commit(plan)
        self.published_keyframes = plan.tag.keyframes
        self.published_stamp = stamp
        self.published_version = version
        return True

    def publish_diagnostics(self) -> None:
        """The robot's status on /diagnostics, stamped with its newest scan."""
        mapper = self.mapper
        now = self.get_clock().now().nanoseconds
        counts = (self.scans_received, mapper.scans_accepted, self.scans_rejected)
        recent = [now_count - then for now_count, then in zip(counts, self._reported, strict=True)]
        self._reported = counts
        health = diagnostics.MapperHealth(
            robot=self.get_namespace().strip("/") or self.get_name(),
            scan_rate=self._scan_rate.rate(),
            silent_for=None if self._last_scan_ns is None else (now - self._last_scan_ns) * 1e-9,
            stale_timeout=self.config.stale_timeout,
            scans_received=self.scans_received,
            scans_accepted=mapper.scans_accepted,
            rejected=dict(self.rejected),
            skipped=self.scans_skipped,
            set_aside=dict(mapper.set_aside_reasons),
            keyframes=self.published_keyframes,
            map_segments=len(mapper.map_segments),
            recent_received=recent[0],
            recent_accepted=recent[1],
            recent_rejected=recent[2],
        )
        status = diagnostics.mapper_status(health)
        self._diagnostics_pub.publish(diagnostics.diagnostic_array([status], self._last_stamp))

    def _marker(self, keyframe: Keyframe, header: Header) -> Marker:
        """The keyframe's marker, reused (with the new header) when the keyframe is unchanged."""
        key = (
            np.float64(keyframe.stamp).tobytes()
            + np.int64(keyframe.piece).tobytes()
            + np.ascontiguousarray(keyframe.T_robotmap_keyframe, dtype=np.float64).tobytes()
            + np.ascontiguousarray(keyframe.segments, dtype=np.float64).tobytes()
        )
        cached = self._marker_cache.get(keyframe.index)
        if cached is not None and cached[0] == key:
            marker = cached[1]
            marker.header = header
            return marker
        marker = keyframe_marker(keyframe, header, self.config.segment_marker_width)
        self._marker_cache[keyframe.index] = (key, marker)
        return marker


def main(args: list[str] | None = None) -> int:
    """Console entry point (``ros2 run multi_robot_mapper robot_mapper``)."""
    return run_node("robot_mapper", RobotMapper, args)


if __name__ == "__main__":
    sys.exit(main())
