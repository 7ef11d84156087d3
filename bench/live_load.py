"""Load: 8 simulated robots at 40 Hz x 1081 beams, live, for a long run on this machine.

Every robot drives the office world's closed tour (``core/worlds.py``), one eighth of a
lap apart, round and round at 0.8 m/s; its laser is a Hokuyo UTM-30LX (40 Hz, 1081 beams,
270 deg, noise and dropouts). One lap of scans is ray cast once (the tour is closed and the
path periodic, so lap after lap joins without a jump; robot k plays it k/8 of a lap later) and
played in real time: this process publishes every robot's scans on ``/robotK/scan`` at 40 Hz
by the wall clock, stamped on a simulated clock that advances with it, for ``--minutes``.

The nodes run as a user runs them (``--layout``):
  processes    one ``robot_mapper`` process per robot (what runs on each robot) and one
               ``map_merger`` process (the default)
  one-process  ``mrm run --in-process``: every node in one process, one Python interpreter lock

Sampled every ``--sample`` seconds, per window and in total:
  scans       published / received by each robot_mapper (its /diagnostics "scans received");
              dropped = published - received (best-effort queue of 5: newest wins)
  merging     merges done, the last merge's time (merger's /diagnostics "last merge (s)",
              sampled), the mean refresh interval (window / merges), robots merged
  cpu         CPU seconds of the node processes (their worker processes included) per wall
              second, i.e. cores used; and the whole machine's busy cores (/proc/stat: other
              users' load included)
  memory      resident memory of each kind of process (mappers summed, merger + its worker)
  maps        keyframes and segments of each robot's partial map, global map segments

    .venv/bin/python -m bench.live_load [--minutes 60] [--robots 8] [--layout processes]
        [--sample 60] [--json FILE]

The run is in real time (one simulated hour takes an hour): the nodes are not known to keep
up faster, and dropping scans is what is measured.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import argparse  # noqa: E402
import array  # noqa: E402
import itertools  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from bench.harness import OUTPUT  # noqa: E402
from multi_robot_mapper.core.simulation import (  # noqa: E402
    SIM_START_S,
    LaserModel,
    _arc_length,
    drive_path,
    simulate_scan,
)
from multi_robot_mapper.core.worlds import ROUTES, WORLDS  # noqa: E402
from multi_robot_mapper.io.messages import stamp_from_seconds  # noqa: E402
from multi_robot_mapper.ros.live import Observer, ScanPlayer  # noqa: E402
from multi_robot_mapper.ros.processes import (  # noqa: E402
    NodeProcesses,
    map_merger_command,
    process_usage,
    robot_mapper_command,
)
from multi_robot_mapper.ros.testing import default_domain_id, isolated_context  # noqa: E402

SPEED = 0.8  # m/s


def lap(world: str, laser: LaserModel, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """One lap of the world's closed tour at SPEED: poses (N, 3) and float32 ranges (N, B).

    The poses are the middle lap of three driven in a row, so the heading smoothing has no
    end effects and the lap's last pose leads into its first one as any two others do."""
    tour = np.asarray(ROUTES[world], dtype=np.float64)
    closed = np.vstack((tour, tour[:1]))
    length = float(_arc_length(closed)[-1])
    count = round(length / SPEED * laser.rate)
    three = np.vstack((closed, closed[1:], closed[1:]))
    poses = drive_path(three, SPEED, laser.rate, 3 * count / laser.rate)[count : 2 * count]
    walls = WORLDS[world]()
    rng = np.random.default_rng(seed)
    ranges = np.array(
        [simulate_scan(walls, (p[0], p[1], p[2]), laser, rng).ranges for p in poses],
        dtype=np.float32,
    )
    return poses, ranges


