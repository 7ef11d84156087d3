"""How long one whole merge of K robots takes (issue 46: "the whole-merge time for 8 robots does
not grow"): each shared log cut into K runs as the issue-13 benches cut it
(``harness.joint_cut``, keyframes at the reference poses), merged from nothing by
``merge_joint`` with every place matched, timed in this process.

    .venv/bin/python -m bench.whole_merge [--logs intel aces fhw csail] [--robots 8]

Prints ``label log robots seconds placed cpu`` per case (``cpu``: the process's CPU seconds,
the figure to compare on a loaded machine: one thread), and the median. ``--placements FILE``
writes every robot's placement per log to a JSON file (to diff two commits' placements);
``--profile FILE`` runs the merges under cProfile and writes its statistics to FILE
(``python -m pstats FILE``). To compare with an older
commit whose package lacks today's ``bench.harness``, run this file by path with the older
checkout first on the path: its own ``bench.merge_speed.joint_cut`` (the same cut) is used
then, and the data is this file's checkout's ``../shared/data``::

    git clone -q . /tmp/before && git -C /tmp/before checkout -q 6e62280
    cd /tmp/before && PYTHONPATH=/tmp/before $OLDPWD/.venv/bin/python -P \\
        $OLDPWD/bench/whole_merge.py --label before --logs fhw

Alternate the two checkouts log by log on this noisy machine (bench/README.md).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import cProfile  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from multi_robot_mapper.core.merging import MergeConfig  # noqa: E402
from multi_robot_mapper.core.merging.joint import merge_joint  # noqa: E402
from multi_robot_mapper.io.carmen import read_carmen  # noqa: E402

try:
    from bench.harness import CARMEN, LOGS, joint_cut
except ImportError:  # an older checkout first on the path: its own cut (the same one)
    from bench.merge_speed import joint_cut  # type: ignore[no-redef]

    CARMEN = Path(__file__).resolve().parents[2] / "shared" / "data" / "carmen"
    LOGS = ("intel", "aces", "fhw", "csail")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="*", default=list(LOGS))
    parser.add_argument("--robots", type=int, default=8)
    parser.add_argument("--label", default="this", help="first word of each line printed")
    parser.add_argument("--placements", type=Path, help="JSON file of every placement")
    parser.add_argument("--profile", type=Path, help="cProfile statistics of the merges")
    args = parser.parse_args()
    seconds = []
    placements: dict[str, dict[str, list[float] | None]] = {}
    profiler = cProfile.Profile() if args.profile else None
    for name in args.logs:
        path = CARMEN / f"{name}.log.gz"
        if not path.is_file():
            print(f"{name}: skipped ({path} is absent)", flush=True)
            continue
        _, keyframes = joint_cut(list(read_carmen(path)), args.robots, 40)
        if profiler is not None:
            profiler.enable()
        started, cpu = time.perf_counter(), time.process_time()
        result = merge_joint(keyframes, MergeConfig(), budget=0.0)
        elapsed, cpu = time.perf_counter() - started, time.process_time() - cpu
        if profiler is not None:
            profiler.disable()
        placements[name] = {
            robot: None if pose is None else [float(v) for v in pose]
            for robot, pose in sorted(result.placements.items())
        }
        seconds.append(elapsed)
        placed = sum(p is not None for p in result.placements.values())
        line = f"{args.label} {name} {args.robots} {elapsed:.2f} {placed}/{args.robots} {cpu:.2f}"
        print(line, flush=True)
    if args.placements is not None:
        args.placements.write_text(json.dumps(placements, indent=1) + "\n")
    if profiler is not None:
        profiler.dump_stats(str(args.profile))
    if seconds:
        print(f"median {np.median(seconds):.2f} s, max {max(seconds):.2f} s")


if __name__ == "__main__":
    main()
