"""Conversions between ROS 2 messages and the core's plain arrays (no rclpy needed)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from sensor_msgs.msg import LaserScan
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import (
    quaternion_from_yaw,
    split_stamp,
    stamp_seconds,
    yaw_from_quaternion,
)
from multi_robot_mapper.core.local_mapping import Keyframe
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


PARTIAL_MAP_NAMESPACE = "partial_map"
PARTIAL_MAP_COLOR = (0.95, 0.45, 0.1, 1.0)


def pose_msg(pose: Sequence[float]) -> Pose:
    """A geometry_msgs/Pose from a planar pose ``(x, y, theta)`` (z = 0, rotation about z)."""
    x, y, theta = (float(v) for v in pose)
    qx, qy, qz, qw = (float(q) for q in quaternion_from_yaw(theta))
    msg = Pose()
    msg.position = Point(x=x, y=y, z=0.0)
    msg.orientation = Quaternion(x=qx, y=qy, z=qz, w=qw)
    return msg


def pose_from_msg(msg: Pose) -> FloatArray:
    """The planar pose ``(x, y, theta)`` of a geometry_msgs/Pose (inverse of :func:`pose_msg`)."""
    q = msg.orientation
    theta = float(yaw_from_quaternion(q.x, q.y, q.z, q.w))
    return np.array([msg.position.x, msg.position.y, theta], dtype=np.float64)


def pose_stamped(pose: Sequence[float], stamp: Time, frame_id: str) -> PoseStamped:
    """A PoseStamped of the planar pose ``(x, y, theta)`` in ``frame_id``."""
    msg = PoseStamped()
    msg.header = Header(frame_id=frame_id, stamp=stamp)
    msg.pose = pose_msg(pose)
    return msg


def keyframe_marker(keyframe: Keyframe, header: Header, width: float) -> Marker:
    """One keyframe as a LINE_LIST marker: ``id`` = keyframe index, ``pose`` = the keyframe's
    pose in the map frame, points = its segments in its own frame (two per segment).

    The keyframe's own stamp rides in ``text`` (``repr`` of the seconds, exact; RViz and
    Foxglove ignore ``text`` on line lists) because ``header.stamp`` is the map's stamp.
    """
    marker = segments_marker(
        keyframe.segments,
        header,
        namespace=PARTIAL_MAP_NAMESPACE,
        width=width,
        color=PARTIAL_MAP_COLOR,
        marker_id=int(keyframe.index),
    )
    marker.pose = pose_msg(keyframe.T_robotmap_keyframe)
    marker.text = repr(float(keyframe.stamp))
    return marker


def partial_map_markers(
    keyframes: Sequence[Keyframe], header_stamp: Time, frame_id: str, width: float
) -> MarkerArray:
    """The whole partial map as a MarkerArray: one :func:`keyframe_marker` per keyframe, each
    stamped ``header_stamp`` (the newest scan integrated) in the map frame ``frame_id``."""
    array = MarkerArray()
    array.markers = [
        keyframe_marker(kf, Header(frame_id=frame_id, stamp=header_stamp), width)
        for kf in keyframes
    ]
    return array


def piece_frame(map_frame: str, piece: int) -> str:
    """The frame of a piece of a robot's map: the robot's map frame for piece 0 (the first
    scan's), ``<map frame>_<piece>`` for a piece started when the robot was lost (``piece``:
    its first keyframe's index)."""
    return map_frame if piece == 0 else f"{map_frame}_{piece}"


def piece_of_frame(map_frame: str | None, frame: str) -> int:
    """The piece whose frame is ``frame`` (inverse of :func:`piece_frame`): 0 for the robot's
    map frame (or when ``map_frame`` is unknown), -1 for a frame that is neither."""
    if map_frame is None or frame == map_frame or not frame.startswith(map_frame + "_"):
        return 0
    suffix = frame[len(map_frame) + 1 :]
    return int(suffix) if suffix.isdigit() else -1


def keyframe_from_marker(marker: Marker, map_frame: str | None = None) -> Keyframe:
    """The keyframe a :func:`keyframe_marker` carries (the stamp from ``text``, else the
    header); its piece from its frame (:func:`piece_frame`) when ``map_frame`` is known."""
    try:
        stamp = float(marker.text)
    except ValueError:
        stamp = seconds_from_stamp(marker.header.stamp)
    piece = piece_of_frame(map_frame, marker.header.frame_id)
    return Keyframe(
        index=int(marker.id),
        stamp=stamp,
        T_robotmap_keyframe=pose_from_msg(marker.pose),
        segments=segments_from_marker(marker),
        piece=piece,
    )


def keyframes_from_markers(array: MarkerArray) -> list[Keyframe]:
    """The keyframes of a ``partial_map`` MarkerArray (inverse of :func:`partial_map_markers`).

    Only ``ADD`` line lists of the ``partial_map`` namespace count; sorted by keyframe index.
    Keyframe 0's frame is the robot's map frame; a keyframe in ``<map frame>_<k>`` is in piece
    k (:func:`piece_frame`).
    """
    markers = [
        m
        for m in array.markers
        if m.ns == PARTIAL_MAP_NAMESPACE and m.type == Marker.LINE_LIST and m.action == Marker.ADD
    ]
    first = [m.header.frame_id for m in markers if int(m.id) == 0]
    map_frame = first[0] if first else None
    keyframes = [keyframe_from_marker(m, map_frame) for m in markers]
    return sorted(keyframes, key=lambda kf: kf.index)


@dataclasses.dataclass(frozen=True)
class PartialMapContents:
    """A ``partial_map`` MarkerArray as the merger uses it."""

    segments: FloatArray  # (N, 4) in the robot's map frame (each keyframe's moved by its pose)
    keyframe_poses: FloatArray  # (K, 3) where the robot's laser stood: its free space's viewpoints
    session: float | None  # stamp of keyframe 0 (s): a new value means the robot started again
    stamp: Time | None  # header stamp (the newest scan in the map); None for an empty array
    frame_id: str  # the robot's map frame ("" for an empty array)
    # every keyframe of every piece (what the joint merger matches; a piece with a frame of
    # its own is a map of its own to it)
    keyframes: list[Keyframe] = dataclasses.field(default_factory=list)


def partial_map_contents(msg: MarkerArray) -> PartialMapContents:
    """The segments, keyframe poses and session of a ``partial_map`` MarkerArray: its main
    piece (the robot's map frame); keyframes of a piece started when the robot was lost lie
    in frames of their own until the robot's mapper joins them. ``keyframes`` holds every
    keyframe of every piece (bad keyframes, with non-finite numbers, left out)."""
    every = [
        kf
        for kf in keyframes_from_markers(msg)
        if kf.piece >= 0
        and np.isfinite(kf.T_robotmap_keyframe).all()
        and np.isfinite(kf.segments).all()
    ]
    keyframes = [kf for kf in every if kf.piece == 0]
    pieces = [
        se2.transform_segments(se2.matrix_from_pose(*kf.T_robotmap_keyframe), kf.segments)
        for kf in keyframes
        if len(kf.segments)
    ]
    poses = np.array([kf.T_robotmap_keyframe for kf in keyframes], dtype=np.float64)
    first = next((kf for kf in every if kf.index == 0), None)
    markers = msg.markers
    stamps = [m.header.stamp for m in markers]
    return PartialMapContents(
        segments=np.vstack(pieces) if pieces else np.zeros((0, 4)),
        keyframe_poses=poses.reshape(-1, 3),
        session=None if first is None else float(first.stamp),
        stamp=max(stamps, key=lambda s: (s.sec, s.nanosec)) if stamps else None,
        frame_id=next((m.header.frame_id for m in markers if int(m.id) == 0), ""),
        keyframes=every,
    )
