"""Live runs' plain data (ros/live.py): every robot's scans played as one stream in stamp
order, and a ``global_map`` message read back by robot, with known answers."""

from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.io.bags import TimedScan
from multi_robot_mapper.io.messages import pose_msg, seconds_from_stamp, stamp_from_seconds
from multi_robot_mapper.ros.live import global_map_view, timeline
from multi_robot_mapper.ros.markers import GLOBAL_MAP_NAMESPACE


def scan(reading: float) -> LaserScanData:
    return LaserScanData(np.full(3, reading), -0.1, 0.1, 0.1, 0.1, 30.0)


def test_the_robots_scans_are_played_in_stamp_order_as_messages() -> None:
    runs = {
        "robot2": [
            TimedScan(1.0, "robot2/laser", scan(2.0)),
            TimedScan(3.0, "robot2/laser", scan(2.5)),
        ],
        "robot1": [
            TimedScan(0.5, "robot1/laser", scan(1.0)),
            TimedScan(3.0, "robot1/laser", scan(1.5)),
        ],
    }
    played = list(timeline(runs, scan_time=0.025))
    assert [(stamp, robot) for stamp, robot, _ in played] == [
        (0.5, "robot1"),
        (1.0, "robot2"),
        (3.0, "robot1"),  # one stamp: by robot name
        (3.0, "robot2"),
    ]
    last = played[-1][2]
    assert last.header.frame_id == "robot2/laser" and seconds_from_stamp(last.header.stamp) == 3.0
    assert list(last.ranges) == [2.5] * 3 and last.scan_time == 0.025


def line_list(robot: str, index: int, x: float, y: float, theta: float, ends: list) -> Marker:
    marker = Marker(ns=f"{GLOBAL_MAP_NAMESPACE}/{robot}", id=index, type=Marker.LINE_LIST)
    marker.pose = pose_msg(np.array([x, y, theta]))
    marker.points = [Point(x=px, y=py) for px, py in ends]
    marker.header.stamp = stamp_from_seconds(12.5)
    return marker


def test_a_global_map_is_read_back_by_robot_in_the_map_frame() -> None:
    wall = [(1.0, 0.0), (1.0, 2.0)]
    arrow = Marker(ns="robots", id=7, type=Marker.ARROW, pose=pose_msg(np.array([4.0, 5.0, 0.5])))
    name = Marker(ns="robots", id=7, type=Marker.TEXT_VIEW_FACING, text="robot1")
    unnamed = Marker(ns="robots", id=8, type=Marker.ARROW, pose=pose_msg(np.zeros(3)))
    gone = line_list("robot3", 0, 0.0, 0.0, 0.0, wall)
    gone.action = Marker.DELETE
    markers = [
        line_list("robot1", 0, 0.0, 0.0, 0.0, wall),
        line_list("robot1", 1, 10.0, 0.0, math.pi / 2, wall),  # at (10, 0), a quarter turn
        line_list("robot2", 0, 0.0, -3.0, math.pi, wall),
        arrow,
        name,
        unnamed,
        gone,
    ]
    view = global_map_view(MarkerArray(markers=markers), received_s=42.0)
    assert view.received_s == 42.0 and seconds_from_stamp(view.stamp) == 12.5
    assert sorted(view.segments) == ["robot1", "robot2"]  # a deleted marker shows nothing
    np.testing.assert_allclose(view.segments["robot1"], [[1, 0, 1, 2], [10, 1, 8, 1]], atol=1e-12)
    np.testing.assert_allclose(view.segments["robot2"], [[-1, -3, -1, -5]], atol=1e-12)
    np.testing.assert_allclose(view.poses["robot1"], [4.0, 5.0, 0.5])
    np.testing.assert_allclose(view.poses["robot #8"], [0.0, 0.0, 0.0])
