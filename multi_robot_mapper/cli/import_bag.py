"""``mrm import-bag``: one robot's bag as a multi-robot rosbag2 bag, for tests and benchmarks.

The bag's scans (ROS 1 or ROS 2, every scan as recorded) are cut into K contiguous runs, one per
robot (``robot1`` .. ``robotK``), exactly as ``mrm import-carmen`` cuts a log (one function does
both): as if K robots had explored consecutive parts of the building at the same time, every
run's stamps shifted so that all robots start at the first run's start; ``--overlap-scans N``
gives each run the N scans before its own start. Each scan is written as ``/robotK/scan``
(frame ``robotK/laser``); reference poses, from ``--truth NAME.truth.csv`` or the bag's own
``ground_truth`` topic, as ``/robotK/ground_truth``, so that ``mrm replay`` and
``mrm evaluate`` score the cut like an imported CARMEN log. Scans without a reference pose are
kept (a laser's every scan) and left out of the scores. No odometry is written.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

from multi_robot_mapper.cli.common import CliError, check_limits, check_output
from multi_robot_mapper.cli.recordings import add_recording_options, load_recordings


def register(subparsers: Any) -> None:
    """Add ``import-bag`` to the ``mrm`` sub-command parsers."""
    parser = subparsers.add_parser(
        "import-bag",
        help="cut one robot's bag (ROS 1 or 2) into K robots' runs, written as a rosbag2 bag",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("bag", type=Path, help="rosbag2 folder, .mcap or ROS 1 .bag file")
    parser.add_argument("--robots", type=int, required=True, metavar="K", help="robots (>= 1)")
    parser.add_argument(
        "--overlap-scans",
        type=int,
        default=0,
        metavar="N",
        help="each robot also gets the N scans before its own run (default 0)",
    )
    parser.add_argument("--out", required=True, metavar="BAG", help="new bag directory")
    parser.add_argument(
        "--storage", choices=("mcap", "sqlite3"), default="mcap", help="rosbag2 storage format"
    )
    add_recording_options(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.io.bags import write_recordings
    from multi_robot_mapper.io.carmen import MIN_STAMP_STEP_S, increasing
    from multi_robot_mapper.io.recordings import cut_recording, geometry_summary

    check_limits(args, "robots", "overlap_scans")
    out = check_output(Path(args.out), kind="new")
    recordings, report = load_recordings(args, [args.bag])
    if len(recordings) != 1:
        raise CliError(
            f"{args.bag} holds {len(recordings)} robots ({', '.join(recordings)}): cutting "
            "needs one (--scan-topics picks one)"
        )
    (whole,) = recordings.values()
    if args.robots > len(whole.scans):
        raise CliError(f"--robots {args.robots} is more than the {len(whole.scans)} scans")
    stamps = np.array([s.stamp for s in whole.scans], dtype=np.float64)
    repaired = increasing(stamps)
    moved = int(np.count_nonzero(repaired != stamps))
    if moved:  # runs are cut and shifted by stamp: equal stamps would mix two scans' places
        whole = dataclasses.replace(
            whole,
            scans=[
                dataclasses.replace(s, stamp=float(t))
                for s, t in zip(whole.scans, repaired, strict=True)
            ],
        )
        report.notes.append(
            f"{moved} of {len(stamps)} scan stamps do not increase; moved to "
            f"{MIN_STAMP_STEP_S * 1e3:g} ms after the scan before"
        )
    runs = cut_recording(whole, args.robots, args.overlap_scans)
    write_recordings(out, runs, storage=args.storage)
    sizes = ", ".join(f"{r.name} {len(r.scans)}" for r in runs.values())
    posed = ", ".join(f"{r.name} {len(r.ground_truth)}" for r in runs.values())
    print(f"wrote {out} ({args.storage}): scans per robot: {sizes}")
    print(f"reference poses per robot: {posed}")
    for line in geometry_summary(recordings):
        print(line)
    for note in report.notes:  # after writing: an error must stay the only line on stderr
        print(f"note: {note}", file=sys.stderr)
    return 0
