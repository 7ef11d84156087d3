"""Shared geometry (core/geometry.py) with known answers: stamps split without losing digits,
yaw and quaternions, point-to-segment distances, concatenated ranges, points along segments."""

from __future__ import annotations

import math

import numpy as np
import pytest

from multi_robot_mapper.core.geometry import (
    point_segment_distance,
    quaternion_from_yaw,
    ranges_index,
    sample_segments,
    split_stamp,
    stamp_seconds,
    yaw_from_quaternion,
)


def test_a_stamp_splits_into_seconds_and_rounded_nanoseconds_with_the_carry_kept() -> None:
    assert split_stamp(1.5) == (1, 500_000_000)
    assert split_stamp(-0.25) == (-1, 750_000_000)  # ROS stamps: nanosec is never negative
    assert split_stamp(2.9999999999) == (3, 0)  # rounds up to the next second
    # An epoch stamp keeps its microseconds (seconds * 1e9 first would not).
    sec, nanosec = split_stamp(1_700_000_000.123456)
    assert sec == 1_700_000_000 and abs(nanosec - 123_456_000) <= 1_000
    assert stamp_seconds(*split_stamp(12.000000001)) == pytest.approx(12.000000001, abs=1e-12)


def test_yaw_and_quaternion_are_inverse_and_scale_does_not_matter() -> None:
    yaws = np.array([-3.0, -math.pi / 2, 0.0, 0.3, math.pi / 2, 3.0])
    x, y, z, w = quaternion_from_yaw(yaws)
    np.testing.assert_allclose(yaw_from_quaternion(x, y, z, w), yaws, atol=1e-12)
    # A quarter turn: (0, 0, sin 45°, cos 45°).
    np.testing.assert_allclose(
        np.hstack(quaternion_from_yaw(math.pi / 2)), [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)]
    )
    # Not unit, even huge: the same yaw.
    assert yaw_from_quaternion(0.0, 0.0, 1e300, 1e300) == pytest.approx(math.pi / 2)
    assert yaw_from_quaternion(0.0, 0.0, 3.0, 3.0) == pytest.approx(math.pi / 2)
    assert yaw_from_quaternion(0.0, 0.0, 0.0, 0.0) == 0.0  # no rotation at all: yaw 0


def test_point_to_segment_distance_is_to_the_nearest_point_of_the_segment() -> None:
    # Segment (0, 0)-(4, 0); points beside it, beyond each end, on it; and a degenerate segment.
    px = np.array([2.0, -3.0, 7.0, 1.0])
    py = np.array([1.5, 4.0, -4.0, 0.0])
    distance = point_segment_distance(px, py, 0.0, 0.0, 4.0, 0.0)
    np.testing.assert_allclose(distance, [1.5, 5.0, 5.0, 0.0])
    assert point_segment_distance(np.array(3.0), np.array(4.0), 0.0, 0.0, 0.0, 0.0) == 5.0
    # Shapes broadcast: three points against two segments.
    grid = point_segment_distance(
        px[:3, None], py[:3, None], np.zeros(2), np.zeros(2), np.array([4.0, 0.0]), [0.0, 4.0]
    )
    assert grid.shape == (3, 2)
    np.testing.assert_allclose(grid[:, 1], [2.0, 3.0, math.hypot(7.0, 4.0)])


def test_ranges_index_concatenates_the_ranges_with_their_owner_and_start() -> None:
    index, owner, start = ranges_index(np.array([3, 0, 10]), np.array([5, 3, 11]))
    assert index.tolist() == [3, 4, 0, 1, 2, 10]
    assert owner.tolist() == [0, 0, 1, 1, 1, 2]
    assert start.tolist() == [0, 2, 5]
    # As np.add.reduceat's offsets: the sums of each range.
    assert np.add.reduceat(index, start).tolist() == [7, 3, 10]


def test_points_along_segments_are_spaced_with_both_ends_and_at_least_two_each() -> None:
    segments = np.array([[0.0, 0.0, 1.0, 0.0], [5.0, 5.0, 5.0, 5.1], [0.0, 0.0, 0.0, -0.9]])
    points, owner = sample_segments(segments, 0.25)
    assert owner.tolist() == [0] * 5 + [1] * 2 + [2] * 5
    np.testing.assert_allclose(
        points[:5], [[0.0, 0.0], [0.25, 0.0], [0.5, 0.0], [0.75, 0.0], [1, 0]]
    )
    np.testing.assert_allclose(points[5:7], [[5.0, 5.0], [5.0, 5.1]])  # shorter than the spacing
    gaps = np.hypot(*np.diff(points[7:], axis=0).T)
    np.testing.assert_allclose(gaps, 0.225)  # 0.9 m in four equal steps, none over 0.25 m
    np.testing.assert_allclose(points[[7, 11]], [[0.0, 0.0], [0.0, -0.9]])
