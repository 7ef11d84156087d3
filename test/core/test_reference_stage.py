"""The ``reference`` method of an offline run (core/reference_stage.py), on noise-free scans of
a known room: every scan with a reference pose is placed at it, its walls on the true walls,
and a scan without one is left out."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.geometry import point_segment_distance
from multi_robot_mapper.core.offline import TimedLaserScan
from multi_robot_mapper.core.pipeline import run_offline
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.core.worlds import polygon

ROOM = polygon([(0.0, 0.0), (8.0, 0.0), (8.0, 5.0), (4.0, 5.0), (4.0, 7.0), (0.0, 7.0)])
LASER = LaserModel(beams=361, range_noise=0.0, dropout=0.0, range_max=20.0)


def drive(poses: list[tuple[float, float, float]], start: float) -> list[TimedLaserScan]:
    rng = np.random.default_rng(0)
    return [
        TimedLaserScan(start + 0.1 * k, simulate_scan(ROOM, pose, LASER, rng), pose)
        for k, pose in enumerate(poses)
    ]


def test_scans_are_placed_at_their_reference_poses_and_their_walls_on_the_true_walls() -> None:
    a = drive([(2.0, 2.0, 0.0), (2.5, 2.2, 0.3), (3.0, 2.4, 0.6)], start=10.0)
    b = drive([(6.0, 3.0, np.pi), (5.5, 3.0, 3.0)], start=10.05)
    b.append(TimedLaserScan(10.35, drive([(5.0, 3.1, 2.9)], 0.0)[0].scan, None))  # no reference
    result = run_offline({"b": b, "a": a}, "reference", ExtractionConfig())
    assert result.robots == ["a", "b"]
    assert result.robot_frames == {"a": (0.0, 0.0, 0.0), "b": (0.0, 0.0, 0.0)}
    for robot, items in (("a", a), ("b", b[:2])):
        stamps, poses = result.trajectories[robot]
        np.testing.assert_allclose(stamps, [item.stamp for item in items])
        np.testing.assert_allclose(poses, [item.reference_pose for item in items])
    assert result.stats["scans_posed"] == 5 and result.stats["method"] == "reference"
    assert sorted(set(result.segment_robot.tolist())) == [0, 1]
    # Every end of every placed segment on a wall of the room (noise-free scans; the fit's
    # corners within a few millimetres).
    ends = result.map_segments.reshape(-1, 2)
    distance = point_segment_distance(
        ends[:, 0:1], ends[:, 1:2], ROOM[:, 0], ROOM[:, 1], ROOM[:, 2], ROOM[:, 3]
    ).min(axis=1)
    assert len(ends) > 0 and distance.max() < 0.01
