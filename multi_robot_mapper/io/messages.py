"""Conversions between ROS 2 messages and the core's plain arrays (no rclpy needed)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from sensor_msgs.msg import LaserScan
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from multi_robot_mapper.core.geometry import split_stamp, stamp_seconds
from multi_robot_mapper.core.scan import LaserScanData

FloatArray = np.typing.NDArray[np.float64]


def scan_from_msg(msg: LaserScan) -> LaserScanData:
    """The geometry of a LaserScan message as plain values (ranges copied to float64)."""
    # Only the length is checked downstream: a zero-copy view of the float32 values.
    intensities = np.asarray(msg.intensities) if len(msg.intensities) else None
    return LaserScanData(
        ranges=np.asarray(msg.ranges, dtype=np.float64),
        angle_min=float(msg.angle_min),
        angle_max=float(msg.angle_max),
        angle_increment=float(msg.angle_increment),
        range_min=float(msg.range_min),
        range_max=float(msg.range_max),
        intensities=intensities,
    )


def scan_to_msg(
    scan: LaserScanData, frame_id: str, stamp: Time, scan_time: float = 0.0
) -> LaserScan:
    """A LaserScan message from plain values (simulator, bag import, tests)."""
    msg = LaserScan()
    msg.header = Header(frame_id=frame_id, stamp=stamp)
    msg.angle_min = float(scan.angle_min)
    msg.angle_max = float(scan.angle_max)
    msg.angle_increment = float(scan.angle_increment)
    msg.scan_time = float(scan_time)
    n = len(scan.ranges)
    msg.time_increment = float(scan_time / n) if n and scan_time else 0.0
    msg.range_min = float(scan.range_min)
    msg.range_max = float(scan.range_max)
    msg.ranges = np.asarray(scan.ranges, dtype=np.float32).tolist()
    if scan.intensities is not None:
        msg.intensities = np.asarray(scan.intensities, dtype=np.float32).tolist()
    return msg


def stamp_from_seconds(seconds: float) -> Time:
    """A builtin_interfaces/Time from seconds."""
    sec, nanosec = split_stamp(seconds)
    return Time(sec=sec, nanosec=nanosec)


def seconds_from_stamp(stamp: Time) -> float:
    """Seconds of a builtin_interfaces/Time."""
    return stamp_seconds(stamp.sec, stamp.nanosec)


def segments_marker(
    segments: FloatArray,
    header: Header,
    namespace: str,
    width: float,
    color: Sequence[float] = (0.1, 0.6, 1.0, 1.0),
    marker_id: int = 0,
) -> Marker:
    """A LINE_LIST marker with one line per row ``[x1, y1, x2, y2]`` of ``segments``."""
    marker = Marker()
    marker.header = header
    marker.ns = namespace
    marker.id = marker_id
    marker.type = Marker.LINE_LIST
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.scale.x = float(width)
    marker.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
    ends = np.asarray(segments, dtype=np.float64).reshape(-1, 2).tolist()
    marker.points = [Point(x=x, y=y, z=0.0) for x, y in ends]
    return marker


def segments_from_marker(marker: Marker) -> FloatArray:
    """The ``(N, 4)`` segments of a LINE_LIST marker (inverse of :func:`segments_marker`)."""
    ends = np.array([(p.x, p.y) for p in marker.points], dtype=np.float64).reshape(-1, 4)
    return ends
