"""Live rate: a real robot_mapper node fed scans at their own pace, simulated or from a real log.

A driver publishes pre-built ``sensor_msgs/LaserScan`` messages (1081 beams, the simulator's
default laser) on ``/robot1/scan`` with sensor-data QoS, one every 25 ms by the wall clock, from
the main thread. The ``robot_mapper`` node runs in the same process on ONE thread (its own
SingleThreadedExecutor): the scans reach it over real DDS topics, and whatever it cannot keep up
with is lost in the best-effort queue (``SCAN_QUEUE_DEPTH``) as it would be on a robot.

Measured (and only this):
  published   scans the driver published
  received    scans whose callback ran in the node (``scans_received``)
  dropped     published - received, also as a percentage
  latency     per received scan, from just before ``publish()`` in the driver to the end of the
              node's scan callback (extraction, local mapping, ``scan_segments`` and ``pose``
              published, or the set-aside decision): DDS delivery + queueing behind earlier
              scans and map publications + the work itself; median / p95 / max
  service     the callback's own duration (the work alone, no queueing), and how much of it
              is ``LocalMapper.add_scan`` (the rest: conversion, extraction, publishing)
  partial_map how often the whole map went out and the longest publication (it shares the
              node's thread, so it delays the scans queued behind it)
  mapper      scans accepted / set aside (with reasons), keyframes, and how far the keyframes
              lie from the simulator's truth (relative to the first scan, the map frame)

    .venv/bin/python -m bench.live_rate [--seconds 30] [--world office] [--seed 0]
        [--set local_mapping.keyframe_distance=0.5 ...] [--cpu 0] [--json]
    .venv/bin/python -m bench.live_rate --log freiburg-079 [--robots 4 --robot 1] [--speed 4]

``--log NAME`` plays a real CARMEN log from ``../shared/data/carmen`` instead (the simulated
bench hides the real cost: 360-beam SICK scans of a real building): robot ``--robot`` of the
log cut into ``--robots`` contiguous runs (as ``mrm import-carmen`` cuts it), each scan
published when its own stamp comes (times ``1 / --speed``). The table adds the time per
stage of the node's scan callback: front end (LaserScan to segments), matching (tracking,
search, recent keyframes), confidence, integrate (placing the scan), graph hand-off (a
keyframe's edge to the back end, which runs in a worker process, or with
``--set backend_process=false`` on a thread of the node), and the back end's time per
keyframe (matching, loop closures, optimisation; not on the scan's path).

Targets (issue 4, simulated): dropped <= 1 %, latency p95 < 25 ms on one core. Issue 17 (real
data, freiburg-079 in 4): time from scan received to partial map updated (the end of the scan
callback) p95 < 25 ms; 0 scans dropped at the log's own rate; dropped scans counted at 4x.
The mapper is not tuned here; this only measures it.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402

from bench.harness import carmen_log  # noqa: E402
from multi_robot_mapper.cli.import_carmen import split_runs  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.simulation import LaserModel, SimulatedRobot, simulate_robots  # noqa: E402
from multi_robot_mapper.core.worlds import ROUTES  # noqa: E402
from multi_robot_mapper.io.carmen import carmen_scan_data, monotonic_stamps, read_carmen  # noqa: E402
from multi_robot_mapper.io.config_files import load_config  # noqa: E402
from multi_robot_mapper.io.messages import scan_to_msg, stamp_from_seconds  # noqa: E402
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig  # noqa: E402
from multi_robot_mapper.ros.robot_mapper import RobotMapper  # noqa: E402
from multi_robot_mapper.ros.testing import isolated_context, spin_until  # noqa: E402

Key = tuple[int, int]


class TimedMapper(RobotMapper):
    """robot_mapper with a clock on its scan callback and its map publication (nothing else)."""

    def __init__(self, **kwargs: Any) -> None:
        self.done_at: dict[Key, float] = {}
        self.service: list[float] = []
        self.map_publish: list[float] = []
        self.local_mapping: list[float] = []
        self.stages: dict[str, list[float]] = {}  # per scan: seconds of each stage
        super().__init__(**kwargs)
        add_scan = self.mapper.add_scan

        def timed_add_scan(*args: Any) -> Any:
            start = time.monotonic()
            update = None
            try:
                update = add_scan(*args)
                return update
            finally:
                spent = time.monotonic() - start
                self.local_mapping.append(spent)
                if update is not None:
                    for stage, seconds in update.seconds.items():
                        self.stages.setdefault(stage, []).append(seconds)

        self.mapper.add_scan = timed_add_scan  # type: ignore[method-assign]

    def _on_scan(self, msg: LaserScan) -> None:
        start = time.monotonic()
        super()._on_scan(msg)
        end = time.monotonic()
        self.done_at[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = end
        self.service.append(end - start)

    def publish_map(self) -> bool:
        start = time.monotonic()
        published = super().publish_map()
        if published:
            self.map_publish.append(time.monotonic() - start)
        return published


def percentiles_ms(values: list[float]) -> dict[str, float]:
    if not values:
        return {"median": math.nan, "p95": math.nan, "max": math.nan}
    a = 1e3 * np.asarray(values)
    return {
        "median": float(np.median(a)),
        "p95": float(np.percentile(a, 95)),
        "max": float(a.max()),
    }


def log_robot(args: argparse.Namespace) -> SimulatedRobot:
    """Robot ``--robot`` of a CARMEN log cut into ``--robots`` runs, with its reference poses."""
    path = carmen_log(args.log)
    if not path.is_file():
        raise SystemExit(f"live_rate: {path} not found")
    scans = list(read_carmen(path))
    start, stop = split_runs(len(scans), args.robots, 0)[args.robot - 1]
    run = scans[start:stop]
    stamps, _ = monotonic_stamps(np.array([s.timestamp for s in run]), args.log)
    return SimulatedRobot(
        stamps=stamps - stamps[0] + 1000.0,
        T_world_laser=np.array([s.reference_pose for s in run]),
        scans=[carmen_scan_data(s) for s in run],
    )


def run(args: argparse.Namespace) -> dict[str, Any]:
    sim_start = time.monotonic()
    if args.log:
        robot = log_robot(args)
    else:
        robot = simulate_robots(args.world, 1, LaserModel(), seed=args.seed, duration=args.seconds)[
            0
        ]
    messages = [
        scan_to_msg(scan, "robot1/laser", stamp_from_seconds(stamp), 0.0)
        for scan, stamp in zip(robot.scans, robot.stamps, strict=True)
    ]
    simulated_s = time.monotonic() - sim_start
    # Any field, user parameter or fixed constant: the node is built with the whole config.
    config = load_config(RobotMapperConfig, overrides=args.set)
    published_at: dict[Key, float] = {}

    with isolated_context() as context:
        node = TimedMapper(context=context, namespace="robot1", config=config)
        node.warnings.log = lambda message: None  # counted below instead of printed
        driver = Node("live_driver", context=context)
        scan_pub = driver.create_publisher(LaserScan, "/robot1/scan", qos_profile_sensor_data)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        if not spin_until(executor, lambda: scan_pub.get_subscription_count() > 0, timeout=10.0):
            raise SystemExit("live_rate: the node never subscribed to /robot1/scan")
        spinner = threading.Thread(target=executor.spin, name="robot_mapper", daemon=True)
        spinner.start()

        # Each scan goes out when its stamp comes (sped up by --speed).
        offsets = (robot.stamps - robot.stamps[0]) / args.speed
        period = float(np.median(np.diff(offsets))) if len(offsets) > 1 else 0.0
        late = 0  # publications more than one period behind the schedule (driver lag)
        t0 = time.monotonic() + 0.2
        for i, msg in enumerate(messages):
            due = t0 + float(offsets[i])
            now = time.monotonic()
            if due > now:
                time.sleep(due - now)
            elif now - due > period:
                late += 1
            published_at[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = time.monotonic()
            scan_pub.publish(msg)
        wall_s = time.monotonic() - t0
        # Let the node finish what reached it (a queue of at most 5 scans), then stop it.
        deadline = time.monotonic() + 5.0
        backend_wait = time.monotonic()
        while not node.mapper.idle and time.monotonic() - backend_wait < 600.0:
            time.sleep(0.05)  # the back end catches up (not on the scans' path)
        quiet_since = time.monotonic()
        seen = node.scans_received
        while time.monotonic() < deadline and time.monotonic() - quiet_since < 1.0:
            time.sleep(0.05)
            if node.scans_received != seen:
                seen, quiet_since = node.scans_received, time.monotonic()
        executor.shutdown()
        spinner.join(timeout=5.0)

        latency = [t - published_at[k] for k, t in node.done_at.items() if k in published_at]
        mapper = node.mapper
        keyframes = mapper.keyframes()
        T_first_world = se2.invert(se2.matrix_from_pose(*robot.T_world_laser[0]))
        errors = []
        for kf in keyframes:
            i = int(np.argmin(np.abs(robot.stamps - kf.stamp)))
            truth = se2.pose_from_matrix(
                T_first_world @ se2.matrix_from_pose(*robot.T_world_laser[i])
            )
            errors.append(
                (
                    math.hypot(
                        truth[0] - kf.T_robotmap_keyframe[0], truth[1] - kf.T_robotmap_keyframe[1]
                    ),
                    abs(math.remainder(truth[2] - kf.T_robotmap_keyframe[2], math.tau)),
                )
            )
        beams = len(robot.scans[0].ranges)
        result = {
            "world": args.world if not args.log else f"{args.log} robot {args.robot}/{args.robots}",
            "seconds": float(robot.stamps[-1] - robot.stamps[0]),
            "speed": args.speed,
            "rate_hz": 1.0 / period if period > 0 else math.nan,
            "beams": beams,
            "overrides": list(args.set),
            "cpu": args.cpu,
            "simulation_s": simulated_s,
            "publish_wall_s": wall_s,
            "published": len(messages),
            "published_late": late,
            "received": node.scans_received,
            "dropped": len(messages) - node.scans_received,
            "dropped_percent": 100.0 * (len(messages) - node.scans_received) / len(messages),
            "rejected": node.scans_rejected,
            "mapping_errors": node.mapping_errors,
            "warnings": dict(node.warnings.counts),
            "latency_ms": percentiles_ms(latency),
            "service_ms": percentiles_ms(node.service),
            "local_mapping_ms": percentiles_ms(node.local_mapping),
            "front_end_ms": percentiles_ms(
                [s - m for s, m in zip(node.service, node.local_mapping, strict=False)]
            ),
            "stage_ms": {stage: percentiles_ms(v) for stage, v in sorted(node.stages.items())},
            "stage_scans": {stage: len(v) for stage, v in node.stages.items()},
            "backend_per_keyframe_ms": percentiles_ms(list(mapper.backend_seconds)),
            "optimisation_per_keyframe_ms": percentiles_ms(list(mapper.optimise_seconds)),
            "pieces_started": mapper.pieces_started,
            "closures": len(mapper.closures),
            "partial_map_publications": len(node.map_publish),
            "partial_map_publish_ms": percentiles_ms(node.map_publish),
            "accepted": mapper.scans_accepted,
            "set_aside": mapper.scans_set_aside,
            "set_aside_reasons": dict(mapper.set_aside_reasons),
            "keyframes": len(keyframes),
            "map_segments": int(sum(len(kf.segments) for kf in keyframes)),
            "keyframe_error_max_m": max((e[0] for e in errors), default=math.nan),
            "keyframe_error_max_rad": max((e[1] for e in errors), default=math.nan),
        }
        node.destroy_node()
        driver.destroy_node()
    return result


def print_table(r: dict[str, Any]) -> None:
    def row(name: str, value: str, note: str = "") -> None:
        print(f"  {name:<26} {value:>20}  {note}")

    def ms(d: dict[str, float]) -> str:
        return f"{d['median']:.1f} / {d['p95']:.1f} / {d['max']:.1f}"

    print(
        f"live rate: {r['world']}, {r['seconds']:.0f} s at {r['rate_hz']:.1f} Hz "
        f"(speed x{r['speed']:g}), {r['beams']} beams"
        + (f", pinned to CPU {r['cpu']}" if r["cpu"] is not None else "")
        + (f", overrides {' '.join(r['overrides'])}" if r["overrides"] else "")
    )
    row("scans published", f"{r['published']}", f"in {r['publish_wall_s']:.1f} s wall clock")
    if r["published_late"]:
        row("  published late", f"{r['published_late']}", "driver > 1 period behind schedule")
    row("scans received", f"{r['received']}")
    ok = "ok" if r["dropped_percent"] <= 1.0 else "MISSED (target <= 1 %)"
    row("dropped", f"{r['dropped']} ({r['dropped_percent']:.1f} %)", ok)
    lat = r["latency_ms"]
    ok = "ok" if lat["p95"] < 25.0 else "MISSED (target p95 < 25 ms)"
    row("latency ms med/p95/max", ms(lat), f"publish -> end of scan callback; {ok}")
    row("service ms med/p95/max", ms(r["service_ms"]), "scan callback alone")
    row("  of which local mapper", ms(r["local_mapping_ms"]), "LocalMapper.add_scan")
    row("  the rest", ms(r["front_end_ms"]), "conversion, extraction, publishing")
    for stage, times in r["stage_ms"].items():
        row(f"    {stage}", ms(times), f"in {r['stage_scans'][stage]} scans")
    row("back end per keyframe", ms(r["backend_per_keyframe_ms"]), "not on the scan's path")
    row("  of which optimisation", ms(r["optimisation_per_keyframe_ms"]))
    row("pieces started / closures", f"{r['pieces_started']} / {r['closures']}")
    row(
        "partial_map publications",
        f"{r['partial_map_publications']}",
        f"ms med/p95/max {ms(r['partial_map_publish_ms'])}",
    )
    row("accepted / set aside", f"{r['accepted']} / {r['set_aside']}", str(r["set_aside_reasons"]))
    if r["rejected"] or r["mapping_errors"]:
        row("rejected / mapping errors", f"{r['rejected']} / {r['mapping_errors']}")
    if r["warnings"]:
        row("warnings (kind: scans)", "", str(r["warnings"]))
    row("keyframes / segments", f"{r['keyframes']} / {r['map_segments']}")
    row(
        "keyframe error max",
        f"{r['keyframe_error_max_m']:.3f} m {math.degrees(r['keyframe_error_max_rad']):.2f} deg",
        "vs simulator truth, relative to the first scan",
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="drive length (s)")
    parser.add_argument("--world", default="office", choices=sorted(ROUTES))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="robot_mapper config override, any field (a fixed constant too), e.g. "
        "local_mapping.keyframe_distance=0.5",
    )
    parser.add_argument(
        "--cpu", type=int, default=None, help="pin the whole process (node, driver, DDS) to a CPU"
    )
    parser.add_argument("--log", help="a CARMEN log of ../shared/data/carmen (e.g. freiburg-079)")
    parser.add_argument("--robots", type=int, default=4, help="with --log: runs the log is cut in")
    parser.add_argument("--robot", type=int, default=1, help="with --log: the run played (1..)")
    parser.add_argument("--speed", type=float, default=1.0, help="play this many times faster")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args()
    if args.cpu is not None:
        os.sched_setaffinity(0, {args.cpu})
    result = run(args)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print_table(result)


if __name__ == "__main__":
    main()
