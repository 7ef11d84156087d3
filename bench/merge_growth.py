"""Robots merged update after update while their maps grow (issue 13): do merged robots stay
merged, and placed right?

Each shared log is cut into K contiguous runs as ``bench/merge_speed.py --split`` cuts it
(each starting ``--overlap`` scans before its predecessor ends), each run's keyframes built at
the reference poses (merging alone is measured, not local mapping). The K robots drive at
the same time: at update s of ``--steps`` each robot holds the first s/steps of its
keyframes, and the merger runs ``merge_joint`` on them, warm from the previous update (every
place matched unless ``--budget`` gives the node's time budget, which makes the result depend
on the machine's speed).

    .venv/bin/python bench/merge_growth.py [--logs intel aces fhw csail] [--robots 2 4 8]
        [--steps 10] [--overlap 40] [--budget 0] [--set NAME=VALUE ...]

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
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from merge_speed import DATA, add_merge_overrides, joint_cut, merge_config_of  # noqa: E402

from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.merging import MergeConfig, MergeResult  # noqa: E402
from multi_robot_mapper.core.merging.joint import merge_joint  # noqa: E402
from multi_robot_mapper.io.carmen import read_carmen  # noqa: E402

RIGHT_DISTANCE = 0.30
RIGHT_ANGLE = math.radians(5.0)


def _off(a: np.ndarray, b: np.ndarray) -> bool:
    """Are two SE(2) matrices more than 0.30 m or 5 deg apart?"""
    dx, dy, dt = se2.pose_from_matrix(se2.invert(a) @ b)
    return bool(np.hypot(dx, dy) > RIGHT_DISTANCE or abs(dt) > RIGHT_ANGLE)


def grow(
    name: str, robots: int, steps: int, overlap: int, budget: float, config: MergeConfig
) -> None:
    """One row of the table (module doc)."""
    path = DATA / f"{name}.log.gz"
    if not path.is_file():
        print(f"| {name} | {robots} | skipped: {path} not found |", flush=True)
        return
    frames, keyframes = joint_cut(list(read_carmen(path)), robots, overlap)
    result: MergeResult | None = None
    placed_before: dict[str, np.ndarray] = {}
    previous_reference: str | None = None
    flips = wrong = moves = 0
    times: list[float] = []
    for step in range(1, steps + 1):
        held = {r: k[: max(1, math.ceil(len(k) * step / steps))] for r, k in keyframes.items()}
        started = time.perf_counter()
        result = merge_joint(held, config, previous=result, budget=budget)
        times.append(time.perf_counter() - started)
        assert result.reference is not None
        T_map_world = se2.invert(frames[result.reference])
        placed_now: dict[str, np.ndarray] = {}
        for robot, pose in result.placements.items():
            if pose is None:
                continue
            placed_now[robot] = se2.matrix_from_pose(*pose)
            wrong += _off(T_map_world @ frames[robot], placed_now[robot])
        same_reference = result.reference == previous_reference
        for robot, T in placed_before.items():
            if robot not in placed_now:
                flips += 1
            elif same_reference and _off(T, placed_now[robot]):
                moves += 1
        placed_before, previous_reference = placed_now, result.reference
    print(
        f"| {name} | {robots} | {steps} | {len(placed_before)}/{robots} | {flips} | {wrong} | "
        f"{moves} | {np.median(times):.2f} | {max(times):.2f} |",
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
    add_merge_overrides(parser)
    args = parser.parse_args()
    config = merge_config_of(args)
    print(
        "| log | robots | updates | placed at the end | flips | wrong placements | moves "
        "| update median (s) | update max (s) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in args.logs:
        for robots in args.robots:
            grow(name, robots, args.steps, args.overlap, args.budget, config)


if __name__ == "__main__":
    main()
