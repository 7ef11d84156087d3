"""``mrm simulate``: K simulated robots in a built-in world, written as a rosbag2 bag.

Each robot drives its own stretch of a tour through the world, neighbours sharing part of it,
and scans at the laser rate from the same first stamp (ray casting with Gaussian range noise and
dropouts; a seed always gives the same bag). Topics are those of ``mrm import-carmen``:
``/robotK/scan`` (frame ``robotK/laser``) and ``/robotK/ground_truth`` (frame ``world``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from multi_robot_mapper.cli.common import (
    MAX_SIMULATED_READINGS,
    CliError,
    check_limits,
    check_output,
)
from multi_robot_mapper.core.simulation import LaserModel, clutter_for, simulate_robots
from multi_robot_mapper.core.worlds import ROUTES

DEFAULT_LASER = LaserModel()  # Hokuyo UTM-30LX
DEFAULT_DURATION_S = 20.0  # about 16 m of driving per robot at the default speed
SPEED_M_S = 0.8  # a walking-pace indoor robot


def register(subparsers: Any) -> None:
    """Add ``simulate`` to the ``mrm`` sub-command parsers."""
    parser = subparsers.add_parser(
        "simulate",
        help="simulate K robots scanning a built-in world and write a rosbag2 bag",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--robots", type=int, required=True, metavar="K", help="robots (>= 1)")
    parser.add_argument("--out", required=True, metavar="BAG", help="new bag directory")
    parser.add_argument(
        "--world", default="office", help=f"one of {', '.join(ROUTES)} (default office)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--rate", type=float, default=DEFAULT_LASER.rate, metavar="HZ", help="scans per second"
    )
    parser.add_argument(
        "--beams", type=int, default=DEFAULT_LASER.beams, metavar="N", help="beams over 270 deg"
    )
    parser.add_argument(
        "--noise",
        type=float,
        default=DEFAULT_LASER.range_noise,
        metavar="SIGMA",
        help="range noise standard deviation, m",
    )
    parser.add_argument(
        "--duration", type=float, default=DEFAULT_DURATION_S, metavar="SECONDS", help="drive time"
    )
    parser.add_argument(
        "--clutter",
        type=float,
        default=0.0,
        metavar="DENSITY",
        help="objects per square metre of free floor: chair and table legs, pillars and "
        "walking people, kept off the robots' route (default 0: an empty building; 0.2 is a "
        "busy office, 0.5 a crowded hall)",
    )
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.io.bags import recording_of, write_recordings

    check_limits(args, "robots", "seed", "rate", "beams", "noise", "duration", "clutter")
    if args.world not in ROUTES:
        raise CliError(f"unknown world {args.world!r}; known: {', '.join(ROUTES)}")
    readings = args.robots * args.rate * args.duration * args.beams
    if readings > MAX_SIMULATED_READINGS:
        raise CliError(
            f"--robots x --rate x --duration x --beams = {readings:.3g} readings, more than "
            f"{MAX_SIMULATED_READINGS:.0e} (about 1 GB in memory); simulate less"
        )
    out = check_output(Path(args.out), kind="new")

    laser = LaserModel(beams=args.beams, range_noise=args.noise, rate=args.rate)
    runs = simulate_robots(
        args.world,
        args.robots,
        laser,
        seed=args.seed,
        duration=args.duration,
        speed=SPEED_M_S,
        clutter=clutter_for(args.world, args.clutter, args.seed) if args.clutter > 0 else None,
    )
    recordings = {f"robot{k + 1}": recording_of(f"robot{k + 1}", run) for k, run in enumerate(runs)}
    write_recordings(out, recordings, storage=args.storage)
    count = sum(len(r.scans) for r in recordings.values())
    crowd = f", clutter {args.clutter:g} objects/m^2" if args.clutter > 0 else ""
    print(
        f"wrote {out} ({args.storage}): {args.robots} robots in {args.world!r}{crowd}, {count} "
        f"scans of {laser.beams} beams at {laser.rate:g} Hz"
    )
    return 0
