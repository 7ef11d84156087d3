"""FFS from afar while the field is wide (core/merging/ffs/far.py, issue 51): each body's own
Newton step, and a corridor whose keyframes the wide field must not slide along it."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.ffs import FfsConfig, make_bodies
from multi_robot_mapper.core.merging.ffs.bodies import placed
from multi_robot_mapper.core.merging.ffs.far import (
    centres_and_radii,
    joint_step,
    run_ffs_far,
    start_width,
    wall_pulls,
)


def _corner_bodies(poses: np.ndarray):  # type: ignore[no-untyped-def]
    corner = np.array([[0.0, 0.0, 4.0, 0.0], [4.0, 0.0, 4.0, 3.0], [0.0, 0.0, 0.0, 2.0]])
    bodies = make_bodies([corner] * len(poses), 0.1, 0.0, 1.0)
    points, directions = placed(bodies, poses)
    return bodies, points, directions


def test_a_body_alone_takes_the_joint_step_with_the_others_held() -> None:
    # Three copies of a corner, two of them off: each body's own step is the joint step of the
    # same pulls with every other body fixed (its own 3x3 block of the system).
    poses = np.array([[0.0, 0.0, 0.0], [0.06, 0.08, 0.02], [-0.05, 0.04, -0.03]])
    bodies, points, directions = _corner_bodies(poses)
    pulls = wall_pulls(points, directions, bodies, 0.3, 0.1, 3.0)
    centres, _ = centres_and_radii(bodies, points)
    free = np.array([False, True, True])
    alone = joint_step(pulls, points, centres, free, alone=True)
    for body in (1, 2):
        held = np.zeros(3, dtype=bool)
        held[body] = True
        assert np.allclose(alone[body], joint_step(pulls, points, centres, held)[body])
    assert np.allclose(alone[0], 0.0) and np.abs(alone[1:]).max() > 1e-3


def _corridor() -> np.ndarray:
    """A room (x < 0) and a corridor 2 m wide and 24 m long, a door recess every 3 m."""
    walls = [[-3, -2, -3, 4], [-3, 4, 0, 4], [-3, -2, 0, -2], [0, -2, 0, 0], [0, 2, 0, 4]]
    for k in range(8):
        a = 3.0 * k
        walls += [[a, 0, a + 2.2, 0], [a + 2.2, 0, a + 2.2, -0.15]]
        walls += [[a + 2.2, -0.15, a + 3.0, -0.15], [a + 3.0, -0.15, a + 3.0, 0]]
    walls += [[0, 2, 24, 2], [24, 0, 24, 2]]
    return np.array(walls, dtype=np.float64)


def _seen(walls: np.ndarray, x: float, half: float) -> np.ndarray:
    """The walls within ``half`` of ``x`` along the corridor (cut where they leave it)."""
    out = []
    for x1, y1, x2, y2 in walls:
        lo, hi = max(min(x1, x2), x - half), min(max(x1, x2), x + half)
        if x1 == x2 and lo <= hi:
            out.append([x1, y1, x2, y2])
        elif x1 != x2 and hi - lo > 0.05:
            out.append([lo, y1, hi, y2])
    return np.array(out, dtype=np.float64)


def test_a_corridors_keyframes_stay_where_they_were_seen_from() -> None:
    # Keyframes every 1.5 m along the corridor, each seeing 6 m of it, at their true poses: a
    # field as wide as the paper's distortion (σ from ~0.4 m) must leave every one where it is.
    views = np.array([[-1.5, 1.0, 0.0]] + [[1.0 + 1.5 * k, 1.0, 0.1 * (-1) ** k] for k in range(8)])
    walls = _corridor()
    sets = [
        se2.transform_segments(se2.invert(se2.matrix_from_pose(*v)), _seen(walls, v[0], 3.0))
        for v in views
    ]
    config = FfsConfig(time_budget=0.0, max_iterations=300)
    bodies = make_bodies(sets, config.spacing, config.roi_radius, config.roi_mass)
    width = start_width(0.30, np.radians(20.0), bodies)
    config = FfsConfig(sigma_start=width, time_budget=0.0, max_iterations=300)
    fixed = np.zeros(len(views), dtype=bool)
    fixed[0] = True
    result = run_ffs_far(bodies, views, config, fixed=fixed)
    gaps = np.hypot(*(result.poses[:, :2] - views[:, :2]).T)
    turns = np.abs(se2.wrap_angle(result.poses[:, 2] - views[:, 2]))
    assert width > 0.3 and result.converged
    assert gaps.max() < 0.005 and np.degrees(turns.max()) < 0.1, (gaps, turns)
