"""``mrm replay BAG --out DIR [--method pivot|ffs|reference] [--config YAML]``.

Runs the pipeline offline, as fast as the CPU allows, through the same core the nodes use, and
writes DIR/map.json, map.svg, map.png, trajectories/<robot>.tum, robots.json and stats.json.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from multi_robot_mapper.core.pipeline import METHODS, TimedLaserScan

# A reference pose is attached to a scan when one is stamped within this of the scan.
GROUND_TRUTH_MATCH_S = 0.02


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("replay", help="run the pipeline offline on a rosbag2 file")
    parser.add_argument("bag", type=Path, help="rosbag2 folder or .mcap file with */scan topics")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--method", choices=METHODS, default="pivot")
    parser.add_argument("--scan-topics", default="/*/scan", help="topic pattern (fnmatch)")
    parser.add_argument("--config", type=Path, help="YAML parameters (config/robot_mapper.yaml)")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override one parameter (repeatable)",
    )
    parser.set_defaults(func=run)


def attach_reference(
    stamps: np.ndarray, gt_stamps: np.ndarray, gt_poses: np.ndarray
) -> list[tuple[float, float, float] | None]:
    """The ground-truth pose stamped nearest each scan, if within GROUND_TRUTH_MATCH_S."""
    if len(gt_stamps) == 0:
        return [None] * len(stamps)
    order = np.argsort(gt_stamps)
    gt_stamps, gt_poses = gt_stamps[order], gt_poses[order]
    right = np.clip(np.searchsorted(gt_stamps, stamps), 0, len(gt_stamps) - 1)
    left = np.maximum(right - 1, 0)
    nearer_left = np.abs(gt_stamps[left] - stamps) <= np.abs(gt_stamps[right] - stamps)
    nearest = np.where(nearer_left, left, right)
    close = np.abs(gt_stamps[nearest] - stamps) <= GROUND_TRUTH_MATCH_S
    return [
        tuple(map(float, gt_poses[i])) if ok else None for i, ok in zip(nearest, close, strict=True)
    ]


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.cli.main import CliError
    from multi_robot_mapper.cli.progress import ProgressBar
    from multi_robot_mapper.core.mapper_config import RobotMapperConfig
    from multi_robot_mapper.core.pipeline import MethodNotImplementedError, run_offline
    from multi_robot_mapper.io import pictures
    from multi_robot_mapper.io.bags import BagError, read_recordings
    from multi_robot_mapper.io.config_files import load_config
    from multi_robot_mapper.io.results import ReplayResult, write_results

    config = load_config(RobotMapperConfig, args.config, args.overrides, node_name="robot_mapper")
    if args.method != "reference":
        # Refuse before reading a large bag.
        try:
            run_offline({}, args.method, config.extraction)
        except MethodNotImplementedError as exc:
            raise CliError(str(exc)) from exc
    try:
        recordings = read_recordings(args.bag, scan_pattern=args.scan_topics)
    except BagError as exc:
        raise CliError(str(exc)) from exc
    inputs: dict[str, Sequence[TimedLaserScan]] = {}
    for name, rec in recordings.items():
        stamps = np.array([s.stamp for s in rec.scans], dtype=np.float64)
        gt_stamps = np.array([g.stamp for g in rec.ground_truth], dtype=np.float64)
        gt_poses = np.array([g.pose for g in rec.ground_truth], dtype=np.float64).reshape(-1, 3)
        refs = attach_reference(stamps, gt_stamps, gt_poses)
        inputs[name] = [
            TimedLaserScan(s.stamp, s.scan, ref) for s, ref in zip(rec.scans, refs, strict=True)
        ]
    if args.method == "reference" and not any(
        item.reference_pose is not None for scans in inputs.values() for item in scans
    ):
        raise CliError(f"{args.bag} has no <robot>/ground_truth poses: 'reference' needs them")
    bar = ProgressBar(f"replay {args.method}")
    try:
        offline = run_offline(inputs, args.method, config.extraction, progress=bar)
    finally:
        bar.close()
    result = ReplayResult(
        method=args.method,
        robots=offline.robots,
        map_segments=offline.map_segments,
        segment_robot=offline.segment_robot,
        trajectories=offline.trajectories,
        robot_frames=offline.robot_frames,
        stats=offline.stats,
    )
    out = Path(args.out)
    write_results(out, result)
    paths = {robot: poses for robot, (_, poses) in offline.trajectories.items()}
    title = f"{args.bag.name}: method '{args.method}'" + (
        " (scans at reference poses, not a mapping result)" if args.method == "reference" else ""
    )
    for suffix in ("png", "svg"):
        fig = pictures.draw_map(
            offline.map_segments, offline.segment_robot, offline.robots, paths, title
        )
        pictures.save_figure(fig, out / f"map.{suffix}")
    posed = offline.stats["scans_posed"]
    print(
        f"{len(offline.robots)} robots, {offline.stats['scans_total']} scans ({posed} posed), "
        f"{len(offline.map_segments)} map segments, {offline.stats['total_s']} s -> {out}"
    )
    return 0
