"""The merger's message builders without a node (ros/markers.py): the TF of placed pieces."""

from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time

from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.ros.markers import piece_transforms


def test_every_placed_other_piece_gets_its_own_frame_in_map() -> None:
    result = MergeResult(
        robots=["robot1", "robot2"],
        placements={"robot1": (0.0, 0.0, 0.0), "robot2": None},
        reference="robot1",
        links=[],
        pairs={},
        segments=np.zeros((0, 4)),
        segment_robot=np.zeros(0, dtype=np.int64),
        timings={},
        stats={},
    )
    # robot1's piece 2 placed 3 m along x, turned a quarter; piece 0 is the robot's own frame.
    result.frames = {"robot1": {0: (0.0, 0.0, 0.0), 2: (3.0, 0.0, math.pi / 2)}}
    stamp = Time(sec=7, nanosec=5)
    transforms = piece_transforms(result, {"robot1": "r1/map"}, stamp, "map")
    assert list(transforms) == ["r1/map_2"]
    transform = transforms["r1/map_2"]
    assert transform.child_frame_id == "r1/map_2" and transform.header.frame_id == "map"
    assert transform.header.stamp == stamp
    assert transform.transform.translation.x == 3.0 and transform.transform.translation.y == 0.0
    q = transform.transform.rotation
    assert math.isclose(2.0 * math.atan2(q.z, q.w), math.pi / 2)
