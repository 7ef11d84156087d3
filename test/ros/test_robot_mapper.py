"""A real robot_mapper node spun in-process: segments, pose and partial map out, bad scans
survived, parameters."""

from __future__ import annotations

import math
import time
from functools import cache

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.config import ConfigError, config_from_flat
from multi_robot_mapper.core.local_mapping import attempts as front_end_attempts
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import LaserModel, SimulatedRobot, raycast, simulate_robots
from multi_robot_mapper.core.worlds import polygon
from multi_robot_mapper.io.map_updates import keyframe_markers, sequence_of
from multi_robot_mapper.io.messages import (
    keyframes_from_markers,
    pose_from_msg,
    scan_to_msg,
    seconds_from_stamp,
    segments_from_marker,
    stamp_from_seconds,
)
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.robot_mapper import RobotMapper, default_map_frame, main
from multi_robot_mapper.ros.testing import default_domain_id, spin_until

pytestmark = pytest.mark.ros

ROOM = polygon([(-2.0, -1.5), (3.0, -1.5), (3.0, 2.5), (-2.0, 2.5)])


def room_scan(beams: int = 361) -> LaserScanData:
    angles = np.linspace(-math.radians(135), math.radians(135), beams)
    ranges = raycast(ROOM, (-1.0, 0.4, 0.05), angles, 30.0)
    return LaserScanData(ranges, angles[0], angles[-1], angles[1] - angles[0], 0.05, 30.0)


class Harness:
    """One robot_mapper in namespace /robot1 and a driver node talking to it over real topics."""

    def __init__(self, context, **node_kwargs) -> None:
        # room_scan is noise-free, the same ranges every time: the copy rule (copy_window)
        # would refuse every repeat, so it is off here (test_hostile_scans tests it).
        overrides = [Parameter("copy_window", value=0), *node_kwargs.pop("parameter_overrides", [])]
        self.mapper = RobotMapper(
            context=context, namespace="robot1", parameter_overrides=overrides, **node_kwargs
        )
        self.logged: list[str] = []
        self.mapper.warnings.log = self.logged.append
        self.driver = Node("driver", context=context)
        self.scan_pub = self.driver.create_publisher(
            LaserScan, "/robot1/scan", qos_profile_sensor_data
        )
        self.received: list[Marker] = []
        self.driver.create_subscription(
            Marker, "/robot1/scan_segments", self.received.append, QoSProfile(depth=100)
        )
        self.poses: list[PoseStamped] = []
        self.driver.create_subscription(
            PoseStamped, "/robot1/pose", self.poses.append, QoSProfile(depth=100)
        )
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.mapper)
        self.executor.add_node(self.driver)
        assert spin_until(
            self.executor,
            lambda: (
                self.scan_pub.get_subscription_count() > 0
                and self.mapper.count_subscribers("scan_segments") > 0
                and self.mapper.count_subscribers("pose") > 0
            ),
            timeout=10.0,
        )

    def send(self, msg: LaserScan) -> None:
        before = self.mapper.scans_received
        self.scan_pub.publish(msg)
        assert spin_until(self.executor, lambda: self.mapper.scans_received > before, timeout=5.0)

    def answer_to(self, msg: LaserScan) -> Marker:
        """Publish a scan and wait for the segments stamped with its stamp."""
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)

        def answered() -> list[Marker]:
            return [
                m for m in self.received if (m.header.stamp.sec, m.header.stamp.nanosec) == stamp
            ]

        self.send(msg)
        assert spin_until(self.executor, lambda: bool(answered()), timeout=5.0)
        return answered()[-1]

    def send_good(self, t: float) -> Marker:
        return self.answer_to(scan_to_msg(room_scan(), "robot1/laser", stamp_from_seconds(t)))

    def close(self) -> None:
        self.executor.shutdown()
        self.mapper.destroy_node()
        self.driver.destroy_node()


@pytest.fixture
def harness(ros_context):
    h = Harness(ros_context)
    yield h
    h.close()


def test_segments_come_back_stamped_and_framed_like_the_scan(harness: Harness) -> None:
    marker = harness.send_good(42.25)
    assert marker.header.frame_id == "robot1/laser"
    assert (marker.header.stamp.sec, marker.header.stamp.nanosec) == (42, 250_000_000)
    assert marker.type == Marker.LINE_LIST
    segments = segments_from_marker(marker)
    assert len(segments) == 5  # the five visible wall pieces of the room
    lengths = np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1])
    assert lengths.sum() > 10.0


