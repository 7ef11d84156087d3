"""``mrm replay BAG [BAG ...] --out DIR [--record FILE.mcap] [--method pivot|ffs|local|reference]``:
the pipeline offline on bags, as fast as the CPU allows, through the same core the nodes use.

Writes DIR/map.json, map.svg, map.png (the merged map; a robot that could not be merged is drawn
in a panel of its own, in its own frame), trajectories/<robot>.tum, robots.json (each robot's
placement and its probability, or why it is unmerged), stats.json and replay.json (the bags read
and the options they were read with, so that mrm evaluate DIR needs no --bag). With --record,
also an MCAP file of the merger's outputs as they evolved (the global map, the occupancy grid,
the robot frames as TF, the trajectories and the diagnostics, every --record-period seconds of
bag time), which Foxglove opens and ros2 bag play replays (config/foxglove_layout.json,
config/multi_robot_mapper.rviz). A bag is a rosbag2 folder (mcap or sqlite3), a .mcap file or a
ROS 1 .bag; one bag may hold every robot (/<robot>/scan) or each robot bring its own (one bag
per robot). The last line printed says how many robots were merged, and why any was not.
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from multi_robot_mapper.cli.common import (
    CliError,
    add_config_options,
    add_overwrite_option,
    check_limits,
    check_output,
    load_mapper_config,
    load_merger_config,
)
from multi_robot_mapper.cli.recordings import (
    add_recording_options,
    load_recordings,
    replayed_bags,
)
from multi_robot_mapper.core.pipeline import METHODS, OfflineMap, TimedLaserScan
from multi_robot_mapper.io.outputs import staged_folder
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.merger_config import MapMergerConfig

RECORD_PERIOD_S = 10.0


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "replay",
        help="run the pipeline offline on bags (rosbag2 or ROS 1; one or one per robot)",
        description=__doc__,
    )
    parser.add_argument(
        "bags",
        nargs="+",
        type=Path,
        metavar="BAG",
        help="rosbag2 folder, .mcap file or ROS 1 .bag file with /<robot>/scan or /scan topics; "
        "several for one bag per robot",
    )
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    add_overwrite_option(parser)
    parser.add_argument(
        "--method",
        choices=METHODS,
        default="pivot",
        help="pivot: local mapping, then every robot's map merged in one joint graph; ffs: pivot, "
        "then Force Field Simulation; local: each robot mapped in its own frame, never merged; "
        "reference: scans at their reference poses (checks the evaluator, not a mapping result)",
    )
    parser.add_argument(
        "--record",
        type=Path,
        metavar="FILE.mcap",
        help="also record the merger's outputs as they evolved to this MCAP file, for Foxglove "
        "and ros2 bag play (default: none; needs --method pivot or ffs)",
    )
    parser.add_argument(
        "--record-period",
        type=float,
        default=RECORD_PERIOD_S,
        metavar="S",
        help="seconds of bag time between two recorded merges",
    )
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
    from multi_robot_mapper.core.pipeline import require_method

    config = load_mapper_config(args)
    merger = load_merger_config(args)
    out = check_output(Path(args.out), overwrite=args.overwrite)  # before any work
    check_limits(args, "record_period")
    try:
        require_method(args.method)  # before reading a large bag
    except ValueError as exc:
        raise CliError(str(exc)) from exc
    record = _record_path(args)
    recordings, report = load_recordings(args, args.bags, salvage=args.salvage)
    inputs = _inputs(recordings)
    if args.method == "reference" and not any(
        item.reference_pose is not None for scans in inputs.values() for item in scans
    ):
        raise CliError(
            f"{', '.join(map(str, args.bags))}: no reference pose (a <robot>/ground_truth topic "
            "or --truth): 'reference' needs them"
        )
    # Everything goes to a fresh folder that replaces --out only when complete: an interrupted
    # run leaves the old result, and no file of an earlier run stays beside the new ones. A
    # recording asked for inside --out is written into that folder too.
    with staged_folder(out) as staging:
        inside = record is not None and record.resolve().is_relative_to(out.resolve())
        target = staging / record.resolve().relative_to(out.resolve()) if inside else record
        offline, recorded = _replay(args, inputs, config, merger, target)
        _write_outputs(args, staging, offline)
    print(
        f"{len(offline.robots)} robots, {offline.stats['scans_total']} scans "
        f"({offline.stats['scans_posed']} posed), {len(offline.map_segments)} map segments, "
        f"{offline.stats['total_s']} s -> {out}"
    )
    if record is not None:
        print(f"recorded {recorded} -> {record}")
    for note in report.notes:  # replayed, but not all of the bag: said, and exit code 1
        print(f"mrm replay: warning: {note}", file=sys.stderr)
    print(merge_summary(offline, args.method))
    return 1 if report.notes else 0


def _record_path(args: argparse.Namespace) -> Path | None:
    """``--record``'s file, checked before any work."""
    from multi_robot_mapper.core.merging.methods import MERGE_METHODS

    if args.record is None:
        return None
    record = Path(args.record)
    if args.method not in MERGE_METHODS:
        raise CliError(
            f"--record records the merger's outputs: it needs --method "
            f"{' or '.join(MERGE_METHODS)} (method '{args.method}' merges nothing)"
        )
    if record.suffix != ".mcap":
        raise CliError(f"--record {record}: the file name must end in .mcap")
    check_output(record, kind="file" if args.overwrite else "new")
    return record


