"""The front end's time per scan on a real log, for one or more checkouts run back to back.

This machine's speed drifts by a third within the hour (README, live rate), so a figure
measured before a change and one measured after it an hour later say little about the
change. This bench alternates the checkouts given (clones of the repository at the commits to
compare, e.g. ``git clone -q . /tmp/before && git -C /tmp/before checkout -q <commit>``) in
rounds, each run in its own process on the same scans, and prints per run: the median, p95
and mean time per scan of extraction plus ``LocalMapper.add_scan`` with the back end off (what
a node's scan thread does), and a digest of every scan's placement (accepted, pose), equal
across checkouts when a change leaves every decision as it was.

    .venv/bin/python -m bench.front_end_ab [CHECKOUT ...] [--log freiburg-079] [--robots 4]
        [--robot 1] [--scans N] [--rounds 3]

With no checkout, this one alone. The live figure (DDS, the node, the back end beside it) is
``bench/live_rate.py``; this one isolates the front end's own arithmetic.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402


def measure(log: str, path: Path, robots: int, robot: int, scans: int | None) -> dict[str, Any]:
    """In the child: the checkout on ``PYTHONPATH`` maps the robot's run of log ``log`` (at
    ``path``); imports are here so that they come from that checkout, not from this file's."""
    import numpy as np

    import multi_robot_mapper
    from multi_robot_mapper.cli.import_carmen import split_runs
    from multi_robot_mapper.core.extraction import extract_scan
    from multi_robot_mapper.core.local_mapping.mapper import LocalMapper
    from multi_robot_mapper.io.carmen import carmen_scan_data, monotonic_stamps, read_carmen
    from multi_robot_mapper.ros.mapper_config import RobotMapperConfig

    records = list(read_carmen(path))
    start, stop = split_runs(len(records), robots, 0)[robot - 1]
    run = records[start:stop][:scans]
    stamps, _ = monotonic_stamps(np.array([r.timestamp for r in run]), log)
    views = [carmen_scan_data(r) for r in run]
    config = RobotMapperConfig()
    mapper = LocalMapper(config.local_mapping, backend=False)
    seconds, placements = [], []
    for stamp, view in zip(stamps, views, strict=True):
        started = time.perf_counter()
        segments, _ = extract_scan(view, config.extraction)
        update = mapper.add_scan(float(stamp), segments, view)
        seconds.append(time.perf_counter() - started)
        pose = None if update.pose is None else tuple(float(v) for v in update.pose)
        placements.append((bool(update.accepted), pose))
    ms = np.array(seconds) * 1e3
    return {
        "package": str(Path(multi_robot_mapper.__file__).parent),
        "scans": len(ms),
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "mean_ms": float(ms.mean()),
        "placements": hashlib.sha1(repr(placements).encode()).hexdigest()[:12],
    }


def run_child(checkout: Path, args: argparse.Namespace) -> dict[str, Any]:
    # This file run as a script: the child imports nothing of this checkout (not bench/).
    command = [sys.executable, str(Path(__file__).resolve()), "--child", "--log", args.log]
    command += ["--log-path", str(args.log_path)]
    command += ["--robots", str(args.robots), "--robot", str(args.robot)]
    if args.scans:
        command += ["--scans", str(args.scans)]
    env = dict(os.environ, PYTHONPATH=str(checkout))
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"front_end_ab: {checkout} failed:\n{done.stderr}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    if Path(result["package"]).resolve() != (checkout / "multi_robot_mapper").resolve():
        raise SystemExit(f"front_end_ab: {checkout} ran the package at {result['package']}")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkouts", nargs="*", type=Path, help="clones to compare")
    parser.add_argument("--log", default="freiburg-079")
    parser.add_argument("--robots", type=int, default=4)
    parser.add_argument("--robot", type=int, default=1)
    parser.add_argument("--scans", type=int, default=None, help="the first N of the run")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--log-path", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.log, args.log_path, args.robots, args.robot, args.scans)))
        return
    # The harness in the parent only: it imports this checkout's package, the child another's.
    from bench.harness import REPO, require_log

    args.log_path = require_log(args.log, "front_end_ab")
    checkouts = [c.resolve() for c in args.checkouts] or [REPO]
    for checkout in checkouts:
        if not (checkout / "multi_robot_mapper").is_dir():
            raise SystemExit(f"front_end_ab: {checkout} is not a checkout of this repository")
    print(f"front end per scan: {args.log} robot {args.robot} of {args.robots}, back end off")
    print("round | checkout | scans | median / p95 / mean (ms) | placements")
    for round_ in range(1, args.rounds + 1):
        for checkout in checkouts:
            r = run_child(checkout, args)
            print(
                f"{round_} | {checkout} | {r['scans']} | {r['median_ms']:.1f} / "
                f"{r['p95_ms']:.1f} / {r['mean_ms']:.1f} | {r['placements']}",
                flush=True,
            )


if __name__ == "__main__":
    main()
