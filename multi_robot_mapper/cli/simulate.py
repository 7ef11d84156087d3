"""``mrm simulate``: K simulated robots in a built-in world or a generated building, written as
a rosbag2 bag.

In a built-in world (office, corridors, rooms) each robot drives its own stretch of a tour
through the world, neighbours sharing part of it. In a generated building (``--world
generated``) the seed draws a floor plan (or ``--kind`` and ``--size`` choose it) and each robot
drives its own path through it from a random start, sharing the ``--overlap`` share of its
drive with the others. All robots scan at the laser rate from the same first stamp (ray casting
with Gaussian range noise and dropouts; glass returns nothing; a seed always gives the same
bag). Topics are those of ``mrm import-carmen``: ``/robotK/scan`` (frame ``robotK/laser``) and
``/robotK/ground_truth`` (frame ``world``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from multi_robot_mapper.cli.common import (
    MAX_SIMULATED_READINGS,
    CliError,
    check_limits,
    check_output,
)
from multi_robot_mapper.core.simulation import (
    LASERS,
    LaserModel,
    SimulatedRobot,
    clutter_for,
    simulate_robots,
)
from multi_robot_mapper.core.worlds import ROUTES

DEFAULT_LASER = "utm30lx"
DEFAULT_DURATION_S = 20.0  # about 16 m of driving per robot at the default speed
SPEED_M_S = 0.8  # a walking-pace indoor robot
GENERATED = "generated"
DEFAULT_OVERLAP = "small"
DEFAULT_SPARSE_M = 0.5
# Options only a generated building takes, and their "not given" values.
_GENERATED_ONLY = MappingProxyType(
    {
        "kind": None,
        "size": None,
        "glass": False,
        "people": None,
        "overlap": None,
        "sparse": None,
    }
)


def register(subparsers: Any) -> None:
    """Add ``simulate`` to the ``mrm`` sub-command parsers."""
    parser = subparsers.add_parser(
        "simulate",
        help="simulate K robots scanning a built-in world or a generated building and write "
        "a rosbag2 bag",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--robots", type=int, required=True, metavar="K", help="robots (>= 1)")
    parser.add_argument("--out", required=True, metavar="BAG", help="new bag directory")
    parser.add_argument(
        "--world",
        default="office",
        help=f"one of {', '.join(ROUTES)} or {GENERATED} (a building drawn from --seed; "
        "default office)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    _add_laser_options(parser)
    parser.add_argument(
        "--duration",
        type=float,
        default=DEFAULT_DURATION_S,
        metavar="SECONDS",
        help=f"drive time (default {DEFAULT_DURATION_S:g}; robots drive at {SPEED_M_S} m/s)",
    )
    parser.add_argument(
        "--clutter",
        type=float,
        default=0.0,
        metavar="DENSITY",
        help="objects per square metre of free floor: chair and table legs, pillars and "
        "walking people, kept off the robots' route (default 0: an empty building; 0.2 is a "
        "busy office, 0.5 a crowded hall); in a generated building furniture only, per "
        "square metre of room and hall floor (--people adds people)",
    )
    _add_generated_options(parser)
    parser.add_argument(
        "--storage", choices=("mcap", "sqlite3"), default="mcap", help="bag format (default mcap)"
    )
    parser.set_defaults(func=run)


def _add_laser_options(parser: argparse.ArgumentParser) -> None:
    """The laser's options: a model, and what of it to override."""
    parser.add_argument(
        "--laser",
        choices=tuple(LASERS),
        default=DEFAULT_LASER,
        help="utm30lx: Hokuyo UTM-30LX, 1081 beams over 270 deg, 30 m, 40 Hz; lms: SICK LMS "
        "200 as in the CARMEN logs, 181 beams over 180 deg, 80 m, 10 Hz; the same noise "
        f"model (default {DEFAULT_LASER})",
    )
    parser.add_argument(
        "--rate", type=float, metavar="HZ", help="scans per second (default: the laser's)"
    )
    parser.add_argument(
        "--beams",
        type=int,
        metavar="N",
        help="beams over the laser's field of view (default: the laser's)",
    )
    parser.add_argument(
        "--noise",
        type=float,
        metavar="SIGMA",
        help="range noise standard deviation, m (default: the laser's, 0.01)",
    )