def test_topics_are_relative_to_the_namespace(harness: Harness) -> None:
    names = {name for name, _ in harness.mapper.get_topic_names_and_types()}
    assert {"/robot1/scan", "/robot1/scan_segments", "/robot1/pose", "/robot1/partial_map"} <= names


def bad(base: LaserScanData | None = None, t: float = 1.0, **changes) -> LaserScan:
    scan = base or room_scan()
    msg = scan_to_msg(scan, "robot1/laser", stamp_from_seconds(t))
    for key, value in changes.items():
        setattr(msg, key, value)
    return msg


def reversed_room() -> LaserScanData:
    scan = room_scan()
    return LaserScanData(
        scan.ranges[::-1].copy(), scan.angle_max, scan.angle_min, -scan.angle_increment, 0.05, 30.0
    )


# case: (changes, kind, words in the warning, rejected or only noted)
BAD_SCANS = {
    "nan": (dict(ranges=[float("nan")] * 100 + [2.0] * 261), "non_finite_ranges", "NaN", False),
    "inf": (dict(ranges=[float("inf")] * 361), "no_valid_ranges", "none of the 361", True),
    "all_invalid": (dict(ranges=[0.0] * 361), "no_valid_ranges", "none of the 361 ranges", True),
    "zero_beams": (dict(ranges=[]), "no_beams", "no beams", True),
    "ten_thousand_beams": (dict(ranges=[2.0] * 10_000), "beam_span", "10000 beams", True),
    "negative_increment": ({}, "negative_increment", "clockwise", False),
    "intensities_length": (
        dict(intensities=[1.0] * 7),
        "intensities_length",
        "intensities has 7",
        False,
    ),
    "angle_max_below_min": (dict(angle_max=-3.0), "angle_order", "opposite sign", True),
    "range_max_below_min": (dict(range_min=5.0, range_max=1.0), "range_limits", "range_max", True),
    "range_min_negative": (dict(range_min=-0.5), "range_limits", "[range_min]", True),
    "range_max_nan": (dict(range_max=float("nan")), "non_finite_field", "[range_max]", True),
    "increment_zero": (dict(angle_increment=0.0), "zero_increment", "[angle_increment]", True),
    "increment_inf": (
        dict(angle_increment=float("inf")),
        "non_finite_field",
        "[angle_increment]",
        True,
    ),
    "fields_contradict_count": (dict(ranges=[2.0] * 200), "beam_count", "describe 361", True),
    "degenerate_increment": (
        dict(angle_increment=1e-4, angle_max=-2.356194 + 1e-4 * 360),
        "field_of_view",
        "min_field_of_view",
        True,
    ),
    "one_beam": (
        dict(ranges=[2.0], angle_max=-2.356194, angle_increment=0.0),
        "field_of_view",
        "1 beams",
        True,
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_SCANS))
def test_bad_scan_warns_once_names_the_problem_and_the_node_goes_on(
    harness: Harness, case: str
) -> None:
    changes, kind, words, rejected = BAD_SCANS[case]
    base = reversed_room() if case == "negative_increment" else None
    harness.send(bad(base, t=1.0, **changes))
    harness.send(bad(base, t=1.5, **changes))  # the same problem again within the period
    matching = [line for line in harness.logged if words in line]
    assert len(matching) == 1, harness.logged
    mapper = harness.mapper
    if rejected:  # not used, counted per reason, the warning names the robot
        assert mapper.rejections.counts[("robot1", kind)] == 2
        assert mapper.scans_rejected == 2 and matching[0].startswith("robot1: scan rejected")
    else:  # used, with a notice
        assert mapper.warnings.counts[kind] == 2 and mapper.scans_rejected == 0
    # and the laser's next good scan is processed as usual
    marker = harness.answer_to(
        scan_to_msg(base or room_scan(), "robot1/laser", stamp_from_seconds(2.0))
    )
    assert len(segments_from_marker(marker)) == 5


