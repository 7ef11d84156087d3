"""``mrm import-carmen``: one CARMEN log as a multi-robot rosbag2 bag.

The log's scans are cut into K contiguous runs, one per robot (``robot1`` .. ``robotK``), as if
K robots had explored consecutive parts of the building at the same time: every run's stamps
are shifted so that all robots start at the first run's start. With ``--overlap-scans N`` each
run also gets the N scans before its own start, so neighbouring robots share some place (what a
map merger needs). Each scan is written as ``/robotK/scan`` (frame ``robotK/laser``) with the
log's reference laser pose as ``/robotK/ground_truth`` (frame ``world``); no odometry is written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.cli.common import CliError
from multi_robot_mapper.io.bags import RobotRecording, TimedPose, TimedScan
from multi_robot_mapper.io.carmen import CarmenFormatError, carmen_scan_data, read_carmen

# Stamps of a run must increase for replay and for sorting by stamp. Some logs repeat or step
# back their ipc timestamps (intel: 4 times; csail stores them to 6 digits, so all 406 scans
# share 2 values); such a scan is put this much after the one before it.
MIN_STAMP_STEP_S = 1e-3


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
    parser.add_argument("--out", required=True, metavar="BAG", help="new bag directory")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    parser.set_defaults(func=run)


def split_runs(count: int, robots: int, overlap: int) -> list[tuple[int, int]]:
    """``[start, stop)`` scan indices of each robot's run: K contiguous runs of ``count`` scans,
    each but the first extended ``overlap`` scans back (never before the first scan)."""
    bounds = np.linspace(0, count, robots + 1).round().astype(np.int64).tolist()
    return [(max(0, bounds[k] - overlap), bounds[k + 1]) for k in range(robots)]


# Scan period assumed for logs whose own clock cannot order the scans.
NOMINAL_PERIOD_S = 1.0


def increasing(stamps: NDArray[np.float64], step: float = MIN_STAMP_STEP_S) -> NDArray[np.float64]:
    """``stamps`` made strictly increasing: each at least ``step`` after the one before."""
    # stamp_i = max over j <= i of (t_j + (i - j) step): a running maximum after removing the
    # ramp, added back (vectorised form of t_i = max(t_i, t_{i-1} + step)).
    ramp = step * np.arange(len(stamps), dtype=np.float64)
    return np.asarray(np.maximum.accumulate(stamps - ramp) + ramp)


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.io.bags import write_recordings

    log = Path(args.log)
    if not log.is_file():
        raise CliError(f"no such log file: {log}")
    if args.robots < 1:
        raise CliError(f"--robots must be at least 1, got {args.robots}")
    if args.overlap_scans < 0:
        raise CliError(f"--overlap-scans must be >= 0, got {args.overlap_scans}")
    out = Path(args.out)
    if out.exists():
        raise CliError(f"{out} already exists; not overwriting it")
    try:
        scans = list(read_carmen(log))
    except (CarmenFormatError, OSError, EOFError, UnicodeError) as exc:
        raise CliError(f"cannot read {log}: {exc}") from exc
    if not scans:
        raise CliError(f"{log} has no FLASER scan")
    if args.robots > len(scans):
        raise CliError(f"--robots {args.robots} is more than the {len(scans)} scans of {log}")

    logged = np.array([s.timestamp for s in scans], dtype=np.float64)
    repeats = int(np.count_nonzero(np.diff(logged) <= 0.0))
    if repeats > len(scans) // 2:
        # The log's clock is too coarse to order its scans (csail's are written with six
        # significant digits): number them at a nominal period instead of inventing times.
        stamps = logged[0] + NOMINAL_PERIOD_S * np.arange(len(scans), dtype=np.float64)
        note = (
            f"note: {repeats} of {len(scans)} timestamps of {log.name} repeat (too coarse a "
            f"clock); stamps set one scan per {NOMINAL_PERIOD_S:g} s from the first"
        )
    else:
        stamps = increasing(logged)
        adjusted = int(np.count_nonzero(stamps != logged))
        note = (
            f"note: {adjusted} of {len(scans)} timestamps of {log.name} do not increase; "
            f"moved to {MIN_STAMP_STEP_S * 1e3:g} ms after the scan before"
            if adjusted
            else ""
        )
    recordings: dict[str, RobotRecording] = {}
    for k, (start, stop) in enumerate(split_runs(len(scans), args.robots, args.overlap_scans)):
        name = f"robot{k + 1}"
        shift = stamps[start] - stamps[0]  # every run starts at the first run's start
        run_scans, truth = [], []
        for i in range(start, stop):
            stamp = float(stamps[i] - shift)
            run_scans.append(TimedScan(stamp, f"{name}/laser", carmen_scan_data(scans[i])))
            truth.append(TimedPose(stamp, scans[i].reference_pose, "world"))
        recordings[name] = RobotRecording(name=name, scans=run_scans, ground_truth=truth)
    write_recordings(out, recordings, storage=args.storage)
    sizes = ", ".join(f"{r.name} {len(r.scans)}" for r in recordings.values())
    print(f"wrote {out} ({args.storage}): scans per robot: {sizes}")
    if note:  # after writing: an error must stay the only line on stderr
        print(note, file=sys.stderr)
    return 0
