"""``mrm``: the pipeline's command line.

mrm demo           simulated scans through a real robot_mapper node, and a picture
mrm frontend       the scan-to-segment front end over a CARMEN log, with statistics
mrm import-carmen  a CARMEN log cut into K robots, written as a rosbag2 file
mrm simulate       K simulated robots in a built-in world, written as a rosbag2 file
mrm replay         the pipeline offline on a rosbag2 file: map, trajectories, pictures
mrm evaluate       a replay's output scored against the bag's reference poses
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
    from multi_robot_mapper.cli.demo import PICTURE, run_demo

    check_limits(args, "seed")
    check_output(Path(args.out) / PICTURE, kind="file")  # before the run, not after it
    result = run_demo(Path(args.out), seed=args.seed)
    lat = np.asarray(result.latency_s) * 1e3
    print(
        f"scans published to robot_mapper: {result.scans_sent}, answered: {result.scans_answered}"
    )
    if result.segments_per_scan:
        print(f"segments per scan: median {np.median(result.segments_per_scan):.0f}")
    if lat.size:
        print(
            f"publish-to-segments latency: median {np.median(lat):.1f} ms, "
            f"p95 {np.percentile(lat, 95):.1f} ms"
        )
    print(f"picture: {result.picture}")
    return 0 if result.scans_answered == result.scans_sent else 1


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
    demo = sub.add_parser("demo", help="simulated scans through a robot_mapper node, and a picture")
    demo.add_argument("--out", default="demo_output", help="output folder")
    demo.add_argument("--seed", type=int, default=0)
    demo.set_defaults(func=_cmd_demo)
    frontend = sub.add_parser("frontend", help="front-end statistics over a CARMEN log")
    frontend.add_argument("log", help="CARMEN log (.log or .log.gz)")
    add_config_options(frontend)
    frontend.set_defaults(func=_cmd_frontend)
    from multi_robot_mapper.cli import evaluate, import_carmen, replay, simulate

    for command in (import_carmen, simulate, replay, evaluate):
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
