"""What one scan's beams say about the other's walls: points seen through, with known answers."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core.matching import (
    seen_through,
)
from multi_robot_mapper.core.scan import LaserScanData


def test_seen_through_marks_points_in_front_of_a_return() -> None:
    view = LaserScanData(np.full(181, 2.0), -np.pi / 2, np.pi / 2, np.pi / 180, 0.1, 10.0)
    points = np.array([[1.0, 0.0], [1.9, 0.0], [3.0, 0.0], [-1.0, 0.0]])
    np.testing.assert_array_equal(seen_through(view, points, 0.15), [True, False, False, False])


def test_each_view_judges_by_its_own_beams_when_many_are_judged_in_turn() -> None:
    # The beams of the views judged last are kept (a keyframe's scan is judged many times
    # per match): each view still answers from its own ranges, whatever was judged before.
    points = np.array([[1.0, 0.0], [3.0, 0.0], [4.95, 0.0]])
    walls = {2.0: [True, False, False], 5.0: [True, True, False], 3.05: [True, False, False]}
    for spread in (0, 1, 0):
        for distance, expected in walls.items():
            view = LaserScanData(
                np.full(181, distance), -np.pi / 2, np.pi / 2, np.pi / 180, 0.1, 10.0
            )
            for _ in range(2):  # the second time from the kept beams
                np.testing.assert_array_equal(seen_through(view, points, 0.15, spread), expected)


def test_seen_through_ignores_a_point_beside_a_grazing_return() -> None:
    ranges = np.full(181, 5.0)
    ranges[91] = 1.0  # the beam next to the point's bearing stops short
    view = LaserScanData(ranges, -np.pi / 2, np.pi / 2, np.pi / 180, 0.1, 10.0)
    point = np.array([[2.0, 0.0]])  # bearing 0: beam 90
    assert seen_through(view, point, 0.15, spread=0)[0]
    assert not seen_through(view, point, 0.15, spread=1)[0]
