"""``mrm demo``: three simulated robots mapped live, merged into one map, drawn and scored.

The scenario: three robots drive partly overlapping stretches of the built-in office world
(``core/worlds.py``, ray cast by ``core/simulation.py``), each with a simulated Hokuyo UTM-30LX
(40 Hz, 1081 beams, 270°), starting ``stagger`` seconds apart, none knowing where the others
are. Their scans are published live on ``/robotK/scan`` at the laser's own rate (``--speed``
plays faster or slower) into real ``robot_mapper`` nodes and a real ``map_merger``, each a
process of its own as on a team's computers, over real DDS topics, with the shipped default
parameters. Everything drawn and scored
comes back over the nodes' topics (``/global_map``, ``/robot_frames/<robot>``,
``/<robot>/pose``, ``/<robot>/partial_map``, ``/global_grid``, ``/diagnostics``).

Written to ``--out``: ``bag/`` (the simulated scans and ground truth), ``result/`` (map.json,
robots.json, trajectories, metrics.json: what ``mrm replay`` writes, so ``mrm evaluate
result --bag bag`` scores it again), ``global_map.png``, ``joining.png`` (snapshots as robots
join), ``joining.gif``, ``global_grid.png``, ``saved_map.json`` (the merger's
``save_map``) and ``outputs.mcap`` (the merger's outputs as they arrived, for Foxglove and
``ros2 bag play``: ``config/foxglove_layout.json``, ``config/multi_robot_mapper.rviz``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from types import MappingProxyType

import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from multi_robot_mapper.cli.recordings import read_as_usual
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.simulation import LaserModel, SimulatedRobot, simulate_robots
from multi_robot_mapper.core.worlds import WORLDS
from multi_robot_mapper.evaluation.metrics import Metrics, evaluate
from multi_robot_mapper.io import pictures
from multi_robot_mapper.io.bags import RobotRecording, recording_of, write_recordings
from multi_robot_mapper.io.messages import partial_map_contents
from multi_robot_mapper.io.output_bag import OutputBag
from multi_robot_mapper.io.outputs import atomic_write_text, staged_entries
from multi_robot_mapper.io.results import ReplayResult, write_results
from multi_robot_mapper.ros.live import GlobalMapView, Observer, PlayStats, ScanPlayer, timeline
from multi_robot_mapper.ros.markers import grid_from_msg
from multi_robot_mapper.ros.processes import (
    NodeProcesses,
    map_merger_command,
    robot_mapper_command,
)
from multi_robot_mapper.ros.recording import LiveRecorder
from multi_robot_mapper.ros.testing import default_domain_id, isolated_context

FloatArray = np.typing.NDArray[np.float64]
LEVELS = MappingProxyType({0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"})


@dataclasses.dataclass(frozen=True)
class DemoScenario:
    """What the demo simulates and how it plays it."""

    world: str = "office"
    robots: int = 3
    duration: float = 20.0  # s of driving per robot (0.8 m/s)
    stagger: float = 6.0  # s between one robot's first scan and the next one's
    # share of a robot's stretch its neighbour drives too: the joint graph links two maps by
    # at least two places that agree, about 3 m apart
    overlap: float = 0.45
    seed: int = 0
    speed: float = 1.0  # play speed: 1 = in real time, at the laser's rate
    settle_timeout: float = 30.0  # s after the last scan for the last maps to be merged

    @property
    def names(self) -> list[str]:
        return [f"robot{k + 1}" for k in range(self.robots)]


@dataclasses.dataclass
class LiveOutcome:
    """What came back over the topics while the scenario played."""

    observer: Observer
    play: PlayStats
    play_started: float  # time.monotonic() of the first scan
    scans_received: dict[str, int]  # as each robot_mapper's last /diagnostics said
    settled: bool  # every final partial map was merged before settle_timeout
    # received, then dropped for waiting longer than scan_max_queue_delay (the mapper was
    # behind): as lost as a scan dropped in transit
    scans_stale: dict[str, int]


@dataclasses.dataclass
class DemoResult:
    robots: list[str]
    merged: list[str]
    metrics: Metrics
    table: str
    files: dict[str, Path]
    live: LiveOutcome
    statuses: list[str]  # the merger's last /diagnostics, one line per robot
    wall_s: float


def simulate_scenario(scenario: DemoScenario) -> dict[str, RobotRecording]:
    """The robots' scans and true poses, robot k starting ``k * stagger`` s after robot 1."""
    runs = simulate_robots(
        scenario.world,
        scenario.robots,
        LaserModel(),
        scenario.seed,
        scenario.duration,
        overlap=scenario.overlap,
    )
    late = [
        SimulatedRobot(run.stamps + k * scenario.stagger, run.T_world_laser, run.scans)
        for k, run in enumerate(runs)
    ]
    return {name: recording_of(name, run) for name, run in zip(scenario.names, late, strict=True)}


