"""``mrm import-carmen``: one CARMEN log as a multi-robot rosbag2 bag.

The log's scans are cut into K contiguous runs, one per robot (``robot1`` .. ``robotK``), as if
K robots had explored consecutive parts of the building at the same time: every run's stamps
are shifted so that all robots start at the first run's start. With ``--overlap-scans N`` each
run also gets the N scans before its own start, so neighbouring robots share some place (what a
map merger needs); ``mrm import-bag`` cuts a bag the same way (one function does both). Each
scan is written as ``/robotK/scan`` (frame ``robotK/laser``) with the log's reference laser pose
as ``/robotK/ground_truth`` (frame ``world``); no odometry is written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from multi_robot_mapper.cli.common import CliError, check_limits, check_output, missing_input
from multi_robot_mapper.io.bags import RobotRecording, TimedPose, TimedScan
from multi_robot_mapper.io.carmen import (
    CarmenFormatError,
    carmen_scan_data,
    increasing,
    monotonic_stamps,
    read_carmen,
)
from multi_robot_mapper.io.recordings import cut_recording, split_runs

__all__ = ["increasing", "register", "run", "split_runs"]


def register(subparsers: Any) -> None:
    """Add ``import-carmen`` to the ``mrm`` sub-command parsers."""
    parser = subparsers.add_parser(
        "import-carmen",
        help="split a CARMEN log into K robots' scans and write them as a rosbag2 bag",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("log", help="CARMEN log (.log or .log.gz)")
    parser.add_argument("--robots", type=int, required=True, metavar="K", help="robots (>= 1)")
    parser.add_argument(
        "--overlap-scans",
        type=int,
        default=0,
        metavar="N",
        help="each robot also gets the N scans before its own run (default 0)",
    )
    parser.add_argument(
        "--range-max",
        type=float,
        metavar="M",
        help="readings at or beyond M metres are 'no return' (default: from the log's PARAM "
        "robot_front_laser_max, else the value repeating at the top of its ranges)",
    )
    parser.add_argument("--out", required=True, metavar="BAG", help="new bag directory")
    parser.add_argument(
        "--storage", choices=("mcap", "sqlite3"), default="mcap", help="rosbag2 storage format"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.io.bags import write_recordings

    log = Path(args.log)
    if not log.is_file():
        raise missing_input(log, "log file")
    check_limits(args, "robots", "overlap_scans", "range_max")
    out = check_output(Path(args.out), kind="new")
    try:
        scans = read_carmen(log, range_max=args.range_max)
    except (CarmenFormatError, OSError, UnicodeError) as exc:
        raise CliError(f"cannot read {log}: {exc}") from exc
    if not scans:
        skipped = "; ".join(scans.skipped_summary())
        raise CliError(f"{log} has no usable FLASER scan" + (f" ({skipped})" if skipped else ""))
    if args.robots > len(scans):
        raise CliError(f"--robots {args.robots} is more than the {len(scans)} scans of {log}")

    logged = np.array([s.timestamp for s in scans], dtype=np.float64)
    stamps, notes = monotonic_stamps(logged, log.name)
    whole = RobotRecording(
        name=log.stem,
        scans=[
            TimedScan(float(t), "laser", carmen_scan_data(s))
            for t, s in zip(stamps, scans, strict=True)
        ],
        ground_truth=[
            TimedPose(float(t), s.reference_pose, "world")
            for t, s in zip(stamps, scans, strict=True)
        ],
    )
    recordings = cut_recording(whole, args.robots, args.overlap_scans)
    write_recordings(out, recordings, storage=args.storage)
    sizes = ", ".join(f"{r.name} {len(r.scans)}" for r in recordings.values())
    print(f"wrote {out} ({args.storage}): scans per robot: {sizes}")
    for line in scans.summary():
        print(line)
    for note in notes:  # after writing: an error must stay the only line on stderr
        print(f"note: {note}", file=sys.stderr)
    return 0