def test_negative_increment_scan_gives_the_same_segments(ros_context) -> None:
    # Two lasers' geometries in one stream: each taken as it comes (geometry_change_scans 1).
    harness = Harness(ros_context, config=RobotMapperConfig(geometry_change_scans=1))
    try:
        _compare_forward_and_reversed(harness)
    finally:
        harness.close()


def _compare_forward_and_reversed(harness: Harness) -> None:
    forward = segments_from_marker(harness.send_good(3.0))
    scan = room_scan()
    reversed_scan = LaserScanData(
        scan.ranges[::-1].copy(), scan.angle_max, scan.angle_min, -scan.angle_increment, 0.05, 30.0
    )
    backward = harness.answer_to(bad(reversed_scan, t=4.0))
    np.testing.assert_allclose(segments_from_marker(backward), forward, atol=1e-4)


def test_invalid_parameter_override_is_refused_with_its_name(ros_context) -> None:
    with pytest.raises(ConfigError, match=r"extraction\.split_tolerance"):
        RobotMapper(
            context=ros_context,
            parameter_overrides=[Parameter("extraction.split_tolerance", value=-1.0)],
        )


def test_parameter_override_reaches_the_config_and_bad_runtime_changes_are_refused(
    ros_context,
) -> None:
    node = RobotMapper(
        context=ros_context,
        parameter_overrides=[Parameter("extraction.cluster_distance", value=0.3)],
    )
    try:
        assert node.config.extraction.cluster_distance == 0.3
        results = node.set_parameters([Parameter("extraction.simplifier", value="nonsense")])
        assert not results[0].successful and "not one of" in results[0].reason
        assert node.config.extraction.simplifier == "split"
        results = node.set_parameters([Parameter("extraction.simplifier", value="dce")])
        assert results[0].successful
        assert node.config.extraction.simplifier == "dce"
    finally:
        node.destroy_node()


# --- local mapping: pose and partial_map -----------------------------------------------------

DRIVE_EVERY = 4  # every 4th scan of a 40 Hz drive: 10 Hz, about 8 cm apart, fast enough here


@cache
def drive() -> SimulatedRobot:
    """Three seconds of one robot in the office world (seeded, the same every time)."""
    return simulate_robots("office", 1, LaserModel(), seed=0, duration=3.0)[0]


def truth_in_robot_map(run: SimulatedRobot, stamp: float) -> np.ndarray:
    """The true laser pose at ``stamp`` relative to the first scan's (the robot's map frame)."""
    i = int(np.argmin(np.abs(run.stamps - stamp)))
    T_first_world = se2.invert(se2.matrix_from_pose(*run.T_world_laser[0]))
    return np.array(
        se2.pose_from_matrix(T_first_world @ se2.matrix_from_pose(*run.T_world_laser[i]))
    )


def assert_pose_close(got: np.ndarray, want: np.ndarray, metres: float, radians: float) -> None:
    assert math.hypot(got[0] - want[0], got[1] - want[1]) < metres, (got, want)
    assert abs(math.remainder(got[2] - want[2], math.tau)) < radians, (got, want)


def send_drive(harness: Harness) -> list[LaserScan]:
    run = drive()
    msgs = [
        scan_to_msg(run.scans[i], "robot1/laser", stamp_from_seconds(run.stamps[i]), 0.025)
        for i in range(0, len(run.scans), DRIVE_EVERY)
    ]
    for msg in msgs:
        harness.send(msg)
    return msgs


@pytest.fixture
def fast_map_harness(ros_context):
    h = Harness(ros_context, parameter_overrides=[Parameter("partial_map_period", value=0.1)])
    yield h
    h.close()


