"""What other programs send the nodes, checked at the boundary (io/inputs.py), on messages made
by hand: a partial map's keyframes placed by their poses with exact answers, and each kind of
bad map or pose refused by kind and field before any work."""

from __future__ import annotations

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.io.inputs import (
    InputError,
    MapLimits,
    partial_map_from_msg,
    pose_from_checked_msg,
)
from multi_robot_mapper.io.messages import PARTIAL_MAP_NAMESPACE

LIMITS = MapLimits(max_keyframes=4, max_segments=3, max_extent=100.0)


def pose(x: float, y: float, theta: float) -> Pose:
    msg = Pose()
    msg.position.x, msg.position.y = x, y
    msg.orientation.z, msg.orientation.w = math.sin(theta / 2), math.cos(theta / 2)
    return msg


def keyframe(index: int, at: Pose, ends: list[tuple[float, float]], sec: int = 5) -> Marker:
    marker = Marker(ns=PARTIAL_MAP_NAMESPACE, id=index, type=Marker.LINE_LIST, action=Marker.ADD)
    marker.header.frame_id = "robot1/map"
    marker.header.stamp = Time(sec=sec, nanosec=index)
    marker.pose = at
    marker.points = [Point(x=x, y=y) for x, y in ends]
    return marker


def two_keyframes() -> list[Marker]:
    return [
        keyframe(0, pose(0.0, 0.0, 0.0), [(1.0, 0.0), (1.0, 2.0)]),
        # A quarter turn at (10, 0): its wall from (1, 0) to (1, 2) lies at x 8..10, y 1.
        keyframe(1, pose(10.0, 0.0, math.pi / 2), [(1.0, 0.0), (1.0, 2.0)], sec=7),
    ]


def test_each_keyframes_segments_are_placed_by_its_pose() -> None:
    other = Marker(ns="something_else", id=0, type=Marker.TEXT_VIEW_FACING)
    partial = partial_map_from_msg(MarkerArray(markers=[*two_keyframes(), other]), LIMITS)
    np.testing.assert_allclose(
        partial.segments, [[1.0, 0.0, 1.0, 2.0], [10.0, 1.0, 8.0, 1.0]], atol=1e-12
    )
    np.testing.assert_allclose(partial.keyframe_poses, [[0, 0, 0], [10, 0, math.pi / 2]])
    assert (partial.stamp.sec, partial.stamp.nanosec) == (7, 1)  # the newest marker's
    assert partial.frame_id == "robot1/map"


def bad(markers: list[Marker], limits: MapLimits = LIMITS) -> InputError:
    with pytest.raises(InputError) as refused:
        partial_map_from_msg(MarkerArray(markers=markers), limits)
    return refused.value


def test_each_kind_of_bad_map_is_refused_by_kind_and_field() -> None:
    good = two_keyframes
    assert (bad([]).kind, bad([]).field) == ("empty_map", "markers")
    assert bad(good() * 3).kind == "too_many_keyframes"  # 6 markers, at most 4
    assert bad(good() + good()[:1]).kind == "duplicate_keyframes"
    many = [keyframe(0, pose(0, 0, 0), [(0.0, 0.0), (1.0, 0.0)] * 4)]
    assert (bad(many).kind, str(bad(many))) == (
        "too_many_segments",
        "4 segments, more than max_segments_per_map (3)",
    )
    odd = good()
    odd[1].points = odd[1].points[:1]
    assert (bad(odd).kind, bad(odd).field) == ("odd_points", "markers[1].points")
    nan = good()
    nan[1].points[0].y = math.nan
    assert (bad(nan).kind, bad(nan).field) == ("non_finite_points", "markers[1].points")
    unturned = good()
    unturned[0].pose.orientation.w = 0.0
    assert (bad(unturned).kind, bad(unturned).field) == ("bad_orientation", "markers[0].pose")
    far = bad(good(), MapLimits(4, 3, max_extent=9.0))
    assert far.kind == "map_too_large" and "reaches 10 m" in str(far)


def test_a_pose_is_a_finite_planar_triple_within_the_extent() -> None:
    np.testing.assert_allclose(pose_from_checked_msg(pose(3.0, -4.0, 0.5), 10.0), [3, -4, 0.5])
    with pytest.raises(InputError) as far:
        pose_from_checked_msg(pose(3.0, -40.0, 0.0), 10.0)
    assert far.value.kind == "map_too_large" and str(far.value).endswith("40 m from the origin")
    broken = pose(0.0, 0.0, 0.0)
    broken.position.z = math.inf
    with pytest.raises(InputError) as infinite:
        pose_from_checked_msg(broken, 10.0, field="robot2/pose")
    assert (infinite.value.kind, infinite.value.field) == ("non_finite_pose", "robot2/pose")
