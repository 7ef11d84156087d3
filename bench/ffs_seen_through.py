"""Walls seen through (issue 51's next step, a probe): does a fitness other than Eq. 5 tell R0
from the wrong maps that Eq. 5 ranks deeper?

    .venv/bin/python -m bench.ffs_seen_through --log edmonton --seeds 0,7,6

The re-convergence experiment of ``bench.ffs_bench`` (its problem, R0 and the seeds' ends by
``run_ffs_escaped``). For each map, the count of points of one body that lie inside another
body's observed free space: closer to that keyframe's sensor than its own wall on the same
bearing (1° bins, its nearest point) by more than 0.20 m, and farther than 0.30 m. A body slid
along a corridor or turned puts its walls where another keyframe saw through; Eq. 5 does not
count that. Prints the count for the reference poses, R0 and each seed's end, with Eq. 5's depth
against R0's.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402

import numpy as np  # noqa: E402

from bench.ffs_bench import distorted, experiment_bodies, keyframe_scans, widened  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.merging.ffs import FfsConfig  # noqa: E402
from multi_robot_mapper.core.merging.ffs.bodies import Bodies, placed  # noqa: E402
from multi_robot_mapper.core.merging.ffs.escape import depth, run_ffs_escaped  # noqa: E402

_MARGIN = 0.20  # m nearer than the keyframe's own wall: past a wall's thickness and noise
_NEAR = 0.30  # m: the robot's own body
_BINS = 360  # bearings of 1°


def _bearing_bins(points: np.ndarray) -> np.ndarray:
    angle = np.arctan2(points[:, 1], points[:, 0]) + np.pi
    return np.floor(angle / (2.0 * np.pi) * _BINS).astype(np.int64) % _BINS


def seen_through(bodies: Bodies, poses: np.ndarray) -> int:
    """Points of any body inside another body's observed free space (module doc)."""
    world, _ = placed(bodies, poses)
    total = 0
    for body in range(bodies.count):
        own = bodies.body == body
        ranges = np.hypot(*bodies.points[own].T)
        wall = np.full(_BINS, np.inf)
        np.minimum.at(wall, _bearing_bins(bodies.points[own]), ranges)
        T_body_map = se2.invert(se2.matrix_from_pose(*poses[body]))
        others = se2.transform_points(T_body_map, world[~own])
        reach = wall[_bearing_bins(others)]
        distance = np.hypot(*others.T)
        total += int(np.sum(np.isfinite(reach) & (distance > _NEAR) & (distance < reach - _MARGIN)))
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log", default="edmonton")
    parser.add_argument("--seeds", default="0", help="comma-separated seeds")
    args = parser.parse_args()
    config = FfsConfig(time_budget=0.0, max_iterations=1000)
    sets, reference, _ = keyframe_scans(args.log, 60)
    bodies, fixed = experiment_bodies(sets, config)
    config = widened(config, bodies, 0.30, 20.0)
    r0 = run_ffs_escaped(bodies, reference, config, fixed=fixed).poses
    r0_depth = depth(bodies, r0, config).total
    print(f"| {args.log} | map | Eq. 5 against R0's | points seen through |")
    print("| --- | --- | --- | --- |")
    print(
        f"| | reference poses | {depth(bodies, reference, config).total / r0_depth - 1:+.3%} | "
        f"{seen_through(bodies, reference)} |"
    )
    print(f"| | R0 | +0.000% | {seen_through(bodies, r0)} |", flush=True)
    for seed in (int(s) for s in args.seeds.split(",")):
        end = run_ffs_escaped(bodies, distorted(r0, fixed, 0.30, 20.0, seed), config, fixed=fixed)
        print(
            f"| | seed {seed}'s end | {depth(bodies, end.poses, config).total / r0_depth - 1:+.3%} "
            f"| {seen_through(bodies, end.poses)} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