def test_every_accepted_scan_gives_its_pose_stamped_and_in_the_robot_map_frame(
    fast_map_harness: Harness,
) -> None:
    h = fast_map_harness
    msgs = send_drive(h)
    assert h.mapper.scans_received == len(msgs)
    accepted = h.mapper.mapper.scans_accepted
    assert accepted >= len(msgs) - 2  # a clean simulated drive: (nearly) every scan placed
    assert spin_until(h.executor, lambda: len(h.poses) == accepted, timeout=5.0)
    sent = {(m.header.stamp.sec, m.header.stamp.nanosec) for m in msgs}
    for pose in h.poses:
        assert pose.header.frame_id == "robot1/map"
        assert (pose.header.stamp.sec, pose.header.stamp.nanosec) in sent
    np.testing.assert_array_equal(pose_from_msg(h.poses[0].pose), [0.0, 0.0, 0.0])
    for pose in h.poses:
        want = truth_in_robot_map(drive(), seconds_from_stamp(pose.header.stamp))
        assert_pose_close(pose_from_msg(pose.pose), want, metres=0.05, radians=0.02)
    # The newest pose is the mapper's, and the scan_segments output goes on as before.
    np.testing.assert_allclose(pose_from_msg(h.poses[-1].pose), h.mapper.mapper.pose, atol=1e-12)
    assert len(h.received) == len(msgs)


@pytest.fixture
def snapshot_harness(ros_context):
    """Every publication a snapshot (snapshot_period below partial_map_period)."""
    h = Harness(
        ros_context,
        config=RobotMapperConfig(snapshot_period=0.05),
        parameter_overrides=[Parameter("partial_map_period", value=0.1)],
    )
    yield h
    h.close()


def test_late_subscriber_receives_the_whole_partial_map(snapshot_harness: Harness) -> None:
    h = snapshot_harness
    msgs = send_drive(h)
    mapper = h.mapper.mapper
    assert spin_until(h.executor, lambda: h.mapper.map_published, timeout=10.0)
    published = h.mapper.partial_maps_published
    # Created after the map went out: transient local delivers the last (whole) map to it.
    maps: list[MarkerArray] = []
    late = Node("late_viewer", context=h.driver.context)
    qos = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    late.create_subscription(MarkerArray, "/robot1/partial_map", maps.append, qos)
    h.executor.add_node(late)
    try:
        assert spin_until(h.executor, lambda: bool(maps), timeout=5.0)
        # Several map periods go by: nothing changed, so nothing is republished.
        spin_until(h.executor, lambda: False, timeout=0.5)
        assert len(maps) == 1 and h.mapper.partial_maps_published == published
    finally:
        h.executor.remove_node(late)
        late.destroy_node()
    assert h.mapper.updates_published == 0
    tag = sequence_of(maps[0])
    array = MarkerArray(markers=keyframe_markers(maps[0]))
    keyframes = mapper.keyframes()
    assert len(keyframes) >= 3
    assert tag is not None and (tag.kind, tag.keyframes) == ("snapshot", len(keyframes))
    assert len(array.markers) == len(keyframes)
    assert [m.id for m in array.markers] == list(range(len(keyframes)))
    # Stamped with the newest scan in the map (the last keyframe's), exactly as that scan was.
    newest = next(m for m in msgs if seconds_from_stamp(m.header.stamp) == keyframes[-1].stamp)
    last_stamp = (newest.header.stamp.sec, newest.header.stamp.nanosec)
    for marker in array.markers:
        assert marker.ns == "partial_map" and marker.type == Marker.LINE_LIST
        assert marker.header.frame_id == "robot1/map"
        assert (marker.header.stamp.sec, marker.header.stamp.nanosec) == last_stamp
    received = keyframes_from_markers(array)
    for got, want in zip(received, keyframes, strict=True):
        np.testing.assert_array_equal(got.segments, want.segments)
        assert got.stamp == want.stamp
        # Keyframe poses: close to the true motion since the first scan.
        assert_pose_close(
            got.T_robotmap_keyframe, truth_in_robot_map(drive(), got.stamp), 0.05, 0.02
        )
    np.testing.assert_allclose(received[0].T_robotmap_keyframe, [0.0, 0.0, 0.0], atol=1e-9)
    segments = sum(len(kf.segments) for kf in received)
    assert segments >= 10


