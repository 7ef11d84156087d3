"""``mrm``: the pipeline's command line (``mrm --help`` lists the commands).

Only the standard library is imported here: the commands import what they need once they run,
so that Ctrl-C at any moment, even while numpy loads, ends with one line and exit code 130.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from multi_robot_mapper.cli.interrupts import (
    InterruptLatch,
    caused_by_interrupt,
    interrupt_received,
    raise_if_interrupted,
)

if TYPE_CHECKING:  # for annotations only: the commands import what they need as they run
    from multi_robot_mapper.cli.demo import LiveOutcome

DESCRIPTION = (
    "Multi-robot 2-D mapping from laser scans without odometry: bags in, one merged map out."
)
EPILOG = """\
Start with:
  mrm replay BAG --out DIR --record DIR/replay.mcap
    a merged map.png, map.json, trajectories, and an MCAP file for Foxglove or ros2 bag play
  mrm COMMAND --help
    a command's options, each with its default
"""
# The errors a user can cause, as (module, class): printed as one line, exit code 2. Looked up
# in sys.modules, so that none of those modules is imported before the command needs it (an
# exception of a class whose module was never imported cannot be raised).
USER_ERRORS = (
    ("multi_robot_mapper.cli.common", "CliError"),
    ("multi_robot_mapper.core.config", "ConfigError"),
    ("multi_robot_mapper.io.bags", "BagError"),
    ("multi_robot_mapper.io.results", "ResultsError"),
    ("multi_robot_mapper.io.outputs", "OutputError"),
)


def _print_scans(live: LiveOutcome) -> None:
    """The demo's scans: published, received by the robot_mappers, dropped and why."""
    import numpy as np

    from multi_robot_mapper.ros.robot_mapper import SCAN_QUEUE_DEPTH

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
    stale = sum(live.scans_stale.values())
    if received < sent or stale:
        print(
            f"  {sent - received + stale} scans dropped: {sent - received} in transit, {stale} "
            f"received but older than scan_max_queue_delay when their turn came (a mapper keeps "
            f"the newest {SCAN_QUEUE_DEPTH} while it is busy and maps the fresh ones first: the "
            "machine could not keep up; they count as unposed below; --speed 0.5 plays at half "
            "the pace)"
        )


def _cmd_demo(args: argparse.Namespace) -> int:
    from multi_robot_mapper.cli.common import check_limits, check_output
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
    _print_scans(result.live)
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
    wrong = [r for r in result.merged if r not in result.metrics.merged_robots]
    print(
        f"\n{merged} of {len(result.robots)} robots merged live"
        + ("" if result.live.settled else " (the last maps were still being merged at the end)")
        + f"; {result.wall_s:.0f} s in all"
    )
    if wrong:
        print(f"placed wrong by the simulation's truth: {', '.join(wrong)}")
    # A robot left unmerged is the merger being sure of nothing it publishes (its reason is in
    # the diagnostics above); a robot placed wrong is a failure.
    return 1 if wrong else 0


def _cmd_frontend(args: argparse.Namespace) -> int:
    import numpy as np

    from multi_robot_mapper.cli.common import CliError, load_mapper_config, missing_input
    from multi_robot_mapper.core.extraction import extract_scan
    from multi_robot_mapper.core.scan import ScanError
    from multi_robot_mapper.io.carmen import CarmenFormatError, carmen_scan_data, read_carmen

    config = load_mapper_config(args)
    if not Path(args.log).is_file():
        raise missing_input(args.log, "log file")
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
    from multi_robot_mapper.cli import evaluate, import_bag, import_carmen, replay, run, simulate
    from multi_robot_mapper.cli.common import HelpFormatter, add_config_options, finish_parsers

    parser = argparse.ArgumentParser(
        prog="mrm", description=DESCRIPTION, epilog=EPILOG, formatter_class=HelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True, title="commands", metavar="COMMAND")
    demo = sub.add_parser(
        "demo", help="three simulated robots mapped and merged live by the nodes, drawn and scored"
    )
    demo.add_argument("--out", default="demo_output", help="output folder")
    demo.add_argument(
        "--seed", type=int, default=0, help="random seed of the robots' scans (range noise)"
    )
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
    for command in (import_carmen, import_bag, simulate, replay, evaluate, run):
        command.register(sub)
    finish_parsers(parser)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every output being written is cleaned up."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated()


def _is_user_error(exc: BaseException) -> bool:
    for module, name in USER_ERRORS:
        kind = getattr(sys.modules.get(module), name, None)
        if isinstance(kind, type) and isinstance(exc, kind):
            return True
    return False


def _command_of(argv: Sequence[str]) -> str:
    """The command named in ``argv`` before it is parsed (for a message of an early Ctrl-C)."""
    return next((a for a in argv if not a.startswith("-")), "")


def _interrupted(name: str, terminated: bool, as_program: bool, in_main_thread: bool) -> int:
    """Say that the command was interrupted (SIGINT) or terminated (SIGTERM): one line, exit
    code 130 or 143."""
    print(
        f"{name}: {'terminated' if terminated else 'interrupted'}; nothing half-written was left",
        file=sys.stderr,
    )
    code = 143 if terminated else 130
    if as_program and in_main_thread:
        # Everything was cleaned up on the way here. Exit now: a second Ctrl-C during the
        # interpreter's shutdown would print a traceback, and an interrupt that went
        # through code a C++ extension ran with PyRun_String (gtsam's pybind11, while
        # importing) makes the interpreter kill itself with SIGINT at exit (-2, not 130).
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; exit codes: 0 done, 1 done with a warning, 2 a user error, 130 Ctrl-C,
    143 SIGTERM. ``argv`` None: this process is ``mrm`` (sys.argv; a second Ctrl-C while the
    interpreter shuts down is then ignored, so that it prints no traceback either)."""
    as_program = argv is None
    words = list(sys.argv[1:] if argv is None else argv)
    name = " ".join(["mrm", _command_of(words)]).strip()
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous_term = signal.signal(signal.SIGTERM, _terminate) if in_main_thread else None
    previous_int = signal.signal(signal.SIGINT, InterruptLatch()) if in_main_thread else None
    try:
        args = build_parser().parse_args(words)
        raise_if_interrupted()  # one a library swallowed while the commands' imports ran
        name = f"mrm {args.command}"
        return int(args.func(args))
    except KeyboardInterrupt as exc:
        return _interrupted(name, isinstance(exc, Terminated), as_program, in_main_thread)
    except BrokenPipeError:  # `mrm ... | head` closed the pipe: not an error
        sys.stderr.close()
        return 0
    except Exception as exc:
        if interrupt_received() or caused_by_interrupt(exc):
            return _interrupted(name, False, as_program, in_main_thread)
        if not _is_user_error(exc):
            raise
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    finally:
        if previous_term is not None:
            signal.signal(signal.SIGTERM, previous_term)
        if previous_int is not None:
            signal.signal(signal.SIGINT, previous_int)


if __name__ == "__main__":
    sys.exit(main())
