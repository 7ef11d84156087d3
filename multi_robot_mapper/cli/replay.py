"""``mrm replay BAG --out DIR [--method local|pivot|ffs|reference] [--config YAML]
[--merger-config YAML] [--set NAME=VALUE]``.

Runs the pipeline offline, as fast as the CPU allows, through the same core the nodes use, and
writes DIR/map.json, map.svg, map.png, trajectories/<robot>.tum, robots.json and stats.json.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from multi_robot_mapper.cli.common import (
    CliError,
    add_config_options,
    add_overwrite_option,
    check_output,
    load_mapper_config,
    load_merger_config,
)
from multi_robot_mapper.core.pipeline import METHODS, TimedLaserScan


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("replay", help="run the pipeline offline on a rosbag2 file")
    parser.add_argument("bag", type=Path, help="rosbag2 folder or .mcap file with */scan topics")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    add_overwrite_option(parser)
    parser.add_argument("--method", choices=METHODS, default="local")
    parser.add_argument("--scan-topics", default="/*/scan", help="topic pattern (fnmatch)")
    parser.add_argument(
        "--salvage",
        action="store_true",
        help="read every intact chunk of a damaged or cut MCAP bag (damaged chunks are skipped "
        "and counted; the exit code is then 1)",
    )
    add_config_options(parser, merging=True)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.cli.progress import ProgressBar
    from multi_robot_mapper.core.pipeline import (
        MethodNotImplementedError,
        require_method,
        run_offline,
    )
    from multi_robot_mapper.io import pictures
    from multi_robot_mapper.io.bags import ReadReport, read_recordings, reference_poses
    from multi_robot_mapper.io.outputs import staged_folder
    from multi_robot_mapper.io.results import ReplayResult, write_results

    config = load_mapper_config(args)
    merging = load_merger_config(args).merge
    out = check_output(Path(args.out), overwrite=args.overwrite)  # before any work
    try:
        require_method(args.method)  # before reading a large bag
    except MethodNotImplementedError as exc:
        raise CliError(str(exc)) from exc
    report = ReadReport()
    recordings = read_recordings(
        args.bag, scan_pattern=args.scan_topics, salvage=args.salvage, report=report
    )
    inputs: dict[str, Sequence[TimedLaserScan]] = {}
    for name, rec in recordings.items():
        stamps = np.array([s.stamp for s in rec.scans], dtype=np.float64)
        poses, found = reference_poses(rec, stamps)
        inputs[name] = [
            TimedLaserScan(s.stamp, s.scan, (float(p[0]), float(p[1]), float(p[2])) if ok else None)
            for s, p, ok in zip(rec.scans, poses, found, strict=True)
        ]
    if args.method == "reference" and not any(
        item.reference_pose is not None for scans in inputs.values() for item in scans
    ):
        raise CliError(f"{args.bag} has no <robot>/ground_truth poses: 'reference' needs them")
    bar = ProgressBar(f"replay {args.method}")
    try:
        offline = run_offline(
            inputs,
            args.method,
            config.extraction,
            progress=bar,
            local_mapping=config.local_mapping,
            merging=merging,
        )
    finally:
        bar.close()
    paths = {robot: poses for robot, (_, poses) in offline.trajectories.items()}
    title = f"{args.bag.name}: method '{args.method}'" + (
        " (scans at reference poses, not a mapping result)" if args.method == "reference" else ""
    )
    # Everything goes to a fresh folder that replaces --out only when complete: an interrupted
    # run leaves the old result, and no file of an earlier run stays beside the new ones.
    with staged_folder(out) as staging:
        write_results(
            staging,
            ReplayResult(
                method=args.method,
                robots=offline.robots,
                map_segments=offline.map_segments,
                segment_robot=offline.segment_robot,
                trajectories=offline.trajectories,
                robot_frames=offline.robot_frames,
                stats=offline.stats,
                probabilities=offline.probabilities,
                unmerged_reasons=offline.unmerged_reasons,
            ),
        )
        figure = pictures.draw_map(
            offline.map_segments, offline.segment_robot, offline.robots, paths, title
        )
        pictures.save_figure(figure, staging / "map.png", staging / "map.svg")
    print(
        f"{len(offline.robots)} robots, {offline.stats['scans_total']} scans "
        f"({offline.stats['scans_posed']} posed), {len(offline.map_segments)} map segments, "
        f"{offline.stats['total_s']} s -> {out}"
    )
    for note in report.notes:  # replayed, but not all of the bag: said, and exit code 1
        print(f"mrm replay: warning: {note}", file=sys.stderr)
    return 1 if report.notes else 0
