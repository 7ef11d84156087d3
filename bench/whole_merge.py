"""How long one whole merge of K robots takes (issue 46: "the whole-merge time for 8 robots does
not grow"): each shared log cut into K runs as the issue-13 benches cut it
(``merge_speed.joint_cut``, keyframes at the reference poses), merged from nothing by
``merge_joint`` with every place matched, timed in this process.

    .venv/bin/python -m bench.whole_merge [--logs intel aces fhw csail] [--robots 8]

Prints ``log robots seconds placed`` per case, and the median. Run it from two checkouts in
turn to compare them on this noisy machine (the README of bench/ says how).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import LOGS, carmen_log, joint_cut, present_logs  # noqa: E402
from multi_robot_mapper.core.merging import MergeConfig  # noqa: E402
from multi_robot_mapper.core.merging.joint import merge_joint  # noqa: E402
from multi_robot_mapper.io.carmen import read_carmen  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="*", default=list(LOGS))
    parser.add_argument("--robots", type=int, default=8)
    args = parser.parse_args()
    seconds = []
    for name in present_logs(args.logs):
        _, keyframes = joint_cut(list(read_carmen(carmen_log(name))), args.robots, 40)
        started = time.perf_counter()
        result = merge_joint(keyframes, MergeConfig(), budget=0.0)
        elapsed = time.perf_counter() - started
        seconds.append(elapsed)
        placed = sum(p is not None for p in result.placements.values())
        print(f"{name} {args.robots} {elapsed:.2f} {placed}/{args.robots}", flush=True)
    if seconds:
        print(f"median {np.median(seconds):.2f} s, max {max(seconds):.2f} s")


if __name__ == "__main__":
    main()
