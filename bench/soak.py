"""Soak (issue 50 item 4a): 8 simulated robots for an hour of simulated time at 10 Hz, as fast
as the machine maps them; memory of every process, merge update time and scans dropped.

Every robot drives the office world's closed tour at 0.8 m/s (a lap is 57 s), one eighth of a
lap apart, round and round (``bench/live_load.py``'s lap, ray cast once); its laser is
``--laser`` at 10 Hz (default ``lms``: the SICK LMS of the CARMEN logs, 181 beams; ``utm30lx``
is the demo's 1081 beams, each scan about three times the mapping work). The nodes are the
real ones, a process each (``mrm run``'s layout: a ``robot_mapper`` per robot, one
``map_merger``), on a simulated clock (``use_sim_time``; this bench publishes ``/clock``), so
that simulated time runs as fast as they keep up: tick by tick, each tick's scans go out once
every robot has placed the scans of ``--lag`` ticks before (its ``pose``), or after
``--tick-timeout`` s. Nothing is dropped for being faster than real time, and a scan dropped
anyway (in transit, or set aside by a mapper) is counted. ``--lag`` is 1 by default: the
mappers' ``scan_max_queue_delay`` is on the wall clock, and with the simulated clock slower
than real time (8 robots and a merger on two cores) the 5 ticks of lag allowed before were
more than 0.5 s of wall clock in a mapper's queue: 18 % of the scans were set aside as stale
(a robot of its own computer keeps up; here eight share two cores), and the maps with them.

Sampled every ``--sample`` simulated seconds: resident memory (RSS) of every node process and
of its worker processes (``/proc``), wall time; from the merger's ``/diagnostics``, each
merge's wall time ("last merge (s)") as the merge count moves; from the mappers'
``/diagnostics``, scans received and set aside. At the end: whether every node process still
ran (a crash is one that did not) and exited cleanly. Writes ``--json`` and a PNG plot
(``--plot``), and prints the figures against the targets: memory growth after the first 10
minutes at most 10 %; the merge time of the last 10 minutes within 20 % of the first 10
after warm-up (the median of each); 0 crashes.

    .venv/bin/python -m bench.soak [--minutes 60] [--robots 8] [--laser lms]
        [--wall-limit MINUTES] [--json FILE] [--plot docs/figures/soak.png]

``--wall-limit`` ends the run early (at that much wall time) and says how far it got.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402

from bench.harness import OUTPUT  # noqa: E402
from bench.live_load import lap, scan_message, tree_usage  # noqa: E402
from multi_robot_mapper.core.simulation import LASERS, SIM_START_S  # noqa: E402
from multi_robot_mapper.io.messages import seconds_from_stamp, stamp_from_seconds  # noqa: E402
from multi_robot_mapper.ros.processes import (  # noqa: E402
    NodeProcesses,
    map_merger_command,
    robot_mapper_command,
)
from multi_robot_mapper.ros.testing import default_domain_id, isolated_context  # noqa: E402

RATE_HZ = 10.0
WARM_UP_MIN = 10.0  # the "after the first 10 minutes"
WINDOW_MIN = 10.0
MEMORY_TARGET = 0.10
MERGE_TARGET = 0.20


class Watch:
    """What the bench reads from the nodes: each robot's newest pose stamp, the mappers' and
    the merger's newest diagnostics, and every merge's wall time as its count moves."""

    def __init__(self, node: Node, robots: list[str]) -> None:
        self._lock = threading.Lock()
        self.posed = dict.fromkeys(robots, 0.0)  # newest pose stamp (s)
        self.poses = dict.fromkeys(robots, 0)  # poses received: scans placed
        self.mappers: dict[str, dict[str, str]] = {}
        self.merger: dict[str, str] = {}
        self.merges: list[tuple[float, float]] = []  # (simulated s, wall s of that merge)
        self.clock = 0.0
        for robot in robots:
            node.create_subscription(
                PoseStamped, f"/{robot}/pose", lambda m, r=robot: self._on_pose(r, m), 100
            )
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)

    def _on_pose(self, robot: str, msg: PoseStamped) -> None:
        with self._lock:
            self.posed[robot] = max(self.posed[robot], seconds_from_stamp(msg.header.stamp))
            self.poses[robot] += 1

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        with self._lock:
            for status in msg.status:
                values = {kv.key: kv.value for kv in status.values}
                if status.name.endswith("/robot_mapper"):
                    self.mappers[status.name.split("/")[0]] = values
                elif status.name == "map_merger":
                    merges = int(values.get("merges", "0"))
                    if merges > int(self.merger.get("merges", "0")) and _number(
                        values.get("last merge (s)")
                    ):
                        self.merges.append((self.clock, float(values["last merge (s)"])))
                    self.merger = values

    def slowest(self) -> float:
        with self._lock:
            return min(self.posed.values())

    def counts(self, key: str) -> dict[str, int]:
        with self._lock:
            return {r: int(v.get(key, "0")) for r, v in self.mappers.items()}


def _number(text: str | None) -> bool:
    try:
        return text is not None and np.isfinite(float(text))
    except ValueError:
        return False


@dataclasses.dataclass
class Sample:
    sim_min: float
    wall_s: float
    rss_mb: dict[str, float]  # each node process with its workers


def node_commands(robots: list[str]) -> dict[str, list[str]]:
    sim = ["-p", "use_sim_time:=true"]
    commands = {r: robot_mapper_command(r, sim) for r in robots}
    commands["map_merger"] = map_merger_command([*sim, "-p", f"robots:={','.join(robots)}"])
    return commands


def play(args: argparse.Namespace, nodes: NodeProcesses, robots: list[str]) -> dict[str, Any]:
    """Tick by tick until ``--minutes`` of simulated time or ``--wall-limit``; the samples."""
    laser = dataclasses.replace(LASERS[args.laser], rate=RATE_HZ)
    _, ranges = lap("office", laser, seed=0)
    offsets = [k * len(ranges) // len(robots) for k in range(len(robots))]
    samples: list[Sample] = []
    with isolated_context(default_domain_id()) as context:
        node = Node("soak_player", context=context)
        watch = Watch(node, robots)
        clock = node.create_publisher(Clock, "/clock", 10)
        scans = {
            r: node.create_publisher(LaserScan, f"/{r}/scan", qos_profile_sensor_data)
            for r in robots
        }
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        begun = time.monotonic()
        deadline = begun + 60.0 * args.wall_limit if args.wall_limit else float("inf")
        waited = 0
        try:
            _matched(scans.values())
            ticks = int(args.minutes * 60.0 * RATE_HZ)
            for tick in range(ticks):
                stamp = SIM_START_S + tick / RATE_HZ
                ready = stamp - args.lag / RATE_HZ
                if not _wait(lambda r=ready: watch.slowest() >= r - 1e-6, args.tick_timeout):
                    waited += 1
                watch.clock = (stamp - SIM_START_S) / 60.0
                clock.publish(Clock(clock=stamp_from_seconds(stamp)))
                for robot, offset in zip(robots, offsets, strict=True):
                    frame = f"{robot}/laser"
                    scan = ranges[(tick + offset) % len(ranges)]
                    scans[robot].publish(scan_message(laser, frame, stamp, scan))
                if tick % int(args.sample * RATE_HZ) == 0:
                    samples.append(sample(nodes, watch.clock, time.monotonic() - begun))
                    report(samples[-1], watch, tick * len(robots))
                if time.monotonic() > deadline:
                    break
            sent = (tick + 1) * len(robots)
            _drain(watch, clock, stamp)
            samples.append(sample(nodes, watch.clock, time.monotonic() - begun))
        finally:
            executor.shutdown()
            spinner.join(10.0)
            node.destroy_node()
    return {
        "samples": samples,
        "merges": list(watch.merges),
        "sent": sent,
        "received": watch.counts("scans received"),
        "placed": dict(watch.poses),
        "set_aside": watch.counts("rejected: stale_in_queue"),
        "ticks_waited_out": waited,
        "wall_s": time.monotonic() - begun,
        "sim_min": watch.clock,
        "merger_status": dict(watch.merger),
    }


def _matched(publishers: Any) -> None:
    """Every scan topic has its mapper; then a little longer, so that both ends have matched
    and the first scans are not lost to discovery."""
    while any(p.get_subscription_count() == 0 for p in publishers):
        time.sleep(0.1)
    time.sleep(2.0)


def _drain(watch: Watch, clock: Any, stamp: float) -> None:
    """The last scans mapped, the last maps merged: the clock moves on 5 s more."""
    _wait(lambda: watch.slowest() >= stamp - 1e-6, 10.0)
    for extra in range(1, 51):
        clock.publish(Clock(clock=stamp_from_seconds(stamp + extra / RATE_HZ)))
        time.sleep(0.1)


def _wait(condition: Any, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.002)
    return True


def sample(nodes: NodeProcesses, sim_min: float, wall_s: float) -> Sample:
    rss = {}
    for name, process in nodes.processes.items():
        if process.poll() is None:
            rss[name] = tree_usage(process.pid)[1] / 1e6
    return Sample(round(sim_min, 3), round(wall_s, 1), rss)


def report(s: Sample, watch: Watch, sent: int) -> None:
    received = sum(watch.counts("scans received").values())
    total = sum(s.rss_mb.values())
    merge = watch.merges[-1][1] if watch.merges else float("nan")
    print(
        f"sim {s.sim_min:6.2f} min  wall {s.wall_s:7.1f} s"
        f"  x{60 * s.sim_min / max(s.wall_s, 1):.2f}"
        f"  RSS {total:7.1f} MB  merges {len(watch.merges)} (last {merge:.2f} s)"
        f"  scans sent {sent} received {received}",
        flush=True,
    )


def figures(run: dict[str, Any]) -> dict[str, Any]:
    """The targets' figures: memory growth after the first 10 minutes (all processes, and each),
    the merges' median wall time in the last window against the first after warm-up (windows
    of 10 minutes, or half of what ran after warm-up when that is shorter), scans dropped."""
    samples: list[Sample] = run["samples"]
    growth = {}
    for name in ["all", *sorted({n for s in samples for n in s.rss_mb})]:
        series = [
            sum(s.rss_mb.values()) if name == "all" else s.rss_mb[name]
            for s in samples
            if s.sim_min >= WARM_UP_MIN and (s.rss_mb if name == "all" else name in s.rss_mb)
        ]
        if len(series) >= 2:
            growth[name] = round((series[-1] - series[0]) / series[0], 4)
    end = run["sim_min"]
    window = min(WINDOW_MIN, max(end - WARM_UP_MIN, 0.0) / 2.0)
    merges = run["merges"]
    first = [s for t, s in merges if WARM_UP_MIN <= t < WARM_UP_MIN + window]
    last = [s for t, s in merges if end - window <= t <= end]
    change = float(np.median(last)) / float(np.median(first)) - 1.0 if first and last else None
    # Every scan sent that no pose came back for: lost in transit, set aside, or not placed.
    dropped = run["sent"] - sum(run["placed"].values())
    return {
        "simulated_min": round(end, 2),
        "wall_min": round(run["wall_s"] / 60.0, 2),
        "memory_growth_after_10_min": growth.get("all"),
        "memory_growth_by_process": growth,
        "window_min": round(window, 2),
        "merges_first_window": len(first),
        "merges_last_window": len(last),
        "merge_s_first_window_median": float(np.median(first)) if first else None,
        "merge_s_last_window_median": float(np.median(last)) if last else None,
        "merge_time_change": None if change is None else round(change, 4),
        "scans_sent": run["sent"],
        "scans_dropped": int(dropped),
        "scans_set_aside_stale": sum(run["set_aside"].values()),
        "ticks_waited_out": run["ticks_waited_out"],
    }


def run_of_json(path: Path) -> dict[str, Any]:
    """A run as :func:`figures` and :func:`plot` take it, from a JSON this bench wrote."""
    data = json.loads(path.read_text(encoding="utf-8"))
    return {
        "samples": [Sample(**s) for s in data["samples"]],
        "merges": [tuple(m) for m in data["merges"]],
        "sim_min": data["simulated_min"],
        "wall_s": 60.0 * data["wall_min"],
        "sent": data["scans_sent"],
        "placed": {"all": data["scans_sent"] - data["scans_dropped"]},
        "set_aside": {"all": data.get("scans_set_aside_stale", 0)},
        "ticks_waited_out": data["ticks_waited_out"],
        "merger_status": data.get("merger_status", {}),
        "crashes": data["crashes"],
        "exit_codes": data["exit_codes"],
        "laser": data["laser"],
        "robots": data["robots"],
    }


def plot(run: dict[str, Any], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    samples: list[Sample] = run["samples"]
    figure, (memory, merge) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    names = sorted({n for s in samples for n in s.rss_mb})
    for name in names:
        points = [(s.sim_min, s.rss_mb[name]) for s in samples if name in s.rss_mb]
        memory.plot(*zip(*points, strict=True), label=name, linewidth=1)
    totals = [(s.sim_min, sum(s.rss_mb.values())) for s in samples if s.rss_mb]
    memory.plot(*zip(*totals, strict=True), label="all", color="black", linewidth=2)
    memory.set_ylabel("resident memory (MB)")
    memory.set_yscale("log")
    memory.legend(fontsize=7, ncol=4)
    memory.axvline(WARM_UP_MIN, color="grey", linestyle=":")
    if run["merges"]:
        merge.plot(*zip(*run["merges"], strict=True), ".", markersize=3)
    merge.axvline(WARM_UP_MIN, color="grey", linestyle=":")
    merge.set_ylabel("merge update time (s, wall)")
    merge.set_xlabel("simulated time (min)")
    figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=90)
    plt.close(figure)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0, help="simulated (default 60)")
    parser.add_argument("--robots", type=int, default=8)
    parser.add_argument("--laser", choices=sorted(LASERS), default="lms")
    parser.add_argument("--lag", type=int, default=1, help="ticks a robot may be behind")
    parser.add_argument("--tick-timeout", type=float, default=2.0, help="s (wall)")
    parser.add_argument("--sample", type=float, default=30.0, help="simulated s between samples")
    parser.add_argument("--wall-limit", type=float, default=0.0, help="minutes (0: none)")
    parser.add_argument("--json", type=Path, default=OUTPUT / "soak.json")
    parser.add_argument("--plot", type=Path, default=OUTPUT / "soak.png")
    parser.add_argument("--logs", type=Path, default=OUTPUT / "soak_logs")
    parser.add_argument(
        "--from-json", type=Path, help="no run: the figures and the plot of a JSON written before"
    )
    args = parser.parse_args()
    run = soak(args) if args.from_json is None else run_of_json(args.from_json)
    result = {**figures(run), "crashes": run["crashes"], "exit_codes": run["exit_codes"]}
    laser, robots = run.get("laser", args.laser), run.get("robots", args.robots)
    result.update(laser=laser, robots=robots, merger_status=run["merger_status"])
    print(json.dumps(result, indent=1))
    title = (
        f"soak: {robots} robots, {laser} at 10 Hz, {result['simulated_min']:.1f} min "
        f"simulated in {result['wall_min']:.1f} min"
    )
    plot(run, args.plot, title)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    result["samples"] = [dataclasses.asdict(s) for s in run["samples"]]
    result["merges"] = run["merges"]
    args.json.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    return 0


def soak(args: argparse.Namespace) -> dict[str, Any]:
    """The run itself: the node processes started, played, stopped; a crash is a node
    process that was no longer running at the end."""
    robots = [f"robot{k + 1}" for k in range(args.robots)]
    nodes = NodeProcesses(node_commands(robots), default_domain_id(), log_dir=args.logs)
    try:
        run = play(args, nodes, robots)
        running = nodes.running()
    finally:
        codes = nodes.stop(timeout=30.0)
    run["crashes"] = sorted(n for n, up in running.items() if not up)
    run["exit_codes"] = codes
    return run


if __name__ == "__main__":
    raise SystemExit(main())