def _add_generated_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``--world generated``, in their own group of the help."""
    from multi_robot_mapper.core.building_kinds import PLAN_KINDS
    from multi_robot_mapper.core.building_runs import OVERLAP_LEVELS

    generated = parser.add_argument_group(f"generated buildings (--world {GENERATED})")
    generated.add_argument(
        "--kind",
        choices=tuple(PLAN_KINDS),
        help="plan kind (default: drawn from the seed)",
    )
    generated.add_argument(
        "--size",
        type=float,
        metavar="METRES",
        help="the plan's largest extent, 20-200 m (default: drawn from the seed, "
        "log-uniform in 20-200 m)",
    )
    generated.add_argument(
        "--glass",
        action="store_true",
        help="glass fronts and back windows on some rooms, a glass stretch of an outer wall: "
        "panes stop the beam and return nothing (default off)",
    )
    generated.add_argument(
        "--people",
        type=int,
        metavar="N",
        help="people walking to and fro along the robots' lanes (default 0)",
    )
    generated.add_argument(
        "--overlap",
        choices=(*OVERLAP_LEVELS, "random"),
        help="share of each robot's route driven in a part of the building all robots share: "
        "none 0 (each robot in its own part), small 0.1, large 0.6 (the ground really shared "
        "is about 0, 1/3 and 3/4 of a route), random drawn from the seed in [0, 0.9] "
        f"(default {DEFAULT_OVERLAP})",
    )
    generated.add_argument(
        "--sparse",
        type=float,
        nargs="?",
        const=DEFAULT_SPARSE_M,
        metavar="METRES",
        help="keep a scan only every METRES m of driving or 15 deg of turning, as in the "
        f"CARMEN corrected logs (METRES default {DEFAULT_SPARSE_M}; default off: every scan)",
    )


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.io.bags import recording_of, write_recordings

    numbers = ("robots", "seed", "rate", "beams", "noise", "duration", "clutter")
    check_limits(args, *numbers, "size", "people", "sparse")
    laser = _laser(args)
    if args.world == GENERATED:
        out, runs, description = _generated(args, laser)
    else:
        out, runs, description = _built_in(args, laser)
    recordings = {f"robot{k + 1}": recording_of(f"robot{k + 1}", run) for k, run in enumerate(runs)}
    write_recordings(out, recordings, storage=args.storage)
    count = sum(len(r.scans) for r in recordings.values())
    print(
        f"wrote {out} ({args.storage}): {args.robots} robots in {description}, {count} scans "
        f"of {laser.beams} beams at {laser.rate:g} Hz"
    )
    return 0


def _laser(args: argparse.Namespace) -> LaserModel:
    base = LASERS[args.laser]
    return LaserModel(
        beams=base.beams if args.beams is None else args.beams,
        field_of_view=base.field_of_view,
        range_min=base.range_min,
        range_max=base.range_max,
        range_noise=base.range_noise if args.noise is None else args.noise,
        dropout=base.dropout,
        rate=base.rate if args.rate is None else args.rate,
    )


def _check_readings(count: int, laser: LaserModel) -> None:
    readings = count * laser.beams
    if readings > MAX_SIMULATED_READINGS:
        raise CliError(
            f"{count} scans x {laser.beams} beams = {readings:.3g} readings, more than "
            f"{MAX_SIMULATED_READINGS:.0e} (about 1 GB in memory); simulate less (fewer "
            "--robots, a shorter --duration, a lower --rate or fewer --beams)"
        )


def _built_in(
    args: argparse.Namespace, laser: LaserModel
) -> tuple[Path, list[SimulatedRobot], str]:
    if args.world not in ROUTES:
        raise CliError(f"unknown world {args.world!r}; known: {', '.join(ROUTES)}, {GENERATED}")
    given = [name for name, unset in _GENERATED_ONLY.items() if getattr(args, name) != unset]
    if given:
        options = ", ".join(f"--{name}" for name in given)
        raise CliError(f"{options} only with --world {GENERATED}")
    _check_readings(round(args.robots * laser.rate * args.duration), laser)
    out = check_output(Path(args.out), kind="new")
    runs = simulate_robots(
        args.world,
        args.robots,
        laser,
        seed=args.seed,
        duration=args.duration,
        speed=SPEED_M_S,
        clutter=clutter_for(args.world, args.clutter, args.seed) if args.clutter > 0 else None,
    )
    crowd = f", clutter {args.clutter:g} objects/m^2" if args.clutter > 0 else ""
    return out, runs, f"{args.world!r}{crowd}"


def _generated(
    args: argparse.Namespace, laser: LaserModel
) -> tuple[Path, list[SimulatedRobot], str]:
    from multi_robot_mapper.core.building_runs import (
        OVERLAP_LEVELS,
        SparseSpacing,
        drive_routes,
        plan_routes,
        scan_drives,
    )
    from multi_robot_mapper.core.buildings import generate_building

    out = check_output(Path(args.out), kind="new")
    level = args.overlap or DEFAULT_OVERLAP
    if level == "random":
        draw = np.random.default_rng(np.random.SeedSequence(args.seed, spawn_key=(2001,)))
        overlap = float(draw.uniform(0.0, 0.9))
    else:
        overlap = OVERLAP_LEVELS[level]
    building = generate_building(
        args.seed,
        kind=args.kind,
        size=args.size,
        glass=args.glass,
        clutter=args.clutter,
        people=args.people or 0,
    )
    if args.robots > len(building.nodes):
        raise CliError(
            f"--robots {args.robots}: the {building.kind} building of seed {args.seed} has "
            f"only {len(building.nodes)} waypoints; use fewer robots or a larger --size"
        )
    paths = plan_routes(building, args.robots, SPEED_M_S * args.duration, overlap, args.seed)
    sparse = None if args.sparse is None else SparseSpacing(distance=args.sparse)
    drives = drive_routes(paths, SPEED_M_S, laser.rate, args.duration, sparse)
    _check_readings(sum(len(d.stamps) for d in drives), laser)
    runs = scan_drives(building, drives, laser, args.seed)
    extras = [f"{len(building.glass)} glass panes"] if args.glass else []
    extras += [f"furniture {args.clutter:g}/m^2"] if args.clutter > 0 else []
    extras += [f"{args.people} people"] if args.people else []
    extras += [f"sparse: a scan every {args.sparse:g} m or 15 deg"] if sparse else []
    return (
        out,
        runs,
        (
            f"a generated {building.kind} building (seed {args.seed}, {building.size:.0f} m, "
            f"symmetry {building.symmetry}{''.join(', ' + e for e in extras)}), overlap {level} "
            f"{overlap:.2f}"
        ),
    )