def scan_message(laser: LaserModel, frame: str, stamp: float, ranges: np.ndarray) -> LaserScan:
    msg = LaserScan()
    msg.header = Header(frame_id=frame, stamp=stamp_from_seconds(stamp))
    msg.angle_min = float(laser.angle_min)
    msg.angle_max = float(laser.angle_min + laser.angle_increment * (laser.beams - 1))
    msg.angle_increment = float(laser.angle_increment)
    msg.scan_time = 1.0 / laser.rate
    msg.time_increment = msg.scan_time / laser.beams
    msg.range_min = float(laser.range_min)
    msg.range_max = float(laser.range_max)
    msg.ranges = array.array("f", ranges.tobytes())
    return msg


def scans(
    robots: list[str], laser: LaserModel, ranges: np.ndarray, seconds: float
) -> Iterator[tuple[float, str, LaserScan]]:
    """Every robot's scan at each tick of the laser, robot k a k/len(robots) lap later."""
    count = len(ranges)
    offsets = [k * count // len(robots) for k in range(len(robots))]
    for tick in itertools.count():
        stamp = SIM_START_S + tick / laser.rate
        if tick / laser.rate >= seconds:
            return
        for robot, offset in zip(robots, offsets, strict=True):
            yield (
                stamp,
                robot,
                scan_message(laser, f"{robot}/laser", stamp, ranges[(tick + offset) % count]),
            )


def descendants(pid: int) -> list[int]:
    """``pid`` and every process below it (from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(parent, []).append(int(entry.name))
    found, stack = [], [pid]
    while stack:
        current = stack.pop()
        found.append(current)
        stack.extend(children.get(current, []))
    return found


def tree_usage(pid: int) -> tuple[float, int]:
    """CPU seconds and resident bytes of a process and all its descendants."""
    cpu, rss = 0.0, 0
    for member in descendants(pid):
        c, r = process_usage(member)
        cpu, rss = cpu + c, rss + r
    return cpu, rss


def machine_busy() -> tuple[float, float]:
    """(busy, total) jiffies of all cores from /proc/stat."""
    values = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    idle = values[3] + values[4]
    return float(sum(values) - idle), float(sum(values))


def status_number(observer: Observer, name: str, key: str) -> float:
    value = observer.status_value(name, key)
    try:
        return float(value) if value not in (None, "-") else float("nan")
    except ValueError:
        return float("nan")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--robots", type=int, default=8)
    parser.add_argument("--layout", choices=("processes", "one-process"), default="processes")
    parser.add_argument("--sample", type=float, default=60.0, help="seconds per sample window")
    parser.add_argument("--world", default="office")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--max-scan-rate",
        type=float,
        default=0.0,
        help="robot_mapper's max_scan_rate (Hz; 0: map every scan)",
    )
    parser.add_argument("--json", type=Path, help="write every sample here")
    parser.add_argument("--logs", type=Path, default=OUTPUT / "live_load_logs")
    args = parser.parse_args()

    laser = LaserModel()
    robots = [f"robot{k + 1}" for k in range(args.robots)]
    started_build = time.monotonic()
    _, ranges = lap(args.world, laser, args.seed)
    print(
        f"one lap of the {args.world} tour: {len(ranges)} scans ({len(ranges) / laser.rate:.0f} s) "
        f"of {laser.beams} beams, ray cast in {time.monotonic() - started_build:.0f} s",
        flush=True,
    )
    domain = default_domain_id()
    names = ",".join(robots)
    commands: dict[str, list[str]]
    if args.layout == "processes":
        rate = ["-p", f"max_scan_rate:={args.max_scan_rate}"]
        commands = {r: robot_mapper_command(r, rate) for r in robots}
        commands["merger"] = map_merger_command(
            [
                *("-p", f"robots:={names}", "-p", "save_on_shutdown:=true"),
                *("-p", f"map_file:={args.logs.resolve() / 'merged_map.json'}"),
            ]
        )
    else:
        run = [sys.executable, "-m", "multi_robot_mapper.cli.main", "run", "--in-process"]
        commands = {"all": [*run, "--robots", names]}
    nodes = NodeProcesses(commands, domain, log_dir=args.logs)
    samples: list[dict[str, Any]] = []
    try:
        with isolated_context(domain) as context:
            observer = Observer(
                robots, keep_maps=False, poses=False, partial_maps=False, context=context
            )
            driver = Node("load_player", context=context)
            player = ScanPlayer(driver, robots)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(observer)
            executor.add_node(driver)
            spinner = threading.Thread(target=executor.spin, daemon=True)
            spinner.start()
            deadline = time.monotonic() + 60.0
            while not player.subscribed() and time.monotonic() < deadline:
                time.sleep(0.1)
            if not player.subscribed():
                print(f"nodes did not come up: {nodes.running()}; logs in {args.logs}")
                return 1
            print(
                f"{len(robots)} robots at {laser.rate:g} Hz x {laser.beams} beams, layout "
                f"{args.layout}, max_scan_rate {args.max_scan_rate:g} Hz, {args.minutes:g} min in "
                f"real time; load average: {uptime()}",
                flush=True,
            )
            player.start(scans(robots, laser, ranges, args.minutes * 60.0))
            began = time.monotonic()
            previous = snapshot(nodes, observer, player, robots)
            header()
            while player.running():
                time.sleep(max(0.0, began + args.sample * (len(samples) + 1) - time.monotonic()))
                current = snapshot(nodes, observer, player, robots)
                samples.append(window(previous, current, robots))
                samples[-1]["elapsed_s"] = current["t"] - began
                report(samples[-1])
                previous = current
            time.sleep(3.0)  # the last diagnostics
            final = snapshot(nodes, observer, player, robots)
            executor.shutdown()
            spinner.join(5.0)
    finally:
        codes = nodes.stop()
    summary(samples, final, robots, codes, player.stats.late_s)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        for sample in samples:
            sample.pop("start", None)
        args.json.write_text(
            json.dumps({"samples": samples, "final": final}, indent=1, default=str)
        )
    return 0


def uptime() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def snapshot(
    nodes: NodeProcesses, observer: Observer, player: ScanPlayer, robots: list[str]
) -> dict[str, Any]:
    """Counters at one moment."""
    usage = {name: tree_usage(p.pid) for name, p in nodes.processes.items()}
    usage["bench (player)"] = process_usage(os.getpid())
    return {
        "t": time.monotonic(),
        "machine": machine_busy(),
        "usage": usage,
        "published": dict(player.stats.published),
        "received": {
            r: status_number(observer, f"{r}/robot_mapper", "scans received") for r in robots
        },
        "accepted": {
            r: status_number(observer, f"{r}/robot_mapper", "scans accepted") for r in robots
        },
        "keyframes": {r: status_number(observer, f"{r}/robot_mapper", "keyframes") for r in robots},
        "segments": {
            r: status_number(observer, f"{r}/robot_mapper", "map segments") for r in robots
        },
        "merges": status_number(observer, "map_merger", "merges"),
        "last_merge_s": status_number(observer, "map_merger", "last merge (s)"),
        "merged": status_number(observer, "map_merger", "robots merged"),
        "global_segments": status_number(observer, "map_merger", "global map segments"),
    }


def window(before: dict[str, Any], after: dict[str, Any], robots: list[str]) -> dict[str, Any]:
    seconds = after["t"] - before["t"]
    published = {r: after["published"][r] - before["published"].get(r, 0) for r in robots}
    received = {r: after["received"][r] - np.nan_to_num(before["received"][r]) for r in robots}
    dropped = {
        r: (published[r] - received[r]) / published[r] if published[r] else float("nan")
        for r in robots
    }
    cpu = {
        name: (after["usage"][name][0] - before["usage"].get(name, (0.0, 0))[0]) / seconds
        for name in after["usage"]
    }
    busy = (after["machine"][0] - before["machine"][0]) / max(
        1.0, after["machine"][1] - before["machine"][1]
    )
    merges = after["merges"] - np.nan_to_num(before["merges"])
    rss = {name: after["usage"][name][1] / 2**20 for name in after["usage"]}
    return {
        "start": before,
        "seconds": seconds,
        "published": published,
        "dropped": dropped,
        "cpu_cores": cpu,
        "machine_busy_cores": busy * (os.cpu_count() or 1),
        "merges": merges,
        "refresh_s": seconds / merges if merges > 0 else float("nan"),
        "last_merge_s": after["last_merge_s"],
        "merged": after["merged"],
        "rss_mb": rss,
        "keyframes": after["keyframes"],
        "segments": after["segments"],
        "global_segments": after["global_segments"],
        "loadavg": Path("/proc/loadavg").read_text().split()[:3],
        "t": after["t"],
    }


COLUMNS = (
    ("end s", 6),
    ("dropped % min/med/max", 22),
    ("merges", 6),
    ("refresh s", 9),
    ("last merge s", 12),
    ("merged", 6),
    ("cores nodes", 11),
    ("cores machine", 13),
    ("RSS MB mappers/merger", 21),
    ("keyframes", 9),
    ("segments", 8),
    ("global", 6),
    ("load average", 16),
)


def header() -> None:
    print(" ".join(f"{name:>{width}}" for name, width in COLUMNS), flush=True)


def report(sample: dict[str, Any]) -> None:
    """One line per window; keyframes and segments are the median robot's."""
    drops = np.array(list(sample["dropped"].values()), dtype=float) * 100.0
    cpu = {k: v for k, v in sample["cpu_cores"].items() if not k.startswith("bench")}
    rss = sample["rss_mb"]
    mappers = sum(v for k, v in rss.items() if k.startswith("robot"))
    merger = sum(v for k, v in rss.items() if not k.startswith(("robot", "bench")))
    cells = (
        f"{sample['elapsed_s']:.0f}",
        f"{np.nanmin(drops):.1f} / {np.nanmedian(drops):.1f} / {np.nanmax(drops):.1f}",
        f"{sample['merges']:.0f}",
        f"{sample['refresh_s']:.2f}",
        f"{sample['last_merge_s']:.2f}",
        f"{sample['merged']:.0f}",
        f"{sum(cpu.values()):.2f}",
        f"{sample['machine_busy_cores']:.2f}",
        f"{mappers:.0f} / {merger:.0f}",
        f"{np.nanmedian(list(sample['keyframes'].values())):.0f}",
        f"{np.nanmedian(list(sample['segments'].values())):.0f}",
        f"{sample['global_segments']:.0f}",
        " ".join(sample["loadavg"]),
    )
    line = " ".join(f"{cell:>{width}}" for cell, (_, width) in zip(cells, COLUMNS, strict=True))
    print(line, flush=True)


def summary(
    samples: list[dict[str, Any]],
    final: dict[str, Any],
    robots: list[str],
    codes: dict[str, int | None],
    late: list[float],
) -> None:
    print()
    print(f"node exit codes: {codes}")
    if not samples:
        return
    total = window(samples[0]["start"], final, robots)
    print("whole run:")
    for robot in robots:
        print(
            f"  {robot}: published {total['published'][robot]}, "
            f"dropped {total['dropped'][robot] * 100:.1f} %, "
            f"keyframes {final['keyframes'][robot]:.0f}, "
            f"map segments {final['segments'][robot]:.0f}"
        )
    late_ms = np.asarray(late) * 1e3
    print(
        f"  player behind schedule: p50 {np.median(late_ms):.1f} ms, "
        f"p95 {np.percentile(late_ms, 95):.1f} ms"
    )
    print(
        f"  merges {total['merges']:.0f} (mean refresh {total['refresh_s']:.2f} s), "
        f"robots merged {final['merged']:.0f}"
    )
    cores = sum(v for k, v in total["cpu_cores"].items() if not k.startswith("bench"))
    print(
        f"  node cores {cores:.2f} (the player: {total['cpu_cores']['bench (player)']:.2f}), "
        f"machine busy cores {total['machine_busy_cores']:.2f}"
    )


if __name__ == "__main__":
    sys.exit(main())