def test_an_error_inside_the_local_mapper_is_logged_and_the_map_kept(
    fast_map_harness: Harness, monkeypatch: pytest.MonkeyPatch
) -> None:
    h = fast_map_harness
    send_drive(h)
    local = h.mapper.mapper
    # The back end works on its own thread: the state compared is the one it leaves.
    assert spin_until(h.executor, lambda: local.idle, timeout=30.0)
    before = local.keyframes()
    state = (local.version, local.pose, local.stamp, local.scans_accepted)

    def broken(*args: object, **kwargs: object) -> None:
        raise RuntimeError("simulated bug")  # in the middle of matching a scan

    monkeypatch.setattr(front_end_attempts, "integrate", broken)
    run = drive()
    far = len(run.scans) - 1  # the drive's last scan, not sent before
    scan = scan_to_msg(run.scans[far], "robot1/laser", stamp_from_seconds(run.stamps[-1] + 0.1))
    h.answer_to(scan)  # scan_segments still comes back
    h.send(scan_to_msg(run.scans[far], "robot1/laser", stamp_from_seconds(run.stamps[-1] + 0.2)))
    logged = [line for line in h.logged if "simulated bug" in line]
    assert len(logged) == 1 and "partial map is kept" in logged[0]  # throttled
    assert h.mapper.mapping_errors == 2
    # A scan changes the mapper only once it is placed: the map is the one built before.
    assert (local.version, local.pose, local.stamp, local.scans_accepted) == state
    after = local.keyframes()
    assert len(after) == len(before)
    for a, b in zip(after, before, strict=True):
        np.testing.assert_array_equal(a.segments, b.segments)
        np.testing.assert_array_equal(a.T_robotmap_keyframe, b.T_robotmap_keyframe)
    monkeypatch.undo()  # the bug is gone: mapping resumes on the same map
    h.send(scan_to_msg(run.scans[far], "robot1/laser", stamp_from_seconds(run.stamps[-1] + 0.3)))
    assert local.scans_accepted == state[3] + 1
    assert spin_until(h.executor, lambda: len(h.poses) == local.scans_accepted, timeout=5.0)


def test_bad_scans_leave_the_partial_map_alone(harness: Harness) -> None:
    harness.send(bad(ranges=[]))  # refused by the front end: never reaches the mapper
    harness.send(bad(ranges=[float("nan")] * 361, t=1.5))  # nothing to map: refused too
    assert harness.mapper.scans_rejected == 2
    local = harness.mapper.mapper
    assert local.scans_accepted == 0 and local.scans_set_aside == 0 and local.pose is None
    assert harness.poses == [] and local.version == 0
    harness.send_good(5.0)
    assert local.scans_accepted == 1
    assert spin_until(harness.executor, lambda: len(harness.poses) == 1, timeout=5.0)


def test_map_frame_default_follows_the_namespace_and_can_be_set(ros_context) -> None:
    assert default_map_frame("/robot1") == "robot1/map"
    assert default_map_frame("/fleet/robot2") == "fleet/robot2/map"
    assert default_map_frame("/") == "map"
    nodes = [
        RobotMapper(context=ros_context),
        RobotMapper(context=ros_context, namespace="robot3"),
        RobotMapper(
            context=ros_context,
            namespace="robot4",
            parameter_overrides=[Parameter("map_frame", value="site/r4_map")],
        ),
    ]
    try:
        assert [n.map_frame for n in nodes] == ["map", "robot3/map", "site/r4_map"]
    finally:
        for node in nodes:
            node.destroy_node()


def test_local_mapping_parameters_two_levels_deep_reach_the_mapper(ros_context) -> None:
    # A fixed constant two levels deep comes from the config the node is built with.
    fixed = {"local_mapping.integrate.point_distance_tolerance": 0.08}
    node = RobotMapper(
        context=ros_context,
        parameter_overrides=[Parameter("local_mapping.keyframe_distance", value=0.7)],
        config=config_from_flat(RobotMapperConfig, fixed),
    )
    try:
        assert node.mapper.config.integrate.point_distance_tolerance == 0.08
        assert node.mapper.config.keyframe_distance == 0.7
        results = node.set_parameters([Parameter("local_mapping.keyframe_angle", value=-1.0)])
        assert not results[0].successful and "keyframe_angle" in results[0].reason
        results = node.set_parameters([Parameter("local_mapping.keyframe_angle", value=0.2)])
        assert results[0].successful and node.mapper.config.keyframe_angle == 0.2
        results = node.set_parameters([Parameter("partial_map_period", value=0.0)])
        assert not results[0].successful and "partial_map_period" in results[0].reason
        results = node.set_parameters([Parameter("partial_map_period", value=0.5)])
        assert results[0].successful
        assert node._map_timer.timer_period_ns == 500_000_000
    finally:
        node.destroy_node()


