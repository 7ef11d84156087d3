"""Message builders: partial map MarkerArray and PoseStamped, known answers and round trips."""

from __future__ import annotations

import math

import numpy as np
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.io.messages import (
    keyframes_from_markers,
    partial_map_markers,
    pose_from_msg,
    pose_stamped,
    seconds_from_stamp,
    stamp_from_seconds,
)


def keyframes() -> list[Keyframe]:
    rng = np.random.default_rng(3)
    return [
        Keyframe(0, 1_000_000_000.0, np.zeros(3), rng.uniform(-5, 5, (4, 4))),
        Keyframe(1, 1_000_000_000.725, np.array([0.8, -0.3, 0.4]), rng.uniform(-5, 5, (7, 4))),
        Keyframe(2, 1_000_000_001.4, np.array([1.9, 0.2, -2.9]), np.zeros((0, 4))),
        Keyframe(3, 1_000_000_002.05, np.array([-3.0, 4.5, math.pi]), rng.uniform(-5, 5, (1, 4))),
    ]


def test_partial_map_layout_one_line_list_per_keyframe() -> None:
    frames = keyframes()
    array = partial_map_markers(frames, stamp_from_seconds(1_000_000_002.5), "robot1/map", 0.05)
    assert len(array.markers) == len(frames)
    for marker, kf in zip(array.markers, frames, strict=True):
        assert marker.id == kf.index
        assert marker.ns == "partial_map"
        assert marker.type == Marker.LINE_LIST and marker.action == Marker.ADD
        assert marker.header.frame_id == "robot1/map"
        assert seconds_from_stamp(marker.header.stamp) == 1_000_000_002.5
        assert marker.scale.x == 0.05 and marker.color.a > 0.0
        assert len(marker.points) == 2 * len(kf.segments)
        if len(kf.segments):
            assert marker.points[1].x == kf.segments[0, 2]
            assert marker.points[1].y == kf.segments[0, 3]
        p = marker.pose
        assert (p.position.x, p.position.y, p.position.z) == (*kf.T_robotmap_keyframe[:2], 0.0)
        yaw = 2.0 * math.atan2(p.orientation.z, p.orientation.w)
        assert math.isclose(
            math.remainder(yaw - kf.T_robotmap_keyframe[2], 2 * math.pi), 0.0, abs_tol=1e-12
        )
        q = p.orientation
        assert math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0)


def test_keyframes_round_trip_through_markers() -> None:
    frames = keyframes()
    array = partial_map_markers(frames, stamp_from_seconds(5.0), "map", 0.03)
    back = keyframes_from_markers(array)
    assert [kf.index for kf in back] == [kf.index for kf in frames]
    for got, want in zip(back, frames, strict=True):
        assert got.stamp == want.stamp  # exact, although the header carries the map's stamp
        np.testing.assert_array_equal(got.segments, want.segments)
        assert got.segments.shape == (len(want.segments), 4)
        np.testing.assert_array_equal(got.T_robotmap_keyframe[:2], want.T_robotmap_keyframe[:2])
        dtheta = math.remainder(got.T_robotmap_keyframe[2] - want.T_robotmap_keyframe[2], math.tau)
        assert abs(dtheta) < 1e-12  # the quaternion costs at most an ulp or two


def test_keyframes_from_markers_ignores_other_markers_and_sorts() -> None:
    array = partial_map_markers(keyframes(), stamp_from_seconds(5.0), "map", 0.03)
    stray = Marker(ns="scan_segments", id=9, type=Marker.LINE_LIST)
    delete = Marker(ns="partial_map", action=Marker.DELETEALL)
    shuffled = MarkerArray(markers=[delete, array.markers[3], stray, array.markers[0]])
    assert [kf.index for kf in keyframes_from_markers(shuffled)] == [0, 3]
    assert keyframes_from_markers(MarkerArray()) == []


def test_pose_stamped_known_answer() -> None:
    msg = pose_stamped((1.5, -2.0, math.pi / 2), stamp_from_seconds(42.25), "robot1/map")
    assert msg.header.frame_id == "robot1/map"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (42, 250_000_000)
    q = msg.pose.orientation
    assert (q.x, q.y) == (0.0, 0.0)
    assert math.isclose(q.z, math.sqrt(0.5)) and math.isclose(q.w, math.sqrt(0.5))
    np.testing.assert_allclose(pose_from_msg(msg.pose), [1.5, -2.0, math.pi / 2], atol=1e-15)
