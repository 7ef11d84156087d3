"""Force Field Simulation (core/ffs): resampling, regions of interest, the force field,
Algorithm 1 on synthetic geometry with a known answer, and the 'ffs' merging method."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.config import ConfigError
from multi_robot_mapper.core.ffs import FfsConfig, make_bodies, resample, run_ffs
from multi_robot_mapper.core.ffs.bodies import corner_points, placed
from multi_robot_mapper.core.ffs.simulation import force_field

# A 4 m x 3 m room with an L-shaped cabinet: corners in every direction.
ROOM = np.array(
    [
        [0.0, 0.0, 4.0, 0.0],
        [4.0, 0.0, 4.0, 3.0],
        [4.0, 3.0, 0.0, 3.0],
        [0.0, 3.0, 0.0, 0.0],
        [1.5, 1.0, 2.5, 1.0],
        [2.5, 1.0, 2.5, 2.0],
    ]
)
VIEWS = np.array([[1.0, 1.5, 0.0], [3.0, 1.2, 0.5], [2.0, 2.5, -0.7]])


def room_bodies(config: FfsConfig):
    """The room as seen (entirely) from each of VIEWS, in the view's own frame."""
    sets = [se2.transform_segments(se2.invert(se2.matrix_from_pose(*p)), ROOM) for p in VIEWS]
    return make_bodies(sets, config.spacing, config.roi_radius, config.roi_mass)


def test_segments_are_resampled_at_the_spacing_with_their_direction() -> None:
    points, directions, owner = resample(np.array([[0.0, 0.0, 1.0, 0.0], [0, 0, 0, 0.25]]), 0.1)
    assert np.bincount(owner).tolist() == [11, 4]  # ends included; 0.25 m in 3 equal steps
    assert np.allclose(points[:11, 0], np.linspace(0.0, 1.0, 11)) and np.allclose(points[:11, 1], 0)
    assert np.allclose(np.diff(points[11:, 1]), 0.25 / 3)
    assert np.allclose(directions[:11], [1.0, 0.0]) and np.allclose(directions[11:], [0.0, 1.0])


def test_regions_of_interest_are_the_room_corners() -> None:
    square = np.array([[0, 0, 2, 0], [2, 0, 2, 2], [2, 2, 0, 2], [0, 2, 0, 0]], dtype=float)
    points, _, owner = resample(square, 0.05)
    inside = corner_points(square, points, owner, 0.06)
    corners = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=float)
    near = np.hypot(*(points[:, None] - corners[None]).transpose(2, 0, 1)).min(axis=1) <= 0.06
    assert np.array_equal(inside, near) and inside.sum() >= 8
    # Two walls at 45 deg make no corner (FFS 3.4: 80-100 deg only).
    slanted = np.array([[0, 0, 2, 0], [0, 0, 1.4, 1.4]], dtype=float)
    p, _, o = resample(slanted, 0.05)
    assert not corner_points(slanted, p, o, 0.06).any()


def test_orthogonal_walls_do_not_attract_and_parallel_ones_pull_equally() -> None:
    config = FfsConfig()
    cross = make_bodies(
        [np.array([[-1.0, 0.0, 1.0, 0.0]]), np.array([[0.0, -1.0, 0.0, 1.0]])], 0.1, 0.0, 1.0
    )
    poses = np.zeros((2, 3))
    points, directions = placed(cross, poses)
    field = force_field(points, directions, cross, np.zeros((2, 2)), 0.1, config.cutoff)
    assert np.allclose(field.force, 0.0) and np.allclose(field.torque, 0.0)
    walls = make_bodies([np.array([[-1.0, 0.0, 1.0, 0.0]])] * 2, 0.1, 0.0, 1.0)
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.05, 0.0]])  # the second 5 cm above
    points, directions = placed(walls, poses)
    field = force_field(points, directions, walls, poses[:, :2], 0.1, config.cutoff)
    assert field.force[0, 1] > 0.0 and np.allclose(field.force[0], -field.force[1])
    assert abs(field.force[0, 0]) < 1e-9 and field.potential < 0.0
    alone = make_bodies([ROOM], 0.1, 0.05, 3.0)  # one body feels no force from itself
    points, directions = placed(alone, np.zeros((1, 3)))
    assert force_field(points, directions, alone, np.zeros((1, 2)), 0.1, 3.0).pairs == 0


def test_ffs_brings_perturbed_views_of_a_room_back() -> None:
    config = FfsConfig()
    bodies = room_bodies(config)
    start = VIEWS + np.array([[0.0, 0.0, 0.0], [0.08, -0.05, 0.04], [-0.06, 0.07, -0.05]])
    result = run_ffs(bodies, start, config, fixed=np.array([True, False, False]))
    assert result.converged and result.iterations == len(result.potentials)
    error = result.poses - VIEWS
    assert np.abs(error[:, :2]).max() < 0.005 and np.abs(error[:, 2]).max() < np.radians(0.3)
    assert result.relocations[-1] < config.stop_relocation


@settings(max_examples=15, deadline=None)
@given(
    x=st.floats(-20.0, 20.0),
    y=st.floats(-20.0, 20.0),
    theta=st.floats(-np.pi, np.pi),
    seed=st.integers(0, 1000),
)
def test_moving_the_whole_scene_moves_the_result_the_same_way(
    x: float, y: float, theta: float, seed: int
) -> None:
    config = FfsConfig(max_iterations=30)
    bodies = room_bodies(config)
    rng = np.random.default_rng(seed)
    start = VIEWS + np.column_stack([rng.uniform(-0.05, 0.05, (3, 2)), rng.uniform(-0.03, 0.03, 3)])
    fixed = np.array([True, False, False])
    here = run_ffs(bodies, start, config, fixed=fixed).poses
    T = se2.matrix_from_pose(x, y, theta)
    moved_start = np.array([se2.pose_from_matrix(T @ se2.matrix_from_pose(*p)) for p in start])
    there = run_ffs(bodies, moved_start, config, fixed=fixed).poses
    expected = np.array([se2.pose_from_matrix(T @ se2.matrix_from_pose(*p)) for p in here])
    assert np.allclose(there[:, :2], expected[:, :2], atol=1e-6)
    assert np.allclose(se2.wrap_angle(there[:, 2] - expected[:, 2]), 0.0, atol=1e-7)


def test_the_config_cools_down_and_says_so_when_it_would_not() -> None:
    with pytest.raises(ConfigError, match="sigma_end"):
        FfsConfig(sigma_start=0.05, sigma_end=0.1)
    with pytest.raises(ConfigError, match="spacing"):
        FfsConfig(spacing=0.0)


def test_method_ffs_merges_simulated_robots_where_the_truth_has_them() -> None:
    # Two office robots mapped offline without odometry, merged by 'ffs': the joint graph
    # places them, FFS moves every body; both robots' trajectories stay on the truth.
    from multi_robot_mapper.core.extraction_config import ExtractionConfig
    from multi_robot_mapper.core.pipeline import TimedLaserScan, run_offline
    from multi_robot_mapper.core.simulation import LaserModel, simulate_robots

    runs = simulate_robots("office", 2, LaserModel(), seed=0, duration=20.0, overlap=0.45)
    recordings = {
        f"robot{k + 1}": [
            TimedLaserScan(float(t), scan, tuple(pose))
            for t, scan, pose in zip(run.stamps, run.scans, run.T_world_laser, strict=True)
        ][::4]
        for k, run in enumerate(runs)
    }
    out = run_offline(recordings, "ffs", ExtractionConfig())
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