@pytest.mark.parametrize("value", [0.0, -1.0])
def test_bad_partial_map_period_is_refused(ros_context, value: float) -> None:
    with pytest.raises(ConfigError, match="partial_map_period"):
        RobotMapper(
            context=ros_context, parameter_overrides=[Parameter("partial_map_period", value=value)]
        )


def test_main_exits_2_on_a_bad_partial_map_period(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", str(default_domain_id()))
    code = main(["robot_mapper", "--ros-args", "-p", "partial_map_period:=0.0"])
    assert code == 2
    assert "partial_map_period" in capsys.readouterr().err


def test_diagnostics_report_rate_rejections_by_reason_and_staleness(ros_context) -> None:
    from diagnostic_msgs.msg import DiagnosticArray

    from multi_robot_mapper.ros.diagnostics import OK, STALE, WARN

    h = Harness(
        ros_context,
        parameter_overrides=[
            Parameter("diagnostics_period", value=0.1),
            Parameter("stale_timeout", value=0.6),
        ],
    )
    arrays: list[DiagnosticArray] = []
    h.driver.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 50)
    try:
        for k in range(8):
            h.send_good(100.0 + k / 40.0)  # stamps at 40 Hz, whatever the wall clock does
        bad_scan = bad(**BAD_SCANS["range_max_below_min"][0])
        bad_scan.header.stamp = stamp_from_seconds(100.2)
        h.send(bad_scan)

        def latest():
            return arrays[-1].status[0] if arrays else None

        assert spin_until(h.executor, lambda: latest() is not None and latest().level == WARN, 5.0)
        status = latest()
        values = {kv.key: kv.value for kv in status.values}
        assert status.name == "robot1/robot_mapper" and status.hardware_id == "robot1"
        assert values["rejected: range_limits"] == "1" and values["scans received"] == "9"
        assert float(values["scan rate (Hz)"]) == pytest.approx(
            8 / 0.2, rel=0.01
        )  # 9 stamps over 0.2 s
        assert arrays[-1].header.stamp == bad_scan.header.stamp  # the newest input's stamp
        h.send_good(100.225)
        assert spin_until(h.executor, lambda: latest().level == OK, 5.0)
        # Silence: STALE after stale_timeout (node clock), the counts stay.
        assert spin_until(h.executor, lambda: latest().level == STALE, 5.0)
        assert "no scan for" in latest().message
    finally:
        h.close()


def test_max_scan_rate_maps_every_nth_scan_of_a_fast_laser_and_counts_the_rest(
    ros_context,
) -> None:
    h = Harness(ros_context, parameter_overrides=[Parameter("max_scan_rate", value=10.0)])
    try:
        for k in range(12):  # 40 Hz stamps: 0, 4 and 8 are mapped
            msg = scan_to_msg(room_scan(), "robot1/laser", stamp_from_seconds(50.0 + k / 40.0))
            h.send(msg)
        assert h.mapper.scans_received == 12 and h.mapper.scans_skipped == 9
        assert h.mapper.mapper.scans_accepted == 3
        assert [seconds_from_stamp(m.header.stamp) for m in h.received] == pytest.approx(
            [50.0, 50.1, 50.2]
        )
    finally:
        h.close()


def test_a_burst_of_scans_while_the_mapper_is_busy_is_kept(harness: Harness) -> None:
    # 40 scans (a second of a 40 Hz laser) arrive while the mapper's thread is not free to
    # take them (here: not spun at all; live: a keyframe's work). Sensor-data QoS's own depth
    # of 5 would keep the last 5; the mapper's queue keeps all 40, and maps them in order.
    from multi_robot_mapper.ros.robot_mapper import SCAN_QUEUE_DEPTH

    assert SCAN_QUEUE_DEPTH >= 40
    before = harness.mapper.scans_received
    for k in range(40):
        stamp = stamp_from_seconds(100.0 + 0.025 * k)
        harness.scan_pub.publish(scan_to_msg(room_scan(), "robot1/laser", stamp))
    time.sleep(1.0)  # delivered into the subscription's queue, nothing taken yet
    assert spin_until(harness.executor, lambda: harness.mapper.scans_received - before == 40, 20.0)
    assert harness.mapper.scans_received - before == 40
