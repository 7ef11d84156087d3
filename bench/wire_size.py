"""What crosses the network between a robot and the merger, in bytes (issue 50, docs/network.md).

Each message is built by the nodes' own builders and serialised by
``rclpy.serialization.serialize_message`` (the CDR payload DDS carries, without the RTPS and
UDP/IP headers; no node, no network). Rates are the defaults of ``RobotMapperConfig`` and
``MapMergerConfig``.

- ``partial_map``: each shared log driven by one robot (or cut into ``--robots`` runs, robot 1
  shown), its keyframes built at the reference poses with the local mapper's keyframe rule
  (``harness.reference_keyframes``: every scan fused, each segment owned by a keyframe, as the
  message carries them), the whole run's map serialised (``io/messages.partial_map_markers``);
  and the message's cost per keyframe and per segment. The node sends the whole map at most
  once per ``partial_map_period``, and only when it changed: the kB/s column is that ceiling.
- ``global_grid``: the whole run's map as the merger's grid would cover it
  (``core/merging/occupancy.occupancy_grid`` at the default ``grid.*``, the robot's keyframes as
  viewpoints), serialised by ``ros/markers.occupancy_grid_msg``.
- fixed-size messages: ``pose`` and ``robot_poses`` (PoseStamped), a robot's ``/diagnostics``
  status (made-up counts of a running robot: its size varies with the reasons it lists), and
  LaserScans of 180 and 1081 beams (what a robot would send if its scans crossed).

    .venv/bin/python -m bench.wire_size [--logs intel aces fhw csail edmonton] [--robots 1]

Sizes are exact for these maps; a map the robot's own mapper builds has other keyframes and
segments (a robot that loses its place starts pieces), so take the bytes per keyframe and per
segment, not the totals, to another site. freiburg-079 (4791 scans, each fused) did not
finish within 500 s and is left out of the default logs; the five default logs take 1-2 min.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import numpy as np
from rclpy.serialization import serialize_message
from visualization_msgs.msg import MarkerArray

from bench.harness import cut_log, present_logs, reference_keyframes
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.merging.occupancy import occupancy_grid
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.io.messages import (
    partial_map_markers,
    pose_stamped,
    scan_to_msg,
    stamp_from_seconds,
)
from multi_robot_mapper.ros import diagnostics
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.markers import occupancy_grid_msg
from multi_robot_mapper.ros.merger_config import MapMergerConfig

FRAME = "robot1/map"
DEFAULT_LOGS = ("intel", "aces", "fhw", "csail", "edmonton")


def size(msg: object) -> int:
    """Bytes of a message's CDR serialisation."""
    return len(serialize_message(msg))


def partial_map(keyframes: Sequence[Keyframe], width: float) -> MarkerArray:
    """The node's ``partial_map`` message of these keyframes (piece 0, the newest's stamp)."""
    stamp = stamp_from_seconds(max(kf.stamp for kf in keyframes))
    return partial_map_markers(keyframes, stamp, FRAME, width)


def marker_costs(width: float) -> tuple[int, int, int]:
    """Bytes of an empty MarkerArray, of each keyframe marker beyond it (no segments) and of
    each segment: from messages of 0, 1 and 2 keyframes."""
    empty = size(MarkerArray())
    pose = np.array([1.0, 2.0, 0.3])
    bare = Keyframe(0, 1.7e9, pose, np.zeros((0, 4)))
    one = Keyframe(0, 1.7e9, pose, np.ones((1, 4)))
    per_marker = size(partial_map([bare], width)) - empty
    per_segment = size(partial_map([one], width)) - empty - per_marker
    return empty, per_marker, per_segment


def log_row(name: str, robots: int, config: RobotMapperConfig) -> tuple[str, list[Keyframe]]:
    """The table row of one log's robot 1: its whole run's partial map; its keyframes."""
    log = cut_log(name, robots)
    start, stop = log.runs[0]
    local = config.local_mapping
    keyframes = reference_keyframes(
        log.scans[start:stop], local.keyframe_distance, local.keyframe_angle
    )
    minutes = float(log.stamps[stop - 1] - log.stamps[start]) / 60.0
    nbytes = size(partial_map(keyframes, config.segment_marker_width))
    segments = sum(len(kf.segments) for kf in keyframes)
    count = len(keyframes)
    ceiling = nbytes / config.partial_map_period
    row = (
        f"| {name} | {stop - start} | {minutes:.0f} | {count} | {segments} | "
        f"{nbytes / 1e3:.1f} | {nbytes / count:.0f} | {ceiling / 1e3:.1f} |"
    )
    return row, keyframes


