"""``mrm replay BAG [BAG ...] --out DIR [--method local|pivot|ffs|reference] [--names N,...]
[--beam-geometry SPEC] [--truth CSV] [--config YAML] [--merger-config YAML] [--set NAME=VALUE]``.

Runs the pipeline offline, as fast as the CPU allows, through the same core the nodes use, and
writes DIR/map.json, map.svg, map.png, trajectories/<robot>.tum, robots.json and stats.json.
A bag is a rosbag2 folder (mcap or sqlite3), a ``.mcap`` file or a ROS 1 ``.bag``; one bag may
hold every robot (``/<robot>/scan``) or each robot bring its own (one bag per robot).
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
from multi_robot_mapper.cli.recordings import add_recording_options, load_recordings
from multi_robot_mapper.core.pipeline import METHODS, TimedLaserScan


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "replay", help="run the pipeline offline on bags (rosbag2 or ROS 1; one or one per robot)"
    )
    parser.add_argument(
        "bags",
        nargs="+",
        type=Path,
        metavar="BAG",
        help="rosbag2 folder, .mcap file or ROS 1 .bag file with /<robot>/scan or /scan topics; "
        "several for one bag per robot",
    )
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    add_overwrite_option(parser)
    parser.add_argument("--method", choices=METHODS, default="local")
    add_recording_options(parser)
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
    from multi_robot_mapper.io.bags import reference_poses
    from multi_robot_mapper.io.outputs import staged_folder
    from multi_robot_mapper.io.results import ReplayResult, write_results

    config = load_mapper_config(args)
    merging = load_merger_config(args).merge
    out = check_output(Path(args.out), overwrite=args.overwrite)  # before any work
    try:
        require_method(args.method)  # before reading a large bag
    except MethodNotImplementedError as exc:
        raise CliError(str(exc)) from exc
    recordings, report = load_recordings(args, args.bags, salvage=args.salvage)
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
        raise CliError(
            f"{', '.join(map(str, args.bags))}: no reference pose (a <robot>/ground_truth topic "
            "or --truth): 'reference' needs them"
        )
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
    title = f"{', '.join(b.name for b in args.bags)}: method '{args.method}'" + (
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