def _inputs(recordings: dict[str, Any]) -> dict[str, Sequence[TimedLaserScan]]:
    """Every robot's scans, each with its reference pose where the recording has one."""
    from multi_robot_mapper.io.bags import reference_poses

    inputs: dict[str, Sequence[TimedLaserScan]] = {}
    for name, rec in recordings.items():
        stamps = np.array([s.stamp for s in rec.scans], dtype=np.float64)
        poses, found = reference_poses(rec, stamps)
        inputs[name] = [
            TimedLaserScan(s.stamp, s.scan, (float(p[0]), float(p[1]), float(p[2])) if ok else None)
            for s, p, ok in zip(rec.scans, poses, found, strict=True)
        ]
    return inputs


def _replay(
    args: argparse.Namespace,
    inputs: dict[str, Sequence[TimedLaserScan]],
    config: RobotMapperConfig,
    merger: MapMergerConfig,
    record: Path | None,
) -> tuple[OfflineMap, str]:
    """The pipeline's run (with the recording of its snapshots into ``record``) and what was
    recorded (topics and message counts)."""
    from multi_robot_mapper.cli.progress import ProgressBar
    from multi_robot_mapper.core.pipeline import run_offline

    bar = ProgressBar(f"mrm replay ({args.method})")
    run = functools.partial(
        run_offline,
        inputs,
        args.method,
        config.extraction,
        progress=bar,
        local_mapping=config.local_mapping,
        merging=merger.merge,
        stream=config.stream_config(),
    )
    try:
        if record is None:
            return run(), ""
        from multi_robot_mapper.io.output_bag import OutputBag
        from multi_robot_mapper.ros.recording import SnapshotRecorder

        with OutputBag(record) as bag:
            recorder = SnapshotRecorder(bag, merger)
            offline = run(snapshots=recorder, snapshot_period=args.record_period)
        counts = ", ".join(f"{topic} {n}" for topic, n in sorted(bag.counts.items()))
        return offline, f"{recorder.snapshots} merges ({counts})"
    finally:
        bar.close()


def _write_outputs(args: argparse.Namespace, folder: Path, offline: OfflineMap) -> None:
    from multi_robot_mapper.core.merge_stage import own_frame_map
    from multi_robot_mapper.io import pictures
    from multi_robot_mapper.io.results import ReplayResult, write_results

    write_results(
        folder,
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
            replayed=replayed_bags(args, args.bags),  # so mrm evaluate DIR needs no --bag
        ),
    )
    paths = {robot: poses for robot, (_, poses) in offline.trajectories.items()}
    title = f"{', '.join(b.name for b in args.bags)}: method '{args.method}'" + (
        " (scans at reference poses, not a mapping result)" if args.method == "reference" else ""
    )
    unmerged = {
        robot: (own_frame_map(offline, robot), paths[robot])
        for robot in offline.robots
        if offline.robot_frames.get(robot) is None
    }
    figure = pictures.draw_map(
        offline.map_segments, offline.segment_robot, offline.robots, paths, title, unmerged
    )
    pictures.save_figure(figure, folder / "map.png", folder / "map.svg")


def merge_summary(offline: OfflineMap, method: str) -> str:
    """One line: how many robots were merged, and each unmerged one with why."""
    robots = offline.robots
    merged = [r for r in robots if offline.robot_frames.get(r) is not None]
    count = f"{len(merged)} of {len(robots)} robot{'s' if len(robots) != 1 else ''} merged"
    if method == "local":
        return (
            f"{count}: method 'local' places no robot relative to another (each map is in its "
            "own frame; map.png draws each in a panel of its own; --method pivot merges)"
        )
    if method == "reference":
        return f"{count}: every robot at its reference poses (not a mapping result)"
    reference = offline.stats.get("merge_reference")
    if len(robots) == 1 and merged:
        return f"{count}: {robots[0]} is the only robot (its map frame is map)"
    unmerged = [r for r in robots if r not in merged]
    said = f"{count} (reference {reference})" if reference in merged else count
    if not unmerged:
        return said
    reasons = "; ".join(
        f"{robot} ({offline.unmerged_reasons.get(robot, 'no reason given')})" for robot in unmerged
    )
    return f"{said}; unmerged: {reasons}"
