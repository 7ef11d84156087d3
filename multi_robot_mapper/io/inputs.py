"""What other programs send the nodes, checked once, at the boundary.

Each check returns clean data (finite numbers, sizes within the limits given) or raises
:class:`InputError` naming the kind of problem (a stable key for counters and throttled
warnings), the message field at fault and what was wrong, before any work is done with it.
The core never sees NaN, inf or an unbounded size. A LaserScan's own fields are checked by
:func:`multi_robot_mapper.core.scan.scan_points`, and each scan against its robot's own stream
(geometry, stamps, copied ranges) by :class:`multi_robot_mapper.core.scan_stream.
ScanStreamGuard`: both in the core, the same for the node and for replay.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose
from numpy.typing import NDArray
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import yaw_from_quaternion
from multi_robot_mapper.io.messages import PARTIAL_MAP_NAMESPACE

FloatArray = NDArray[np.float64]


class InputError(ValueError):
    """Input that is not used: ``kind`` (counter key), ``field`` (the message field at fault)."""

    def __init__(self, kind: str, field: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind
        self.field = field
        self.message = message


# --- partial maps ----------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class MapLimits:
    """Sizes a partial map may have; anything larger is refused before it is read."""

    max_keyframes: int
    max_segments: int
    max_extent: float  # every point and keyframe within this of the robot map's origin, m


@dataclasses.dataclass(frozen=True)
class PartialMap:
    """A robot's partial map as the merger uses it, every number finite."""

    segments: FloatArray  # (N, 4) in the robot's map frame
    keyframe_poses: FloatArray  # (K, 3) T_robotmap_keyframe: the viewpoints of its free space
    stamp: Time  # the newest header stamp of the markers
    frame_id: str  # the robot's map frame


def partial_map_from_msg(msg: MarkerArray, limits: MapLimits) -> PartialMap:
    """A ``partial_map`` MarkerArray (one LINE_LIST per keyframe, see ``io/messages.py``) checked
    and converted; raises :class:`InputError`."""
    keyframes = _keyframe_markers(msg.markers, limits)
    counts = _point_counts(keyframes, limits)
    poses = np.array([_planar_pose(m.pose, f"markers[{i}].pose") for i, m in enumerate(keyframes)])
    segments = _segments_in_map_frame(keyframes, counts, poses)
    extent = max(
        float(np.abs(segments).max(initial=0.0)), float(np.abs(poses[:, :2]).max(initial=0.0))
    )
    if not extent <= limits.max_extent:
        raise InputError(
            "map_too_large",
            "markers[].pose/points",
            f"the map reaches {extent:.3g} m from its origin, more than max_map_extent "
            f"({limits.max_extent:g} m)",
        )
    stamp = max((m.header.stamp for m in keyframes), key=lambda t: (t.sec, t.nanosec))
    return PartialMap(segments, poses, stamp, keyframes[0].header.frame_id)


def _keyframe_markers(markers: Sequence[Marker], limits: MapLimits) -> list[Marker]:
    """The keyframe markers of a partial map: at least one, each id once, and no more markers
    in all than ``max_keyframes``."""
    if len(markers) > limits.max_keyframes:
        raise InputError(
            "too_many_keyframes",
            "markers",
            f"{len(markers)} keyframe markers, more than max_keyframes_per_map "
            f"({limits.max_keyframes})",
        )
    keyframes = [
        m
        for m in markers
        if m.ns == PARTIAL_MAP_NAMESPACE and m.type == Marker.LINE_LIST and m.action == Marker.ADD
    ]
    if not keyframes:
        raise InputError(
            "empty_map", "markers", "no keyframe marker (ns 'partial_map', ADD LINE_LIST)"
        )
    ids = [m.id for m in keyframes]
    if len(set(ids)) != len(ids):
        raise InputError(
            "duplicate_keyframes",
            "markers[].id",
            f"{len(ids) - len(set(ids))} keyframe markers repeat an id (a map holds each once)",
        )
    return keyframes


def _point_counts(keyframes: list[Marker], limits: MapLimits) -> list[int]:
    """Each keyframe marker's number of points: even (segment ends come in pairs), and no
    more than ``max_segments`` segments in all."""
    counts = [len(m.points) for m in keyframes]
    if sum(counts) > 2 * limits.max_segments:
        raise InputError(
            "too_many_segments",
            "markers[].points",
            f"{sum(counts) // 2} segments, more than max_segments_per_map ({limits.max_segments})",
        )
    odd = next((i for i, c in enumerate(counts) if c % 2), None)
    if odd is not None:
        raise InputError(
            "odd_points",
            f"markers[{odd}].points",
            f"a LINE_LIST of {counts[odd]} points (segments need pairs)",
        )
    return counts


def _segments_in_map_frame(
    keyframes: list[Marker], counts: list[int], poses: FloatArray
) -> FloatArray:
    """Every keyframe's segments (its points, finite, in pairs) in the robot's map frame."""
    ends = np.array([(p.x, p.y) for m in keyframes for p in m.points], dtype=np.float64).reshape(
        -1, 2
    )
    if not np.isfinite(ends).all():
        bad = int(np.repeat(np.arange(len(keyframes)), counts)[~np.isfinite(ends).all(axis=1)][0])
        raise InputError("non_finite_points", f"markers[{bad}].points", "a point holds NaN or inf")
    # Each keyframe's segments are in its own frame: placed by the keyframe's pose.
    bounds = np.concatenate(([0], np.cumsum(counts) // 2))
    local = ends.reshape(-1, 4)
    pieces = [
        se2.transform_segments(se2.matrix_from_pose(*pose), local[start:stop])
        for pose, start, stop in zip(poses, bounds[:-1], bounds[1:], strict=True)
        if stop > start
    ]
    return np.vstack(pieces) if pieces else np.zeros((0, 4))


def _planar_pose(pose: Pose, field: str) -> tuple[float, float, float]:
    """``(x, y, theta)`` of a Pose whose numbers are finite and whose quaternion has a length."""
    p, q = pose.position, pose.orientation
    values = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
    if not all(math.isfinite(v) for v in values):
        raise InputError("non_finite_pose", field, "the pose holds NaN or inf")
    if q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w < 1e-12:
        raise InputError("bad_orientation", field, "the orientation quaternion is zero")
    return (float(p.x), float(p.y), float(yaw_from_quaternion(q.x, q.y, q.z, q.w)))


def pose_from_checked_msg(pose: Pose, max_extent: float, field: str = "pose") -> FloatArray:
    """A robot's pose message (``T_robotmap_laser``) as ``(x, y, theta)``, finite and within
    ``max_extent`` of the map's origin; raises :class:`InputError`."""
    x, y, theta = _planar_pose(pose, field)
    if max(abs(x), abs(y)) > max_extent:
        raise InputError(
            "map_too_large", field, f"the pose lies {max(abs(x), abs(y)):.3g} m from the origin"
        )
    return np.array([x, y, theta], dtype=np.float64)
