"""A map_merger killed and started again mid-run (issue 50 item 4b): how long until every robot
it had placed is back in place?

Three robots drive the office world (``core/simulation.py``: 150 s each, sharing 45 % of their
stretches, scans at 10 Hz, every 4th of the simulated 40 Hz laser), played live into a
``robot_mapper`` process per robot; the ``map_merger`` is a process of its own
(``save_on_shutdown`` and ``load_on_start`` on one ``map_file``), as ``mrm run`` starts it.
Once it has placed the robots, it is stopped and started again, ``--cycles`` times, turn
about:

  kill   SIGKILL: nothing saved; the new merger gets each robot's latched ``partial_map``
         snapshot, then at the first update it cannot apply asks for a fresh one
         (``partial_map_request``)
  stop   SIGINT: the map saved on shutdown, loaded at start-up, then as for kill

For each cycle: seconds from starting the new process until its first ``/diagnostics`` (the
interpreter and rclpy starting, the saved map loaded), and until every robot placed before the
restart has its ``robot_frames/<robot>`` again (the figure; target 5 s), and how far each
placement moved (relative to the first robot's frame: the choice of reference does not count).
Whether the robots were still driving. The merge keeps going between cycles (each robot's
map keeps growing while they drive).

    .venv/bin/python -m bench.merger_restart [--cycles 6] [--json FILE]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from bench.harness import OUTPUT  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.simulation import LaserModel, simulate_robots  # noqa: E402
from multi_robot_mapper.io.bags import recording_of  # noqa: E402
from multi_robot_mapper.io.messages import pose_from_msg  # noqa: E402
from multi_robot_mapper.ros.live import ScanPlayer, timeline  # noqa: E402
from multi_robot_mapper.ros.map_merger import LATCHED_QOS  # noqa: E402
from multi_robot_mapper.ros.processes import (  # noqa: E402
    NodeProcesses,
    map_merger_command,
)
from multi_robot_mapper.ros.testing import default_domain_id, isolated_context  # noqa: E402

ROBOTS = ("robot1", "robot2", "robot3")
# The office's right joins get P 0.95-0.99 (test_link_graph.SIMULATED_WORLD_JOIN_PROBABILITY).
JOIN_PROBABILITY = 0.9
TARGET_S = 5.0
DRIVE_S = 150.0  # long enough for most restarts to come while the robots drive


class Frames:
    """The newest ``robot_frames/<robot>`` of each robot still placed and when it came
    (monotonic s), and whether a merger's ``/diagnostics`` came since :meth:`clear` (the new
    process is up: a killed participant's publishers stay in the graph until their lease ends,
    so counting ``global_map``'s publishers would count the dead one).

    A robot placed once and placed no more keeps its last latched ``robot_frames`` pose, in the
    ``map`` frame of that time (the reference may have changed since): the merger withdraws it
    by publishing 0 on ``robot_frames/<robot>/probability``, and so it is dropped here."""

    def __init__(self, node: Node) -> None:
        self._lock = threading.Lock()
        self.frames: dict[str, tuple[float, np.ndarray]] = {}
        self.heard: float | None = None
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        for robot in ROBOTS:
            node.create_subscription(
                PoseStamped,
                f"/robot_frames/{robot}",
                lambda msg, r=robot: self._on_frame(r, msg),
                LATCHED_QOS,
            )
            node.create_subscription(
                Float64,
                f"/robot_frames/{robot}/probability",
                lambda msg, r=robot: self._on_probability(r, msg),
                LATCHED_QOS,
            )

    def _on_frame(self, robot: str, msg: PoseStamped) -> None:
        with self._lock:
            self.frames[robot] = (time.monotonic(), np.asarray(pose_from_msg(msg.pose)))

    def _on_probability(self, robot: str, msg: Float64) -> None:
        if msg.data <= 0.0:
            with self._lock:
                self.frames.pop(robot, None)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        if any(status.name == "map_merger" for status in msg.status):
            with self._lock:
                self.heard = time.monotonic() if self.heard is None else self.heard

    def clear(self) -> None:
        with self._lock:
            self.frames.clear()
            self.heard = None

    def copy(self) -> dict[str, tuple[float, np.ndarray]]:
        with self._lock:
            return dict(self.frames)


def relative(frames: dict[str, tuple[float, np.ndarray]], robot: str, base: str) -> np.ndarray:
    """T_basemap_robotmap from two placements in ``map``."""
    T_map_base = se2.matrix_from_pose(*frames[base][1])
    return se2.invert(T_map_base) @ se2.matrix_from_pose(*frames[robot][1])


def moved(before: dict, after: dict, robots: list[str]) -> tuple[float, float]:
    """The largest change of any robot's placement relative to the first robot's (m, deg)."""
    worst_m = worst_deg = 0.0
    for robot in robots[1:]:
        a, b = relative(before, robot, robots[0]), relative(after, robot, robots[0])
        worst_m = max(worst_m, float(np.hypot(*(a[:2, 2] - b[:2, 2]))))
        turn = math.atan2(b[1, 0], b[0, 0]) - math.atan2(a[1, 0], a[0, 0])
        worst_deg = max(worst_deg, abs(math.degrees(math.remainder(turn, math.tau))))
    return worst_m, worst_deg


def wait(condition: Any, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return bool(condition())


class Merger:
    """The map_merger process, started and stopped by hand."""

    def __init__(self, map_file: Path, log_dir: Path, domain: int) -> None:
        self.command = map_merger_command(
            [
                *("-p", f"robots:={','.join(ROBOTS)}", "-p", "save_on_shutdown:=true"),
                *("-p", "load_on_start:=true", "-p", f"map_file:={json.dumps(str(map_file))}"),
                *("-p", f"merge.join_probability:={JOIN_PROBABILITY}"),
            ]
        )
        self.log_dir, self.domain, self.starts = log_dir, domain, 0
        self.map_file = map_file
        self.nodes: NodeProcesses | None = None

    def start(self) -> None:
        self.starts += 1
        name = f"map_merger_{self.starts}"
        self.nodes = NodeProcesses({name: self.command}, self.domain, self.log_dir)

    def keep_file(self) -> None:
        """A copy of the map file as the stopped merger left it (``global_map_<n>.json``,
        n the merger's start), for what a restart found."""
        if self.map_file.is_file():
            shutil.copy(self.map_file, self.log_dir / f"global_map_{self.starts}.json")

    def end(self, how: str) -> None:
        assert self.nodes is not None
        (process,) = self.nodes.processes.values()
        if how == "kill":
            process.send_signal(signal.SIGKILL)
            process.wait()
        else:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(20.0)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        self.nodes = None


def cycle(
    how: str, merger: Merger, frames: Frames, player: ScanPlayer, timeout: float
) -> dict[str, Any]:
    """One stop and start of the merger; what it took to get every robot back."""
    before = frames.copy()
    placed = sorted(before)
    driving = player.running()
    merger.end(how)
    merger.keep_file()
    frames.clear()
    started = time.monotonic()
    merger.start()
    up = wait(lambda: frames.heard is not None, timeout)
    up_s = (frames.heard or time.monotonic()) - started
    back = wait(lambda: set(placed) <= set(frames.copy()), timeout)
    after = frames.copy()
    back_s = max((after[r][0] for r in placed if r in after), default=started) - started
    worst_m, worst_deg = moved(before, after, placed) if back else (math.nan, math.nan)
    return {
        "how": how,
        "driving": driving,
        "robots": placed,
        "up_s": round(up_s, 2) if up else None,
        "back_s": round(back_s, 2) if back else None,
        "moved_m": round(worst_m, 4),
        "moved_deg": round(worst_deg, 3),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", type=int, default=6, help="stops and starts (default 6)")
    parser.add_argument("--timeout", type=float, default=60.0, help="s to wait for each step")
    parser.add_argument("--json", type=Path, default=OUTPUT / "merger_restart.json")
    args = parser.parse_args()
    runs = simulate_robots("office", 3, LaserModel(), seed=1, duration=DRIVE_S, overlap=0.45)
    scans = {r: recording_of(r, run).scans[::4] for r, run in zip(ROBOTS, runs, strict=True)}
    domain = default_domain_id()
    work = Path(tempfile.mkdtemp(prefix="merger_restart_"))
    mappers = NodeProcesses.robot_mappers(ROBOTS, domain, log_dir=work)
    merger = Merger(work / "global_map.json", work, domain)
    rows: list[dict[str, Any]] = []
    try:
        with isolated_context(domain) as context:
            watcher = Node("restart_watcher", context=context)
            frames = Frames(watcher)
            player = ScanPlayer(watcher, list(ROBOTS))
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(watcher)
            spinner = threading.Thread(target=executor.spin, daemon=True)
            spinner.start()
            merger.start()
            assert wait(player.subscribed, args.timeout), "the robot_mappers did not subscribe"
            player.start(timeline(scans))
            # Every robot placed, or as many as the merger is sure of by mid-drive.
            wait(lambda: len(frames.copy()) == len(ROBOTS), DRIVE_S / 2)
            assert frames.copy(), "no robot placed: nothing to restart"
            for k in range(args.cycles):
                row = cycle(("kill", "stop")[k % 2], merger, frames, player, args.timeout)
                rows.append(row)
                print(json.dumps(row), flush=True)
                time.sleep(3.0)  # the merger keeps merging the growing maps
            player.stop()
            merger.end("stop")
            executor.shutdown()
            spinner.join(10.0)
            watcher.destroy_node()
    finally:
        if merger.nodes is not None:
            merger.nodes.stop()
        mappers.stop()
    summarise(rows, args.json, work)
    return 0


def summarise(rows: list[dict[str, Any]], path: Path, work: Path) -> None:
    backs = [r["back_s"] for r in rows if r["back_s"] is not None]
    print("\n| cycle | how | driving | robots | up (s) | every robot back (s) | moved (m, deg) |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for k, r in enumerate(rows, 1):
        print(
            f"| {k} | {r['how']} | {'yes' if r['driving'] else 'no'} | {len(r['robots'])} | "
            f"{r['up_s']} | {r['back_s']} | {r['moved_m']}, {r['moved_deg']} |"
        )
    if backs:
        print(
            f"\nevery robot back in place: median {np.median(backs):.2f} s, max {max(backs):.2f} "
            f"s over {len(backs)} of {len(rows)} restarts (target {TARGET_S:g} s); logs in {work}"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"cycles": rows}, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    raise SystemExit(main())