def grid_row(name: str, keyframes: Sequence[Keyframe], merger: MapMergerConfig) -> str:
    """The merger's grid over one robot's whole map (the keyframes as its viewpoints)."""
    poses = np.array([kf.T_robotmap_keyframe for kf in keyframes])
    walls = np.vstack(
        [
            se2.transform_segments(se2.matrix_from_pose(*kf.T_robotmap_keyframe), kf.segments)
            for kf in keyframes
            if len(kf.segments)
        ]
    )
    grid = occupancy_grid(walls, [(walls, poses)], merger.grid, MergeConfig())
    msg = occupancy_grid_msg(grid, stamp_from_seconds(keyframes[-1].stamp), "map")
    return (
        f"| {name} | {grid.width} x {grid.height} cells of {grid.resolution:g} m | "
        f"{size(msg) / 1e3:.1f} |"
    )


def fixed_rows(config: RobotMapperConfig) -> list[str]:
    """The messages whose size does not grow with the map."""
    stamp = stamp_from_seconds(1.7e9)
    pose = size(pose_stamped((1.0, 2.0, 0.3), stamp, FRAME))
    health = diagnostics.MapperHealth(
        robot="robot1", scan_rate=40.0, silent_for=0.01, stale_timeout=5.0,
        scans_received=12000, scans_accepted=11800, rejected={"stale_in_queue": 3},
        set_aside={"lost: no confident match": 7}, keyframes=900, map_segments=5000,
        recent_received=40, recent_accepted=40, recent_rejected=0, skipped=0,
    )  # fmt: skip
    status = diagnostics.diagnostic_array([diagnostics.mapper_status(health)], stamp)
    rows = [
        f"| `pose` / `robot_poses/<robot>` (PoseStamped, frame `{FRAME}`) | {pose} | "
        "one per placed scan |",
        f"| robot's `/diagnostics` status | {size(status)} | one per "
        f"`diagnostics_period` ({config.diagnostics_period:g} s) |",
    ]
    for beams in (180, 1081):
        scan = LaserScanData(
            ranges=np.full(beams, 5.0), angle_min=-2.35, angle_max=2.35,
            angle_increment=4.7 / (beams - 1), range_min=0.02, range_max=30.0,
            intensities=None,
        )  # fmt: skip
        nbytes = size(scan_to_msg(scan, "robot1/laser", stamp))
        rows.append(
            f"| LaserScan, {beams} beams, no intensities | {nbytes} | at 40 Hz: "
            f"{nbytes * 40 / 1e3:.1f} kB/s |"
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=list(DEFAULT_LOGS))
    parser.add_argument("--robots", type=int, default=1, help="cut each log into K runs")
    args = parser.parse_args(argv)
    config, merger = RobotMapperConfig(), MapMergerConfig()
    began = time.perf_counter()
    empty, per_marker, per_segment = marker_costs(config.segment_marker_width)
    print(
        f"partial_map: {empty} B + {per_marker} B per keyframe + {per_segment} B per segment "
        f"(frame '{FRAME}'); partial_map_period {config.partial_map_period:g} s\n"
    )
    print(
        "| log | scans | minutes of log | keyframes | segments | partial_map kB | "
        "B per keyframe | kB/s at most |\n| --- | --- | --- | --- | --- | --- | --- | --- |"
    )
    grids = []
    for name in present_logs(args.logs):
        row, keyframes = log_row(name, args.robots, config)
        print(row, flush=True)
        grids.append(grid_row(name, keyframes, merger))
    print("\n| log | global_grid of the whole run | kB |\n| --- | --- | --- |")
    print("\n".join(grids))
    print("\n| message | bytes | rate |\n| --- | --- | --- |")
    print("\n".join(fixed_rows(config)))
    print(f"\n{time.perf_counter() - began:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
