"""``mrm``: the pipeline's command line.

mrm demo           three simulated robots mapped live by the nodes, merged, drawn and scored
mrm frontend       the scan-to-segment front end over a CARMEN log, with statistics
mrm import-carmen  a CARMEN log cut into K robots, written as a rosbag2 file
mrm import-bag     one robot's bag (ROS 1 or 2) cut into K robots, written as a rosbag2 file
mrm simulate       K simulated robots in a built-in world, written as a rosbag2 file
mrm replay         the pipeline offline on bags (ROS 1 or 2): map, trajectories, pictures
mrm evaluate       a replay's output scored against reference poses and relations
mrm run            robot_mappers and a map_merger in one process, live (no launch files)
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from multi_robot_mapper.cli.common import (
    CliError,
    add_config_options,
    check_limits,
    check_output,
    load_mapper_config,
)
from multi_robot_mapper.core.config import ConfigError


def _cmd_demo(args: argparse.Namespace) -> int:
    from multi_robot_mapper.cli.demo import DemoScenario, run_demo

    check_limits(args, "seed", "speed")
    # Checked before the run, not after it; a folder from an earlier demo is written over
    # (make demo runs again into demo_output).
    check_output(Path(args.out), kind="folder", overwrite=True)
    scenario = DemoScenario(seed=args.seed, speed=args.speed)
    print(
        f"mrm demo: {scenario.robots} simulated robots in the {scenario.world} world, "
        f"{scenario.duration:g} s each, starting {scenario.stagger:g} s apart, played live at "
        f"{scenario.speed:g}x the laser's rate (40 Hz, 1081 beams) into robot_mapper and "
        "map_merger nodes ...",
        flush=True,
    )
    result = run_demo(Path(args.out), scenario)
    live = result.live
    sent = sum(live.play.published.values())
    received = sum(live.scans_received.values())
    late = np.asarray(live.play.late_s) * 1e3
    print(
        f"scans published {sent} in {live.play.wall_s:.1f} s"
        + (f" (p95 {np.percentile(late, 95):.1f} ms behind schedule)" if late.size else "")
        + f"; received by the robot_mappers {received} ("
        + ", ".join(f"{r} {n}" for r, n in live.scans_received.items())
        + ")"
    )
    if received < sent:
        print(
            f"  {sent - received} scans dropped in transit (sensor-data QoS keeps the newest 5 "
            "while a mapper is busy: the machine could not keep up; they count as unposed "
            "below; --speed 0.5 plays at half the pace)"
        )
    print()
    print(result.table)
    print()
    print("map_merger's last /diagnostics:")
    for line in result.statuses:
        print(f"  {line}")
    print()
    for name, path in result.files.items():
        print(f"{name + ':':<16} {path}")
    merged = len(result.merged)
    print(
        f"\n{merged} of {len(result.robots)} robots merged live"
        + ("" if live.settled else " (the last maps were still being merged at the end)")
        + f"; {result.wall_s:.0f} s in all"
    )
    return 0 if merged == len(result.robots) else 1


def _cmd_frontend(args: argparse.Namespace) -> int:
    from multi_robot_mapper.core.extraction import extract_scan
    from multi_robot_mapper.core.scan import ScanError
    from multi_robot_mapper.io.carmen import CarmenFormatError, carmen_scan_data, read_carmen

    config = load_mapper_config(args)
    if not Path(args.log).is_file():
        raise CliError(f"no such log file: {args.log}")
    segments, dropped, invalid, rejected = [], [], [], 0
    try:
        log = read_carmen(args.log)
    except (CarmenFormatError, OSError, UnicodeError) as exc:
        raise CliError(f"cannot read {args.log}: {exc}") from exc
    for scan in log:
        try:
            seg, valid = extract_scan(carmen_scan_data(scan), config.extraction)
        except ScanError:
            rejected += 1
            continue
        segments.append(len(seg))
        dropped.append(seg.dropped_points)
        invalid.append(valid.invalid_count)
    if not segments:
        raise CliError(f"{args.log} has no usable FLASER scan")
    for line in log.summary():
        print(line)
    print(f"scans: {len(segments)} (rejected {rejected})")
    print(f"segments per scan: median {np.median(segments):.0f}, mean {np.mean(segments):.1f}")
    print(f"points dropped in small clusters per scan: median {np.median(dropped):.0f}")
    print(f"beams without a valid return per scan: median {np.median(invalid):.0f}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mrm", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser(
        "demo", help="three simulated robots mapped and merged live by the nodes, drawn and scored"
    )
    demo.add_argument("--out", default="demo_output", help="output folder")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument(
        "--speed",
        type=float,
        default=1.0,
        help="play speed (1: real time, the laser's 40 Hz; 0.5: half as fast)",
    )
    demo.set_defaults(func=_cmd_demo)
    frontend = sub.add_parser("frontend", help="front-end statistics over a CARMEN log")
    frontend.add_argument("log", help="CARMEN log (.log or .log.gz)")
    add_config_options(frontend)
    frontend.set_defaults(func=_cmd_frontend)
    from multi_robot_mapper.cli import evaluate, import_bag, import_carmen, replay, run, simulate

    for command in (import_carmen, import_bag, simulate, replay, evaluate, run):
        command.register(sub)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every output being written is cleaned up."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated()


def main(argv: Sequence[str] | None = None) -> int:
    from multi_robot_mapper.io.bags import BagError
    from multi_robot_mapper.io.outputs import OutputError
    from multi_robot_mapper.io.results import ResultsError

    args = build_parser().parse_args(argv)
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        return int(args.func(args))
    except (CliError, ConfigError, BagError, ResultsError, OutputError) as exc:
        print(f"mrm {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except Terminated:
        print(f"mrm {args.command}: terminated; nothing half-written was left", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print(f"mrm {args.command}: interrupted; nothing half-written was left", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `mrm ... | head` closed the pipe: not an error
        sys.stderr.close()
        return 0
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