def play_live(
    recordings: dict[str, RobotRecording],
    scenario: DemoScenario,
    saved_map: Path,
    log_dir: Path | None = None,
    record: Path | None = None,
) -> LiveOutcome:
    """Play the recordings live into a robot_mapper process per robot (as on the robots) and
    a map_merger process, watch their topics; the merger saves its map to ``saved_map`` as it
    stops. ``record``: an MCAP file of the merger's outputs as they arrived
    (:class:`~multi_robot_mapper.ros.recording.LiveRecorder`)."""
    with contextlib.ExitStack() as stack:
        bag = None if record is None else stack.enter_context(OutputBag(record))
        return _play_live(recordings, scenario, saved_map, log_dir, bag)


def _node_processes(robots: list[str], saved_map: Path, log_dir: Path | None) -> NodeProcesses:
    """A robot_mapper per robot and the map_merger, with the shipped defaults; the merger
    saves its map on shutdown."""
    commands = {robot: robot_mapper_command(robot) for robot in robots}
    commands["map_merger"] = map_merger_command(
        [
            *("-p", f"robots:={','.join(robots)}", "-p", "save_on_shutdown:=true"),
            *("-p", f"map_file:={json.dumps(str(saved_map.resolve()))}"),
        ]
    )
    return NodeProcesses(commands, default_domain_id(), log_dir=log_dir)


def _play_live(
    recordings: dict[str, RobotRecording],
    scenario: DemoScenario,
    saved_map: Path,
    log_dir: Path | None,
    bag: OutputBag | None,
) -> LiveOutcome:
    robots = list(recordings)
    nodes = _node_processes(robots, saved_map, log_dir)
    try:
        with isolated_context(default_domain_id()) as context:
            observer = Observer(robots, context=context)
            driver = Node("demo_player", context=context)
            player = ScanPlayer(driver, robots, scenario.speed)
            # One thread: the callbacks here are short, and rclpy's multi-threaded executor
            # spends more CPU waking than they take (the mappers need those cores).
            executor = SingleThreadedExecutor(context=context)
            watchers: list[Node] = [observer, driver]
            if bag is not None:
                watchers.append(LiveRecorder(robots, bag, context=context))
            for node in watchers:
                executor.add_node(node)
            spinner = threading.Thread(target=executor.spin, daemon=True)
            spinner.start()
            try:
                if not _wait(lambda: player.subscribed() and _merger_up(driver), 30.0):
                    raise RuntimeError(
                        "the node processes did not subscribe to their inputs within 30 s "
                        f"(running: {nodes.running()}; logs: {log_dir})"
                    )
                # The player sees each mapper's subscription before that subscription has
                # matched the player in turn (discovery runs both ways): a scan published at
                # once can be lost (1 of 2 400 lost in transit in 3 of 5 runs without this
                # wait, robot1's where counted; 0 in 4 of 4 with it).
                time.sleep(DISCOVERY_S)
                started = time.monotonic()
                scans = {r: rec.scans for r, rec in recordings.items()}
                stats = player.play(timeline(scans, 0.025))
                done = _wait(lambda: _settled(observer), scenario.settle_timeout)
                time.sleep(1.5)  # the last global map, frames and diagnostics arrive
                codes = nodes.stop()  # the merger saves its map as it stops
            finally:
                executor.shutdown()
                spinner.join(timeout=10.0)
                for node in watchers:
                    node.destroy_node()
    finally:
        nodes.stop()
    if codes.get("map_merger") != 0:
        raise RuntimeError(f"the map_merger did not stop cleanly: {codes} (logs: {log_dir})")

    def count(robot: str, key: str) -> int:
        return int(observer.status_value(f"{robot}/robot_mapper", key) or 0)

    received = {robot: count(robot, "scans received") for robot in robots}
    stale = {robot: count(robot, "rejected: stale_in_queue") for robot in robots}
    return LiveOutcome(observer, stats, started, received, done, stale)


