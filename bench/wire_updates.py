"""Bytes per second of a robot's partial map at the log's own rate: the whole map at every
change (before, issue 50) against snapshots now and then plus updates of what changed (after,
``io/map_updates.py``); docs/network.md.

The robot side replayed without a node: every scan of the log goes through the front end and
the local mapper (``LocalMapper`` with its back end in line, default ``RobotMapperConfig``), its
real keyframes and the poses its pose graph moves. On the log's clock, every
``partial_map_period`` at which the map changed, the node's ``publish_map`` rule runs: a
snapshot (every keyframe, on ``partial_map``) when ``snapshot_period`` has gone by since the
last, else an update of the changed keyframes (``UpdatePlanner``); each message built by the
node's builders (``keyframe_marker``, ``sequence_marker``) and serialised by
``rclpy.serialization`` (CDR payload, no RTPS/UDP/IP headers). *Before* is the whole map at each
of those ticks, sized by the measured cost per keyframe and per segment (``wire_size``).
Average: all bytes over the log's duration; peak: the largest total in one second of log time.

    .venv/bin/python -m bench.wire_updates [--logs freiburg-079 intel-bag] [--scans N]

``freiburg-079`` is the CARMEN log (4791 scans, each fused); ``intel-bag`` the dense bag
(13631 scans at 10 Hz, one robot); ``--scans N`` replays only the first N scans of each.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Iterator

import numpy as np
from rclpy.serialization import serialize_message
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from bench.harness import BAGS, CARMEN
from bench.wire_size import marker_costs
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.io.carmen import carmen_scan_data, monotonic_stamps, read_carmen
from multi_robot_mapper.io.map_updates import SNAPSHOT, UpdatePlanner, sequence_marker
from multi_robot_mapper.io.messages import keyframe_marker, piece_frame, stamp_from_seconds
from multi_robot_mapper.io.recordings import read_bags
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig

FRAME = "robot1/map"
TARGET_KBPS = 20.0


def log_scans(name: str, limit: int) -> Iterator[tuple[float, LaserScanData]]:
    """``(stamp, scan)`` of every scan of a log (the first ``limit`` when > 0)."""
    if name.endswith("-bag"):
        (recording,) = read_bags([BAGS / f"{name[: -len('-bag')]}.bag"]).values()
        scans = recording.scans[: limit or None]
        yield from ((s.stamp, s.scan) for s in scans)
        return
    log = read_carmen(CARMEN / f"{name}.log.gz")[: limit or None]
    stamps, _ = monotonic_stamps(np.array([s.timestamp for s in log]), name)
    yield from ((float(t), carmen_scan_data(s)) for t, s in zip(stamps, log, strict=True))


@dataclasses.dataclass
class Traffic:
    """Messages sent: ``(log time, bytes)`` per kind, and the whole-map bytes (before)."""

    snapshots: list[tuple[float, int]] = dataclasses.field(default_factory=list)
    updates: list[tuple[float, int]] = dataclasses.field(default_factory=list)
    before: list[tuple[float, int]] = dataclasses.field(default_factory=list)
    keyframes: int = 0
    segments: int = 0
    sent_keyframes: int = 0  # keyframe markers in updates


def replay(name: str, limit: int, config: RobotMapperConfig) -> tuple[Traffic, float, int]:
    """The log replayed; its traffic, its duration (s of log time) and its scans."""
    empty, per_keyframe, per_segment = marker_costs(config.segment_marker_width)
    mapper = LocalMapper(config.local_mapping)
    planner = UpdatePlanner("bench")
    traffic = Traffic()
    period, width = config.partial_map_period, config.segment_marker_width
    first = next_tick = last_snapshot = None
    published, count, stamp = 0, 0, 0.0
    for stamp, scan in log_scans(name, limit):
        count += 1
        if first is None:
            first, next_tick = stamp, stamp + period
        mapper.add_scan(stamp, extract_scan(scan, config.extraction)[0], scan)
        if stamp < next_tick or mapper.version in (0, published):
            continue
        next_tick = stamp + period
        published = mapper.version
        keyframes = mapper.keyframes()
        segments = sum(len(kf.segments) for kf in keyframes)
        traffic.before.append(
            (stamp, empty + per_keyframe * len(keyframes) + per_segment * segments)
        )
        due = last_snapshot is None or stamp - last_snapshot >= config.snapshot_period
        plan = planner.plan(keyframes, snapshot=due)
        if plan is None:
            continue
        header = Header(stamp=stamp_from_seconds(stamp))
        array = MarkerArray()
        for kf in plan.keyframes:
            header = Header(frame_id=piece_frame(FRAME, kf.piece), stamp=header.stamp)
            array.markers.append(keyframe_marker(kf, header, width))
        array.markers.append(sequence_marker(plan.tag, Header(frame_id=FRAME, stamp=header.stamp)))
        nbytes = len(serialize_message(array))
        if plan.tag.kind == SNAPSHOT:
            last_snapshot = stamp
            traffic.snapshots.append((stamp, nbytes))
        else:
            traffic.updates.append((stamp, nbytes))
            traffic.sent_keyframes += len(plan.keyframes)
        planner.commit(plan)
        traffic.keyframes, traffic.segments = len(keyframes), segments
    assert first is not None
    return traffic, stamp - first, count


def rates(sent: list[tuple[float, int]], duration: float) -> tuple[float, float]:
    """Average bytes/s over ``duration`` and the largest total in one second (kB/s)."""
    if not sent:
        return 0.0, 0.0
    stamps = np.array([t for t, _ in sent])
    sizes = np.array([b for _, b in sent], dtype=np.float64)
    seconds = np.floor(stamps - stamps[0]).astype(np.int64)
    peak = float(np.bincount(seconds, weights=sizes).max())
    return float(sizes.sum()) / max(duration, 1e-9) / 1e3, peak / 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=["freiburg-079", "intel-bag"])
    parser.add_argument("--scans", type=int, default=0, help="only the first N scans")
    args = parser.parse_args(argv)
    config = RobotMapperConfig()
    print(
        f"partial_map_period {config.partial_map_period:g} s, snapshot_period "
        f"{config.snapshot_period:g} s; kB = 1000 B, CDR payload; target average "
        f"<= {TARGET_KBPS:g} kB/s\n"
    )
    print(
        "| log | scans | minutes | keyframes | segments | before: avg / peak kB/s | "
        "snapshots: n, avg kB/s | updates: n, keyframes sent, avg kB/s | after: avg / peak "
        "kB/s | CPU s |\n" + "| --- " * 10 + "|"
    )
    for name in args.logs:
        began = time.process_time()
        traffic, duration, scans = replay(name, args.scans, config)
        before = rates(traffic.before, duration)
        snapshots = rates(traffic.snapshots, duration)
        updates = rates(traffic.updates, duration)
        after = rates(sorted(traffic.snapshots + traffic.updates), duration)
        print(
            f"| {name} | {scans} | {duration / 60:.1f} | {traffic.keyframes} | "
            f"{traffic.segments} | {before[0]:.1f} / {before[1]:.1f} | "
            f"{len(traffic.snapshots)}, {snapshots[0]:.2f} | {len(traffic.updates)}, "
            f"{traffic.sent_keyframes}, {updates[0]:.2f} | **{after[0]:.2f}** / {after[1]:.1f} | "
            f"{time.process_time() - began:.0f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
