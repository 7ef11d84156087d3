"""The 'ffs' merging method: simulated robots merged where the truth has them, updates resumed,
warm starts."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from test_link_graph import SIMULATED_WORLD_JOIN_PROBABILITY

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.ffs import (
    FfsConfig,
)


@pytest.fixture(scope="module")
def office_recordings() -> dict[str, list[Any]]:
    """Two simulated office robots' scans (every 4th), with their true poses."""
    from multi_robot_mapper.core.pipeline import TimedLaserScan
    from multi_robot_mapper.core.simulation import LaserModel, simulate_robots

    runs = simulate_robots("office", 2, LaserModel(), seed=0, duration=20.0, overlap=0.45)
    return {
        f"robot{k + 1}": [
            TimedLaserScan(float(t), scan, tuple(pose))
            for t, scan, pose in zip(run.stamps, run.scans, run.T_world_laser, strict=True)
        ][::4]
        for k, run in enumerate(runs)
    }


def test_method_ffs_merges_simulated_robots_where_the_truth_has_them(
    office_recordings: dict[str, list[Any]],
) -> None:
    # Two office robots mapped offline without odometry, merged by 'ffs': the joint graph
    # places them, FFS moves every body; both robots' trajectories stay on the truth.
    from multi_robot_mapper.core.extraction_config import ExtractionConfig
    from multi_robot_mapper.core.merging import MergeConfig
    from multi_robot_mapper.core.pipeline import run_offline

    recordings = office_recordings
    merging = MergeConfig(join_probability=SIMULATED_WORLD_JOIN_PROBABILITY)
    out = run_offline(recordings, "ffs", ExtractionConfig(), merging=merging)
    assert all(out.robot_frames[r] is not None for r in recordings), out.robot_frames
    assert out.stats["merge_stats"]["ffs_iterations"] > 0
    truth = {
        r: {round(s.stamp, 6): s.reference_pose for s in scans} for r, scans in recordings.items()
    }
    stamps, poses = out.trajectories["robot1"]
    reference = np.array([truth["robot1"][round(float(s), 6)] for s in stamps])
    T_world_map = se2.rigid_fit(poses, reference)
    for robot in recordings:
        stamps, poses = out.trajectories[robot]
        true_xy = np.array([truth[robot][round(float(s), 6)][:2] for s in stamps])
        placed_xy = se2.transform_points(T_world_map, poses[:, :2])
        rmse = float(np.sqrt(np.mean(np.sum((placed_xy - true_xy) ** 2, axis=1))))
        assert rmse < 0.05, (robot, rmse)


def test_ffs_updates_resume_where_the_last_one_stopped(
    office_recordings: dict[str, list[Any]],
) -> None:
    # An update cut short (3 iterations) leaves its poses and cooling to the next, which goes
    # on cooling from there; once settled, an update with nothing new settles at once, and
    # one with something new starts afresh from the joint graph.
    from multi_robot_mapper.core.extraction_config import ExtractionConfig
    from multi_robot_mapper.core.merging import MergeConfig
    from multi_robot_mapper.core.merging.ffs.method import FfsState, merge_ffs
    from multi_robot_mapper.core.merging.joint import merge_joint
    from multi_robot_mapper.core.pipeline import run_offline

    local = run_offline(office_recordings, "local", ExtractionConfig())
    plain = MergeConfig(join_probability=SIMULATED_WORLD_JOIN_PROBABILITY)
    short = dataclasses.replace(plain, ffs=FfsConfig(max_iterations=3))
    first = merge_ffs(local.keyframes, short, budget=0.0)
    state = first.refinement
    assert isinstance(state, FfsState) and set(state.keyframes) == set(first.robots)
    # Cut short, its bodies are mid-anneal: the result keeps the joint graph's placement.
    joint = merge_joint(local.keyframes, short, budget=0.0)
    assert first.stats["ffs_converged"] == 0 and not state.settled
    for robot in first.robots:
        assert np.allclose(first.keyframe_poses[robot], joint.keyframe_poses[robot]), robot
    assert state.sigma == pytest.approx(short.ffs.sigma_start - 3 * short.ffs.sigma_step)
    second = merge_ffs(local.keyframes, short, previous=first, budget=0.0)
    assert isinstance(second.refinement, FfsState)
    assert second.refinement.sigma == pytest.approx(state.sigma - 3 * short.ffs.sigma_step)
    settled = merge_ffs(local.keyframes, plain, budget=0.0)
    assert settled.stats["ffs_converged"] == 1
    again = merge_ffs(local.keyframes, plain, previous=settled, budget=0.0)
    assert again.stats["ffs_converged"] == 1 and again.stats["ffs_iterations"] == 1
    for robot in again.robots:
        moved = again.keyframe_poses[robot] - settled.keyframe_poses[robot]
        assert np.abs(moved).max() < 1e-3, robot
    fewer = {robot: frames[:-1] for robot, frames in local.keyframes.items()}
    fresh = merge_ffs(fewer, plain, previous=settled, budget=0.0)
    cooling = (FfsConfig().sigma_start - FfsConfig().sigma_end) / FfsConfig().sigma_step
    assert fresh.stats["ffs_iterations"] >= cooling


def test_a_warm_start_carries_each_keyframe_as_the_last_simulation_corrected_it() -> None:
    from multi_robot_mapper.core.merging.ffs.method import FfsState, warm_started

    before = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.1], [2.0, 0.5, 0.2]])
    # What FFS did to each held keyframe, in its own frame.
    fixes = np.array([[0.01, -0.02, 0.01], [0.03, 0.0, -0.02], [-0.01, 0.02, 0.005]])
    after = se2.compose_each(before, fixes)
    state = FfsState({"a": np.array([0, 1, 2])}, {"a": before}, {"a": after}, 0.05, 0.6, False)
    # Since, the graph re-placed robot a as a whole (T_move) and added its keyframe 3; robot b
    # is new.
    T_move = se2.matrix_from_pose(4.0, -2.0, 0.7)
    moved = np.array([se2.pose_from_matrix(T_move @ se2.matrix_from_pose(*p)) for p in before])
    start = np.vstack([moved, [[3.0, 1.0, 0.3]], [[5.0, 5.0, 1.0]]])
    owners = [("a", 0), ("a", 1), ("a", 2), ("a", 3), ("b", 0)]
    index = {"a": np.array([0, 1, 2, 3]), "b": np.array([0])}
    warm = warm_started(state, owners, index, start)
    expected = [se2.pose_from_matrix(T_move @ se2.matrix_from_pose(*p)) for p in after]
    assert np.allclose(warm[:3], expected)  # each moved with its robot, its correction kept
    assert np.allclose(warm[3], se2.compose(start[3], fixes[2]))  # 3 takes 2's, its nearest
    assert np.allclose(warm[4], start[4])
