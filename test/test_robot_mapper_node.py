"""A real robot_mapper node spun in-process: segments out, bad scans survived, parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker

from multi_robot_mapper.core.config import ConfigError
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import polygon, raycast
from multi_robot_mapper.io.messages import scan_to_msg, segments_from_marker, stamp_from_seconds
from multi_robot_mapper.ros.robot_mapper import RobotMapper
from multi_robot_mapper.ros.testing import spin_until

pytestmark = pytest.mark.ros

ROOM = polygon([(-2.0, -1.5), (3.0, -1.5), (3.0, 2.5), (-2.0, 2.5)])


def room_scan(beams: int = 361) -> LaserScanData:
    angles = np.linspace(-math.radians(135), math.radians(135), beams)
    ranges = raycast(ROOM, (-1.0, 0.4, 0.05), angles, 30.0)
    return LaserScanData(ranges, angles[0], angles[-1], angles[1] - angles[0], 0.05, 30.0)


class Harness:
    """One robot_mapper in namespace /robot1 and a driver node talking to it over real topics."""

    def __init__(self, context, **node_kwargs) -> None:
        self.mapper = RobotMapper(context=context, namespace="robot1", **node_kwargs)
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
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.mapper)
        self.executor.add_node(self.driver)
        assert spin_until(
            self.executor,
            lambda: (
                self.scan_pub.get_subscription_count() > 0
                and self.mapper.count_subscribers("scan_segments") > 0
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
    assert {"/robot1/scan", "/robot1/scan_segments"} <= names


def bad(base: LaserScanData | None = None, **changes) -> LaserScan:
    scan = base or room_scan()
    msg = scan_to_msg(scan, "robot1/laser", stamp_from_seconds(1.0))
    for key, value in changes.items():
        setattr(msg, key, value)
    return msg


BAD_SCANS = {
    "nan": (dict(ranges=[float("nan")] * 100 + [2.0] * 261), "non_finite_ranges", "NaN"),
    "inf": (dict(ranges=[float("inf")] * 361), "non_finite_ranges", "inf"),
    "all_invalid": (dict(ranges=[0.0] * 361), "no_valid_ranges", "none of the 361 ranges"),
    "zero_beams": (dict(ranges=[]), "no_beams", "no beams"),
    "ten_thousand_beams": (dict(ranges=[2.0] * 10_000), "beam_span", "10000 beams"),
    "negative_increment": ({}, "negative_increment", "clockwise"),
    "intensities_length": (dict(intensities=[1.0] * 7), "intensities_length", "intensities has 7"),
    "angle_max_below_min": (dict(angle_max=-3.0), "angle_order", "opposite sign"),
    "range_max_below_min": (dict(range_min=5.0, range_max=1.0), "range_limits", "range_max"),
}


@pytest.mark.parametrize("case", sorted(BAD_SCANS))
def test_bad_scan_warns_once_names_the_problem_and_the_node_goes_on(
    harness: Harness, case: str
) -> None:
    changes, kind, words = BAD_SCANS[case]
    if case == "negative_increment":
        scan = room_scan()
        reversed_scan = LaserScanData(
            scan.ranges[::-1].copy(),
            scan.angle_max,
            scan.angle_min,
            -scan.angle_increment,
            0.05,
            30.0,
        )
        msg = bad(reversed_scan)
    else:
        msg = bad(**changes)
    harness.send(msg)
    harness.send(msg)  # the same problem again within the period: throttled
    matching = [line for line in harness.logged if words in line]
    assert len(matching) == 1, harness.logged
    assert harness.mapper.warnings.counts[kind] == 2
    marker = harness.send_good(2.0)  # and the next good scan is processed as usual
    assert len(segments_from_marker(marker)) == 5


def test_negative_increment_scan_gives_the_same_segments(harness: Harness) -> None:
    forward = segments_from_marker(harness.send_good(3.0))
    scan = room_scan()
    reversed_scan = LaserScanData(
        scan.ranges[::-1].copy(), scan.angle_max, scan.angle_min, -scan.angle_increment, 0.05, 30.0
    )
    backward = harness.answer_to(bad(reversed_scan))
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
