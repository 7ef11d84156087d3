"""A real map_merger with real robot_mapper nodes, in-process: a simulated bag's scans go out
on ``/robotK/scan``, the merger discovers the robots' ``partial_map`` topics, and the global
map and the robot frames come back over real topics.

One drive is simulated and fed once (module fixture): robots 1-3 drive partly overlapping
stretches of the office world, robot 4 drives through another building that shares nothing
with it. The merger runs on its own MultiThreadedExecutor in a thread, as ``main()`` runs it.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from test_link_graph import SIMULATED_WORLD_JOIN_PROBABILITY
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import point_segment_distance
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.simulation import (
    SIM_START_S,
    LaserModel,
    SimulatedRobot,
    drive_path,
    simulate_robots,
    simulate_scan,
)
from multi_robot_mapper.core.worlds import office_world
from multi_robot_mapper.io.bags import (
    RobotRecording,
    read_recordings,
    recording_of,
    write_recordings,
)
from multi_robot_mapper.io.messages import (
    partial_map_markers,
    pose_from_msg,
    scan_to_msg,
    seconds_from_stamp,
    segments_from_marker,
    stamp_from_seconds,
)
from multi_robot_mapper.ros.map_merger import LATCHED_QOS, MapMerger, main
from multi_robot_mapper.ros.robot_mapper import RobotMapper
from multi_robot_mapper.ros.testing import default_domain_id, isolated_context, spin_until

pytestmark = pytest.mark.ros

OFFICE_ROBOTS = ("robot1", "robot2", "robot3")
STRANGER = "robot4"
DURATION = 20.0  # s of driving per robot (about 16 m; neighbours share about 5 m of it)
EVERY = 4  # every 4th scan of the 40 Hz drive: 10 Hz, as test_robot_mapper feeds it
TIME_LIMIT = 45.0  # s from the first scan until every office robot is merged


def stranger_run(duration: float, seed: int) -> SimulatedRobot:
    """A drive through another building (test_link_graph's ``stranger_walls``).

    Not the built-in ``rooms`` or ``corridors`` worlds: those are drawn on the same grid of
    right angles as the office, where segment overlap alone links look-alike places and only
    the free-space test separates them (test_link_graph's look-alike test covers that case).
    """
    from test_link_graph import stranger_walls

    walls = stranger_walls()
    laser = LaserModel()
    route = np.array([(2.5, 5.5), (5.0, 6.5), (8.0, 5.0), (11.0, 3.5)])
    poses = drive_path(route, 0.8, laser.rate, duration)
    rng = np.random.default_rng(seed)
    stamps = SIM_START_S + np.arange(len(poses), dtype=np.float64) / laser.rate
    scans = [simulate_scan(walls, (p[0], p[1], p[2]), laser, rng) for p in poses]
    return SimulatedRobot(stamps=stamps, T_world_laser=poses, scans=scans)


@dataclass
class Outcome:
    """What came out of the one simulated drive."""

    runs: dict[str, SimulatedRobot]
    merger: MapMerger
    mappers: dict[str, RobotMapper]
    global_maps: list[MarkerArray]
    frames: dict[str, list[PoseStamped]]
    logged: list[str]
    seconds_to_merged: float | None
    map_stamps: dict[str, tuple[int, int]] = field(default_factory=dict)


def _stamp(msg_stamp: object) -> tuple[int, int]:
    return (msg_stamp.sec, msg_stamp.nanosec)  # type: ignore[attr-defined]


def simulated_bag(runs: dict[str, SimulatedRobot], folder: Path) -> dict[str, RobotRecording]:
    """The runs written to an mcap bag (``/<robot>/scan``, ``/<robot>/ground_truth``) and read
    back: what a user replays."""
    recordings = {name: recording_of(name, run) for name, run in runs.items()}
    write_recordings(folder / "bag", recordings)
    return read_recordings(folder / "bag")


@pytest.fixture(scope="module")
def outcome(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Outcome]:
    office = simulate_robots("office", 3, LaserModel(), seed=0, duration=DURATION)
    runs = dict(zip(OFFICE_ROBOTS, office, strict=True))
    runs[STRANGER] = stranger_run(DURATION, seed=0)
    bag = simulated_bag(runs, tmp_path_factory.mktemp("merger"))
    assert sorted(bag) == sorted(runs)
    with isolated_context() as context:
        fast_map = [Parameter("partial_map_period", value=0.5)]
        mappers = {
            name: RobotMapper(context=context, namespace=name, parameter_overrides=fast_map)
            for name in runs
        }
        merger = MapMerger(
            context=context,
            parameter_overrides=[
                Parameter("discovery_period", value=0.3),
                Parameter("merge_period", value=0.5),
                Parameter("merge.join_probability", value=SIMULATED_WORLD_JOIN_PROBABILITY),
            ],
        )
        logged: list[str] = []
        merger.notes.log = logged.append
        driver = Node("driver", context=context)
        scan_pubs = {
            name: driver.create_publisher(LaserScan, f"/{name}/scan", qos_profile_sensor_data)
            for name in runs
        }
        global_maps: list[MarkerArray] = []
        # Every global map kept for the DELETE check below: a depth of 1 (the merger's latched
        # QoS) lets a new message replace one the busy executor has not taken yet, and the
        # check then sees markers vanish without the DELETE that message carried.
        every_map = QoSProfile(
            depth=100,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        driver.create_subscription(MarkerArray, "/global_map", global_maps.append, every_map)
        frames: dict[str, list[PoseStamped]] = {name: [] for name in runs}
        for name in runs:
            driver.create_subscription(
                PoseStamped, f"/robot_frames/{name}", frames[name].append, LATCHED_QOS
            )
        executor = SingleThreadedExecutor(context=context)
        for node in (*mappers.values(), driver):
            executor.add_node(node)
        merger_executor = MultiThreadedExecutor(num_threads=2, context=context)
        merger_executor.add_node(merger)
        thread = threading.Thread(target=merger_executor.spin, daemon=True)
        thread.start()
        try:
            assert spin_until(
                executor,
                lambda: all(p.get_subscription_count() > 0 for p in scan_pubs.values()),
                timeout=10.0,
            )
            started = time.monotonic()
            merged_at: list[float] = []

            def all_office_merged() -> bool:
                if not merged_at and all(frames[name] for name in OFFICE_ROBOTS):
                    merged_at.append(time.monotonic() - started)
                return bool(merged_at)

            count = len(office[0].scans)
            for i in range(0, count, EVERY):
                before = {name: m.scans_received for name, m in mappers.items()}
                for name in runs:
                    item = bag[name].scans[i]  # the bag's scans, as a replay publishes them
                    stamp = stamp_from_seconds(item.stamp)
                    scan_pubs[name].publish(scan_to_msg(item.scan, item.frame_id, stamp, 0.025))
                assert spin_until(
                    executor,
                    lambda b=before: all(m.scans_received > b[n] for n, m in mappers.items()),
                    timeout=5.0,
                )
                all_office_merged()

            def settled() -> bool:
                """Every final partial map published, received and merged, every place
                matched (no further merge will change the result the last global map
                shows)."""
                all_office_merged()
                local_done = all(m.map_published for m in mappers.values())
                with merger._lock:
                    versions = {n: s.version for n, s in merger.robots.items()}
                    received = all(
                        len(s.segments)
                        and s.map_stamp is not None
                        and seconds_from_stamp(s.map_stamp)
                        == max(kf.stamp for kf in mappers[n].mapper.keyframes())
                        for n, s in merger.robots.items()
                    )
                return (
                    local_done
                    and received
                    and set(versions) == set(runs)
                    and merger._merged_versions == versions
                    and merger.up_to_date()
                    and bool(merged_at)
                )

            spin_until(
                executor, settled, timeout=max(5.0, TIME_LIMIT - (time.monotonic() - started))
            )
            spin_until(executor, lambda: False, timeout=1.0)  # the last messages arrive
        finally:
            merger_executor.shutdown()
            thread.join(timeout=10.0)
            executor.shutdown()
        result = Outcome(
            runs=runs,
            merger=merger,
            mappers=mappers,
            global_maps=global_maps,
            frames=frames,
            logged=logged,
            seconds_to_merged=merged_at[0] if merged_at else None,
        )
        with merger._lock:
            result.map_stamps = {
                n: _stamp(s.map_stamp) for n, s in merger.robots.items() if s.map_stamp
            }
        yield result
        for node in (*mappers.values(), merger, driver):
            node.destroy_node()


def truth(run: SimulatedRobot) -> np.ndarray:
    """T_world_robotmap: the robot's map frame is its laser at the first scan."""
    return se2.matrix_from_pose(*run.T_world_laser[0])


def test_every_office_robot_is_merged_in_time_where_the_truth_puts_it(outcome: Outcome) -> None:
    merger = outcome.merger
    assert outcome.seconds_to_merged is not None, (merger.result, outcome.logged)
    assert outcome.seconds_to_merged < TIME_LIMIT
    result = merger.result
    assert result is not None and result.reference in OFFICE_ROBOTS
    assert set(merger.robots) == {*OFFICE_ROBOTS, STRANGER}  # all four discovered
    T_world_map = truth(outcome.runs[result.reference])
    for name in OFFICE_ROBOTS:
        message = outcome.frames[name][-1]
        assert message.header.frame_id == "map"
        got = pose_from_msg(message.pose)
        want = se2.pose_from_matrix(se2.invert(T_world_map) @ truth(outcome.runs[name]))
        assert math.hypot(got[0] - want[0], got[1] - want[1]) < 0.10, (name, got, want)
        assert abs(math.remainder(got[2] - want[2], math.tau)) < math.radians(1.0), name
        np.testing.assert_allclose(got, result.placements[name], atol=1e-9)
    assert result.placements[result.reference] == (0.0, 0.0, 0.0)
    assert merger.merges >= 1 and merger.merge_errors == 0


def test_the_global_map_shows_one_marker_per_keyframe_poses_and_names(outcome: Outcome) -> None:
    assert outcome.global_maps
    array = outcome.global_maps[-1]
    first = array.markers[0]
    for marker in array.markers:
        assert marker.header.frame_id == "map"
        assert marker.header.stamp == first.header.stamp
    # Stamped from the input (simulated scans start in 2001), never from now().
    stamp = seconds_from_stamp(first.header.stamp)
    newest_scan = max(run.stamps[-1] for run in outcome.runs.values())
    assert SIM_START_S <= stamp <= newest_scan
    assert _stamp(first.header.stamp) >= max(outcome.map_stamps.values())
    shown = [m for m in array.markers if m.action == Marker.ADD]
    lines = [m for m in shown if m.type == Marker.LINE_LIST]
    assert {m.ns for m in lines} == {f"global_map/{name}" for name in OFFICE_ROBOTS}
    colors = {(m.color.r, m.color.g, m.color.b) for m in lines}
    assert len(colors) == 3  # one colour per robot
    # One marker per merged keyframe, placed at the keyframe's optimised pose in map: its
    # segments, moved by that pose, lie where the truth puts the robot's walls.
    result = outcome.merger.result
    assert result is not None
    T_world_map = truth(outcome.runs[result.reference])
    for name in OFFICE_ROBOTS:
        mine = [m for m in lines if m.ns == f"global_map/{name}"]
        assert sorted(m.id for m in mine) == result.keyframe_index[name].tolist()
        index = result.keyframe_index[name].tolist()
        poses = dict(zip(index, result.keyframe_poses[name], strict=True))
        for marker in mine:
            np.testing.assert_allclose(pose_from_msg(marker.pose), poses[marker.id], atol=1e-6)
    segments = np.vstack(
        [
            se2.transform_segments(
                se2.matrix_from_pose(*pose_from_msg(m.pose)), segments_from_marker(m)
            )
            for m in lines
        ]
    )
    assert len(segments) >= 100
    world = se2.transform_segments(T_world_map, segments)
    ends = world.reshape(-1, 2)
    walls = office_world()
    gaps = point_segment_distance(
        ends[:, None, 0], ends[:, None, 1], *(walls[None, :, k] for k in range(4))
    ).min(axis=1)
    assert np.median(gaps) < 0.05, np.median(gaps)
    names = {m.text for m in shown if m.type == Marker.TEXT_VIEW_FACING}
    assert names == set(OFFICE_ROBOTS)
    # Markers of keyframes no longer shown are deleted, never left behind.
    for earlier, later in zip(outcome.global_maps, outcome.global_maps[1:], strict=False):
        before = {(m.ns, m.id) for m in earlier.markers if m.action == Marker.ADD}
        now = {(m.ns, m.id) for m in later.markers if m.action == Marker.ADD}
        deleted = {(m.ns, m.id) for m in later.markers if m.action == Marker.DELETE}
        assert before - now <= deleted
    arrows = [m for m in shown if m.type == Marker.ARROW]
    assert len(arrows) == 3
    # Each arrow is its robot's newest pose, placed in map: near where the truth has it.
    result = outcome.merger.result
    assert result is not None
    T_world_map = truth(outcome.runs[result.reference])
    for arrow in arrows:
        robot = result.robots[arrow.id]
        run = outcome.runs[robot]
        got = pose_from_msg(arrow.pose)
        distances = [
            math.hypot(*(se2.invert(T_world_map) @ np.array([x, y, 1.0]))[:2] - got[:2])
            for x, y, _ in run.T_world_laser[-EVERY * 3 :]
        ]
        assert min(distances) < 0.2, (robot, got)


def test_a_robot_whose_map_never_overlaps_ends_unmerged(outcome: Outcome) -> None:
    merger = outcome.merger
    state = merger.robots[STRANGER]
    assert len(state.segments) >= 50  # it did send a map...
    assert merger.result is not None and merger.result.placements[STRANGER] is None
    said = [line for line in outcome.logged if f"'{STRANGER}' is unmerged" in line]
    assert said and len(said) <= 5  # ...it is logged as unmerged, throttled...
    array = outcome.global_maps[-1]
    assert STRANGER not in {m.text for m in array.markers}  # ...and not drawn
    assert f"global_map/{STRANGER}" not in {m.ns for m in array.markers if m.action == Marker.ADD}


def test_a_robot_whose_map_never_overlaps_is_never_linked(outcome: Outcome) -> None:
    # Not even for a while. On segment overlap alone, some runs linked the stranger at an
    # intermediate stage of the growing maps (fraction 0.4-0.7); links are now also judged on
    # the free space the robots saw from their keyframes (test_link_graph's look-alike test) and
    # on the match confidence. Before any link exists the largest map is the reference, and
    # that may be the stranger's: its frame is then `map` itself, the identity, until the
    # office robots' linked group outgrows it. Any other frame would come from a wrong link.
    for frame in outcome.frames[STRANGER]:
        p, q = frame.pose.position, frame.pose.orientation
        assert (p.x, p.y, q.z) == (0.0, 0.0, 0.0), frame
    assert outcome.merger.result is not None
    assert outcome.merger.result.placements[STRANGER] is None
    assert all(STRANGER not in (link.robot_a, link.robot_b) for link in outcome.merger.result.links)


def test_listed_robots_are_subscribed_without_discovery(ros_context) -> None:
    node = MapMerger(
        context=ros_context, parameter_overrides=[Parameter("robots", value="/alpha, beta/")]
    )
    try:
        assert sorted(node.robots) == ["alpha", "beta"]
        topics = {s.topic_name for state in node.robots.values() for s in state.subscriptions}
        assert topics == {
            f"/{robot}/{topic}"
            for robot in ("alpha", "beta")
            for topic in ("partial_map", "partial_map_updates", "pose")
        }
        assert node.merge_now() is False  # no map yet: nothing to merge, nothing published
        assert node.global_maps_published == 0
    finally:
        node.destroy_node()


def test_runtime_parameter_changes_are_validated(ros_context) -> None:
    node = MapMerger(context=ros_context, node_name="merger_two")
    try:
        results = node.set_parameters([Parameter("method", value="icp")])
        assert not results[0].successful and "icp" in results[0].reason
        results = node.set_parameters([Parameter("merge.ffs.time_budget", value=-1.0)])
        assert not results[0].successful and "time_budget" in results[0].reason
        results = node.set_parameters([Parameter("merge.join_probability", value=0.2)])
        assert not results[0].successful and "join_probability" in results[0].reason
        results = node.set_parameters([Parameter("merge_period", value=0.25)])
        assert results[0].successful and node._merge_timer.timer_period_ns == 250_000_000
        assert node.config.method == "pivot"
    finally:
        node.destroy_node()


def test_main_exits_2_with_one_line_for_an_unknown_method(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", str(default_domain_id()))
    code = main(["map_merger", "--ros-args", "-p", "method:=icp"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "icp" in err


def _partial_map_message(segments: np.ndarray, laser_poses: np.ndarray, name: str) -> MarkerArray:
    """A partial map as robot_mapper sends it: one keyframe per laser pose (the merger's
    viewpoints); the first owns every segment (in its own frame), the others none."""
    keyframes = [
        Keyframe(k, SIM_START_S + k, np.asarray(pose, dtype=np.float64), np.zeros((0, 4)))
        for k, pose in enumerate(laser_poses)
    ]
    T_map_first = se2.matrix_from_pose(*laser_poses[0])
    own = se2.transform_segments(se2.invert(T_map_first), segments)
    keyframes[0] = Keyframe(0, SIM_START_S, np.asarray(laser_poses[0], dtype=np.float64), own)
    return partial_map_markers(keyframes, stamp_from_seconds(SIM_START_S + 99), f"{name}/map", 0.03)


@pytest.mark.parametrize("method", ["pivot", "ffs"])
def test_a_merge_in_the_worker_process_is_the_merge_in_the_node(ros_context, method) -> None:
    # Two office robots' maps in frames anywhere: merged in the worker process (the default)
    # and in the node's own thread, by either method, the placements are the same and where
    # the truth has them (every place matched in one update and FFS run to its end: a time
    # budget would make the two differ).
    from test_link_graph import in_own_frames, poses_in_own_frames, random_frames, world_runs

    runs = world_runs("office", 2)
    frames = random_frames(2, seed=5)
    names = ["alpha", "bravo"]
    maps = in_own_frames(tuple(m for m, _ in runs), frames, names)
    views = poses_in_own_frames(tuple(p for _, p in runs), frames, names)
    placements = []
    for worker in (True, False):
        node = MapMerger(
            context=ros_context,
            node_name=f"merger_{worker}",
            parameter_overrides=[
                Parameter("robots", value="alpha,bravo"),
                Parameter("merge_worker", value=worker),
                Parameter("merge.update_budget", value=0.0),
                Parameter("method", value=method),
                Parameter("merge.ffs.time_budget", value=0.0),
                Parameter("merge.join_probability", value=SIMULATED_WORLD_JOIN_PROBABILITY),
            ],
        )
        try:
            for name in names:
                node._on_partial_map(name, _partial_map_message(maps[name], views[name], name))
            assert node.merge_now() and node.merge_errors == 0
            assert node.result is not None and node.result.unmerged == []
            placements.append(node.result.placements)
        finally:
            node.destroy_node()
    assert placements[0] == placements[1]
    reference = "alpha" if placements[0]["alpha"] == (0.0, 0.0, 0.0) else "bravo"
    other = "bravo" if reference == "alpha" else "alpha"
    T_ref_other = se2.invert(frames[names.index(reference)]) @ frames[names.index(other)]
    got = placements[0][other]
    assert got is not None
    want = se2.pose_from_matrix(T_ref_other)
    assert math.hypot(got[0] - want[0], got[1] - want[1]) < 0.05
    assert abs(math.remainder(got[2] - want[2], math.tau)) < math.radians(0.5)


def test_a_merge_cut_short_by_destroy_node_ends_quietly_without_a_new_worker(ros_context) -> None:
    # Ctrl-C while a merge runs in the worker process: destroy_node stops the worker under
    # it. The merge ends there: not counted as a failed merge, no fallback merges (each would
    # start a new interpreter while Python waits for the executor's threads: `mrm run` once
    # took over 20 s to exit), no process left behind.
    from test_link_graph import in_own_frames, poses_in_own_frames, random_frames, world_runs

    runs = world_runs("office", 2)
    names = ["alpha", "bravo"]
    frames = random_frames(2, seed=5)
    maps = in_own_frames(tuple(m for m, _ in runs), frames, names)
    views = poses_in_own_frames(tuple(p for _, p in runs), frames, names)
    node = MapMerger(
        context=ros_context,
        parameter_overrides=[Parameter("robots", value="alpha,bravo")],
    )
    for name in names:
        node._on_partial_map(name, _partial_map_message(maps[name], views[name], name))
    outcome: list[bool] = []
    merging = threading.Thread(target=lambda: outcome.append(node.merge_now()))
    merging.start()
    time.sleep(0.3)  # the worker is still starting (a new interpreter) or merging
    node.destroy_node()
    merging.join(30.0)
    assert not merging.is_alive() and outcome == [False]
    assert node.merge_errors == 0 and node.result is None
    assert node._worker._process is None