QUIET_S = 2.5  # no partial map for this long after the last scan: every final map is out
DISCOVERY_S = 1.0  # after the subscriptions are seen, for discovery's other half (_play_live)


def _merger_up(node: Node) -> bool:
    """The merger process offers its global map (it is subscribed to the robots by then)."""
    return node.count_publishers("/global_map") > 0


def _settled(observer: Observer) -> bool:
    """No robot has published a map for QUIET_S, and the merger's last /diagnostics says it
    holds every robot's newest partial map (as many keyframes as the observer's) and has
    merged everything it received."""
    now = time.monotonic()
    if not observer.partial_maps or any(
        now - observer.partial_map_times[r] < QUIET_S for r in observer.partial_maps
    ):
        return False
    held = {r: observer.status_value(f"map_merger/{r}", "keyframes") for r in observer.partial_maps}
    newest = {
        r: str(len(partial_map_contents(m).keyframe_poses))
        for r, m in observer.partial_maps.items()
    }
    return held == newest and observer.status_value("map_merger", "up to date") == "yes"


def _wait(condition: object, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():  # type: ignore[operator]
            return True
        time.sleep(0.05)
    return bool(condition())  # type: ignore[operator]


def live_results(observer: Observer) -> ReplayResult:
    """The live outputs in the replay result layout: the global map as the merger last
    published it, each robot's poses moved into ``map`` by its frame (in its own frame when
    unmerged) and the robot frames."""
    robots = sorted(observer.robots)
    last = observer.global_maps[-1] if observer.global_maps else None
    pieces = [] if last is None else [(r, s) for r, s in last.segments.items() if r in robots]
    segments = np.vstack([s for _, s in pieces]) if pieces else np.zeros((0, 4))
    owners = np.concatenate(
        [np.full(len(s), robots.index(r), dtype=np.int64) for r, s in pieces]
        or [np.zeros(0, dtype=np.int64)]
    )
    frames: dict[str, tuple[float, float, float] | None] = {}
    trajectories = {}
    for robot in robots:
        placement = observer.placement(robot)
        stamps, poses = observer.trajectory(robot)
        if placement is not None:
            poses = _moved(se2.matrix_from_pose(*placement), poses)
            frames[robot] = (float(placement[0]), float(placement[1]), float(placement[2]))
        else:
            frames[robot] = None
        trajectories[robot] = (stamps, poses)
    return ReplayResult("pivot (live)", robots, segments, owners, trajectories, frames, {})


def _moved(T_map_robot: FloatArray, poses: FloatArray) -> FloatArray:
    matrices = [T_map_robot @ se2.matrix_from_pose(*p) for p in poses]
    return np.array([se2.pose_from_matrix(T) for T in matrices]).reshape(-1, 3)


def run_demo(out_dir: Path, scenario: DemoScenario | None = None) -> DemoResult:
    """The whole demo: simulate, play live, collect, score, draw."""
    import json

    from multi_robot_mapper.cli.evaluate import build_inputs, format_table

    begun = time.monotonic()
    scenario = scenario or DemoScenario()
    out_dir = Path(out_dir)
    # Every output is made in a fresh folder inside --out and moved into place when the demo
    # is done: an interrupted demo (Ctrl-C, an error) leaves the old outputs whole, not an
    # old bag gone and a new one half-written. The logs are written in place as the nodes
    # run: they are no result, and most wanted when the demo fails.
    logs = out_dir / "logs"
    with staged_entries(out_dir) as staging:
        recordings = simulate_scenario(scenario)
        made = {"bag": write_recordings(staging / "bag", recordings)}
        made["saved map"] = staging / "saved_map.json"
        made["recording"] = staging / "outputs.mcap"
        live = play_live(recordings, scenario, made["saved map"], logs, made["recording"])

        # The result records the bag where it will be once moved into place, so that
        # ``mrm evaluate OUT/result`` scores against it without --bag.
        result = dataclasses.replace(
            live_results(live.observer),
            replayed=read_as_usual([out_dir.resolve() / "bag"]),
        )
        made["result"] = staging / "result"
        write_results(made["result"], result)
        inputs = build_inputs(result, recordings)
        metrics = evaluate(
            inputs.tracks, result.map_segments, inputs.reference_points, result.robot_frames
        )
        atomic_write_text(
            made["result"] / "metrics.json", json.dumps(metrics.to_dict(), indent=1) + "\n"
        )
        table = format_table(metrics, result.method)
        made.update(draw_demo(staging, scenario, live, result, metrics))
    files = {name: out_dir / path.relative_to(staging) for name, path in made.items()}
    files["logs"] = logs
    merged = [r for r in result.robots if result.robot_frames[r] is not None]
    statuses = [
        f"{status.name}: {LEVELS.get(status.level[0], '?')} - {status.message}"
        for name, status in sorted(live.observer.diagnostics.items())
        if name.startswith("map_merger")
    ]
    return DemoResult(
        result.robots, merged, metrics, table, files, live, statuses, time.monotonic() - begun
    )


def draw_demo(
    out_dir: Path,
    scenario: DemoScenario,
    live: LiveOutcome,
    result: ReplayResult,
    metrics: Metrics,
) -> dict[str, Path]:
    """global_map.png, joining.png, joining.gif and global_grid.png."""
    observer = live.observer
    colors = pictures.robot_colors(result.robots)
    files: dict[str, Path] = {}
    merged = {r: s for r, s in _by_robot(result).items() if result.robot_frames[r] is not None}
    unmerged = {r: observer.partial_map(r) for r in result.robots if r not in merged}
    paths = {r: result.trajectories[r][1][:, :2] for r in result.robots}
    walls_world = WORLDS[scenario.world]()
    walls = se2.transform_segments(se2.invert(metrics.T_ref_map), walls_world) if merged else None
    title = (
        f"global map (frame 'map'): {len(merged)} of {len(result.robots)} robots merged live, "
        f"{len(result.map_segments)} segments"
    )
    figure = pictures.draw_global_map(
        merged,
        {r: p for r, p in paths.items() if r in merged},
        unmerged,
        {r: p for r, p in paths.items() if r in unmerged},
        colors,
        title,
        walls,
    )
    files["global map"] = pictures.save_figure(figure, out_dir / "global_map.png")
    views = observer.global_maps
    if views:
        extent = pictures.segments_extent([s for v in views for s in v.segments.values()])
        snapshots = [_titled(v, live.play_started) for v in joining_views(views)]
        figure = pictures.draw_snapshots(snapshots, colors, extent)
        files["snapshots"] = pictures.save_figure(figure, out_dir / "joining.png")
        frames = [_titled(v, live.play_started) for v in every_second(views)]
        files["animation"] = pictures.animate_snapshots(
            frames, colors, extent, out_dir / "joining.gif"
        )
    if observer.grid is not None:
        grid = grid_from_msg(observer.grid)
        known = np.count_nonzero(grid.cells >= 0)
        figure = pictures.draw_grid(
            grid.cells,
            grid.origin,
            grid.resolution,
            f"global_grid: {grid.width} x {grid.height} cells of {grid.resolution:g} m, "
            f"{known} known",
        )
        files["occupancy grid"] = pictures.save_figure(figure, out_dir / "global_grid.png")
    return files


def _by_robot(result: ReplayResult) -> dict[str, FloatArray]:
    return {
        robot: result.map_segments[result.segment_robot == index]
        for index, robot in enumerate(result.robots)
    }


def joining_views(views: Sequence[GlobalMapView]) -> list[GlobalMapView]:
    """The first global map, the first one showing each further robot, and the last."""
    chosen: list[GlobalMapView] = []
    shown = 0
    for view in views:
        if len(view.segments) > shown:
            shown = len(view.segments)
            chosen.append(view)
    if views and (not chosen or chosen[-1] is not views[-1]):
        chosen.append(views[-1])
    return chosen


def every_second(views: Sequence[GlobalMapView], spacing: float = 1.0) -> list[GlobalMapView]:
    """Global maps at least ``spacing`` s apart (and the last)."""
    chosen: list[GlobalMapView] = []
    for view in views:
        if not chosen or view.received_s - chosen[-1].received_s >= spacing:
            chosen.append(view)
    if views and chosen[-1] is not views[-1]:
        chosen.append(views[-1])
    return chosen


def _titled(view: GlobalMapView, started: float) -> tuple[str, dict[str, FloatArray]]:
    names = ", ".join(sorted(view.segments)) or "nobody"
    return (f"t = {view.received_s - started:.0f} s: {names} in the map", view.segments)
