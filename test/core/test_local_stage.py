"""The local mapping stage of an offline run (core/local_stage.py), on two robots' short
noise-free drives in a known room: every robot mapped alone in its own frame, never claimed in
another's, its scans placed as the truth moved them, and what the replay reports of it."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.offline import TimedLaserScan
from multi_robot_mapper.core.pipeline import run_offline
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.core.worlds import polygon

ROOM = polygon([(0.0, 0.0), (8.0, 0.0), (8.0, 5.0), (4.0, 5.0), (4.0, 7.0), (0.0, 7.0)])
LASER = LaserModel(beams=361, range_noise=0.0, dropout=0.0, range_max=20.0)
DRIVES = {
    "a": [(2.0, 2.0, 0.0), (2.1, 2.0, 0.02), (2.2, 2.02, 0.04)],
    "b": [(6.0, 3.0, 3.0), (5.9, 3.0, 3.0), (5.8, 3.01, 2.98)],
}


def test_each_robot_is_mapped_alone_in_its_own_frame_as_the_truth_moved_it() -> None:
    rng = np.random.default_rng(0)
    recordings = {
        robot: [
            TimedLaserScan(10.0 + 0.1 * k, simulate_scan(ROOM, pose, LASER, rng))
            for k, pose in enumerate(poses)
        ]
        for robot, poses in DRIVES.items()
    }
    result = run_offline(recordings, "local", ExtractionConfig())
    assert result.robots == ["a", "b"]
    assert result.robot_frames == {"a": None, "b": None}  # never placed in another's frame
    assert result.merge_result is None and result.stats["scans_posed"] == 6
    for index, (robot, truth) in enumerate(DRIVES.items()):
        stamps, poses = result.trajectories[robot]
        np.testing.assert_allclose(stamps, [10.0, 10.1, 10.2])
        # Each scan's pose relative to the first, as the truth has it (within a centimetre).
        T_first = se2.matrix_from_pose(*poses[0])
        true_first = se2.matrix_from_pose(*truth[0])
        for pose, true in zip(poses[1:], truth[1:], strict=True):
            moved = se2.invert(T_first) @ se2.matrix_from_pose(*pose)
            true_moved = se2.invert(true_first) @ se2.matrix_from_pose(*true)
            error = se2.pose_from_matrix(se2.invert(true_moved) @ moved)
            assert np.hypot(error[0], error[1]) < 0.01 and abs(error[2]) < 0.005
        assert len(result.keyframes[robot]) >= 1
        assert np.any(result.segment_robot == index)
