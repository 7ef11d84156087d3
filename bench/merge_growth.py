"""Robots merged update after update while their maps grow (issue 13): do merged robots stay
merged, and placed right?

Each shared log is cut into K contiguous runs as ``bench/merge_speed.py --split`` cuts it
(each starting ``--overlap`` scans before its predecessor ends), each run's keyframes built at
the reference poses (merging alone is measured, not local mapping). The K robots drive at
the same time: at update s of ``--steps`` each robot holds the first s/steps of its
keyframes, and the merger runs ``merge_joint`` on them, warm from the previous update (every
place matched unless ``--budget`` gives the node's time budget, which makes the result depend
on the machine's speed).

``--method ffs`` runs the ``ffs`` merging method instead (the joint graph, then FFS, as the
node does): FFS bounded by ``merge.ffs.time_budget`` per update (the node's), warm-started
from the previous update's where that one was cut short (issue 14 item 4), or started afresh
from the joint graph at every update with ``--cold``. The last two columns: FFS iterations per
update (median; ffs only) and the keyframe error at the end (RMSE of every merged keyframe's
position against the reference after one rigid fit of all).

    .venv/bin/python -m bench.merge_growth [--logs intel aces fhw csail] [--robots 2 4 8]
        [--steps 10] [--overlap 40] [--budget 0] [--method pivot|ffs] [--cold]
        [--set NAME=VALUE ...]

One row per log and K: updates, robots placed at the end, *flips* (a robot placed by one
update and unplaced by the next; each one is a robot whose map vanishes from the global map
and comes back), *wrong placements* (robot-updates placed more than 0.30 m or 5 deg from the
reference), *moves* (a placed robot whose placement moved more than 0.30 m or 5 deg from one
update to the next), and the median and largest update time.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import add_merge_overrides, apart, carmen_log, joint_cut, merge_config_of  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.merging import MergeConfig, MergeResult  # noqa: E402
from multi_robot_mapper.core.merging.methods import MERGE_METHODS, merge_method  # noqa: E402
from multi_robot_mapper.io.carmen import read_carmen  # noqa: E402


def keyframe_error(
    result: MergeResult, frames: dict[str, np.ndarray], keyframes: dict[str, list[Any]]
) -> float:
    """RMSE (m) of every merged keyframe's position against its reference after one rigid
    fit of all (module doc)."""
    estimated, reference = [], []
    for robot, poses in result.keyframe_poses.items():
        pose_of = {kf.index: kf.T_robotmap_keyframe for kf in keyframes[robot]}
        for row, index in enumerate(result.keyframe_index[robot]):
            estimated.append(poses[row, :2])
            T_world_keyframe = frames[robot] @ se2.matrix_from_pose(*pose_of[int(index)])
            reference.append(T_world_keyframe[:2, 2])
    if len(estimated) < 2:
        return float("nan")
    est, ref = np.array(estimated), np.array(reference)
    error = se2.transform_points(se2.fit_points(est, ref), est) - ref
    return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))


def grow(
    name: str,
    robots: int,
    steps: int,
    overlap: int,
    budget: float,
    config: MergeConfig,
    method: str = "pivot",
    cold: bool = False,
) -> None:
    """One row of the table (module doc)."""
    path = carmen_log(name)
    if not path.is_file():
        print(f"| {name} | {robots} | skipped: {path} not found |", flush=True)
        return
    frames, keyframes = joint_cut(list(read_carmen(path)), robots, overlap)
    result: MergeResult | None = None
    placed_before: dict[str, np.ndarray] = {}
    previous_reference: str | None = None
    flips = wrong = moves = 0
    times: list[float] = []
    iterations: list[int] = []
    merge = merge_method(method)
    # budget 0 would lift FFS's own time limit too (merge_ffs): the node's FFS is bounded.
    config = dataclasses.replace(config, update_budget=budget)
    for step in range(1, steps + 1):
        held = {r: k[: max(1, math.ceil(len(k) * step / steps))] for r, k in keyframes.items()}
        previous = result
        if cold and previous is not None:
            previous = dataclasses.replace(previous, refinement=None)
        started = time.perf_counter()
        result = merge(held, config, previous=previous)
        times.append(time.perf_counter() - started)
        iterations.append(int(result.stats.get("ffs_iterations", 0)))
        assert result.reference is not None
        T_map_world = se2.invert(frames[result.reference])
        placed_now: dict[str, np.ndarray] = {}
        for robot, pose in result.placements.items():
            if pose is None:
                continue
            placed_now[robot] = se2.matrix_from_pose(*pose)
            wrong += apart(T_map_world @ frames[robot], placed_now[robot])
        same_reference = result.reference == previous_reference
        for robot, T in placed_before.items():
            if robot not in placed_now:
                flips += 1
            elif same_reference and apart(T, placed_now[robot]):
                moves += 1
        placed_before, previous_reference = placed_now, result.reference
    assert result is not None
    error = keyframe_error(result, frames, keyframes)
    ffs_iterations = f"{np.median(iterations):.0f}" if method == "ffs" else "–"
    extra = f" {ffs_iterations} | {error:.4f} |"
    print(
        f"| {name} | {robots} | {steps} | {len(placed_before)}/{robots} | {flips} | {wrong} | "
        f"{moves} | {np.median(times):.2f} | {max(times):.2f} |{extra}",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="*", default=["intel", "aces", "fhw", "csail"])
    parser.add_argument("--robots", type=int, nargs="*", default=[2, 4, 8])
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--overlap", type=int, default=40)
    parser.add_argument(
        "--budget", type=float, default=0.0, help="seconds of place matching per update (0: all)"
    )
    parser.add_argument("--method", choices=tuple(MERGE_METHODS), default="pivot")
    parser.add_argument("--cold", action="store_true", help="ffs: no warm start (module doc)")
    add_merge_overrides(parser)
    args = parser.parse_args()
    config = merge_config_of(args)
    header = (
        "| log | robots | updates | placed at the end | flips | wrong placements | moves "
        "| update median (s) | update max (s) | FFS iterations (median) "
        "| keyframe error at the end (m) |"
    )
    print(header)
    print("|" + " --- |" * (header.count("|") - 1))
    for name in args.logs:
        for robots in args.robots:
            grow(
                name, robots, args.steps, args.overlap, args.budget, config, args.method, args.cold
            )


if __name__ == "__main__":
    main()
