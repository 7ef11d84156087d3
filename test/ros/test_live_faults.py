"""Never lose the map: the merger's faults with real nodes, in-process (its save and load
services: test_saved_map_services.py).

Robots here are small nodes that publish a partial map exactly as robot_mapper does
(``partial_map`` reliable + transient local, depth 1; ``pose``), built from simulated office
runs placed in random frames, so every right placement is known. Each test spins the real
``map_merger`` on real topics and services.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger
from test_link_graph import in_own_frames, poses_in_own_frames, random_frames, world_runs

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.simulation import SIM_START_S
from multi_robot_mapper.io.messages import (
    partial_map_markers,
    pose_from_msg,
    pose_stamped,
    seconds_from_stamp,
    stamp_from_seconds,
)
from multi_robot_mapper.ros.diagnostics import OK, STALE, WARN
from multi_robot_mapper.ros.live import Observer
from multi_robot_mapper.ros.map_merger import MapMerger
from multi_robot_mapper.ros.markers import grid_from_msg
from multi_robot_mapper.ros.robot_mapper import PARTIAL_MAP_QOS, POSE_QOS
from multi_robot_mapper.ros.testing import spin_until

pytestmark = pytest.mark.ros

NAMES = ["alpha", "bravo"]
FRAMES = random_frames(2, seed=11)  # T_world_robotmap of each robot


def office_maps() -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Two overlapping office maps and their viewpoints, each in its robot's frame."""
    runs = world_runs("office", 2)
    maps = in_own_frames(tuple(m for m, _ in runs), FRAMES, NAMES)
    views = poses_in_own_frames(tuple(p for _, p in runs), FRAMES, NAMES)
    return maps, views


def partial_map(segments: np.ndarray, views: np.ndarray, frame: str, start: float, stamp: float):
    """A partial map as robot_mapper sends it: keyframe k at views[k] stamped start + k (the
    session is keyframe 0's stamp); keyframe 0 owns every segment (in its own frame)."""
    T_map_first = se2.matrix_from_pose(*views[0])
    own = se2.transform_segments(se2.invert(T_map_first), segments)
    keyframes = [
        Keyframe(k, start + k, np.asarray(v, dtype=np.float64), own if k == 0 else np.zeros((0, 4)))
        for k, v in enumerate(views)
    ]
    return partial_map_markers(keyframes, stamp_from_seconds(stamp), frame, 0.03)


class FakeRobot:
    """A node in ``/<name>`` that publishes one partial map (latched) and poses."""

    def __init__(self, context, name: str, segments, views, start: float, frame: str = "") -> None:
        self.node = Node("robot_mapper", namespace=f"/{name}", context=context)
        self.frame = frame or f"{name}/map"
        self.map_pub = self.node.create_publisher(
            type(partial_map(segments, views, self.frame, start, start)),
            "partial_map",
            PARTIAL_MAP_QOS,
        )
        self.pose_pub = self.node.create_publisher(PoseStamped, "pose", POSE_QOS)
        self.stamp = start + len(views)
        self.map_pub.publish(partial_map(segments, views, self.frame, start, self.stamp))

    def pose(self, pose: tuple[float, float, float], stamp: float) -> None:
        self.pose_pub.publish(pose_stamped(pose, stamp_from_seconds(stamp), self.frame))

    def destroy(self) -> None:
        self.node.destroy_node()


class Rig:
    """An executor with a merger, fake robots and an observer."""

    def __init__(self, context) -> None:
        self.context = context
        self.executor = SingleThreadedExecutor(context=context)
        self.observer = Observer(NAMES, context=context)
        self.executor.add_node(self.observer)
        self.client_node = Node("client", context=context)
        self.executor.add_node(self.client_node)
        self.robots: dict[str, FakeRobot] = {}
        self.merger: MapMerger | None = None

    def start_merger(self, **parameters: object) -> MapMerger:
        values = {"robots": ",".join(NAMES), "merge_worker": False, "merge_period": 0.2}
        values.update(parameters)
        self.merger = MapMerger(
            context=self.context,
            parameter_overrides=[Parameter(k, value=v) for k, v in values.items()],
        )
        self.executor.add_node(self.merger)
        return self.merger

    def stop_merger(self) -> None:
        assert self.merger is not None
        self.executor.remove_node(self.merger)
        self.merger.destroy_node()
        self.merger = None

    def add_robot(self, name: str, segments, views, start: float = SIM_START_S) -> FakeRobot:
        robot = FakeRobot(self.context, name, segments, views, start)
        self.executor.add_node(robot.node)
        self.robots[name] = robot
        return robot

    def remove_robot(self, name: str) -> None:
        robot = self.robots.pop(name)
        self.executor.remove_node(robot.node)
        robot.destroy()

    def spin_until(self, condition: Callable[[], bool], timeout: float = 30.0) -> bool:
        return spin_until(self.executor, condition, timeout)

    def merged(self, *robots: str) -> bool:
        merger = self.merger
        return (
            merger is not None
            and merger.result is not None
            and merger.up_to_date()
            and all(merger.result.placements.get(r) is not None for r in robots)
        )

    def call(self, service: str) -> Trigger.Response:
        client = self.client_node.create_client(Trigger, service)
        assert self.spin_until(client.service_is_ready, 10.0)
        future = client.call_async(Trigger.Request())
        assert self.spin_until(future.done, 10.0)
        self.client_node.destroy_client(client)
        return future.result()

    def close(self) -> None:
        for name in list(self.robots):
            self.remove_robot(name)
        if self.merger is not None:
            self.stop_merger()
        self.executor.shutdown()
        self.observer.destroy_node()
        self.client_node.destroy_node()


@pytest.fixture
def rig(ros_context) -> Iterator[Rig]:
    r = Rig(ros_context)
    yield r
    r.close()


def truth_in_reference(reference: str, robot: str) -> np.ndarray:
    frames = dict(zip(NAMES, FRAMES, strict=True))
    return se2.invert(frames[reference]) @ frames[robot]


def assert_right_placements(merger: MapMerger, robots: list[str], tolerance: float = 0.05) -> None:
    result = merger.result
    assert result is not None and result.reference is not None
    reference = result.reference.split("_session")[0]
    for robot in robots:
        got = result.placements[robot]
        assert got is not None, robot
        want = se2.pose_from_matrix(truth_in_reference(reference, robot.split("_session")[0]))
        assert math.hypot(got[0] - want[0], got[1] - want[1]) < tolerance, (robot, got, want)
        assert abs(math.remainder(got[2] - want[2], math.tau)) < math.radians(1.0), robot


def test_a_restarted_merger_rebuilds_the_map_from_the_latched_partial_maps(rig: Rig) -> None:
    maps, views = office_maps()
    for name in NAMES:
        rig.add_robot(name, maps[name], views[name])
    merger = rig.start_merger(robots="", discovery_period=0.2)  # found by discovery
    assert rig.spin_until(lambda: rig.merged(*NAMES))
    before = dict(merger.result.placements)
    rig.stop_merger()
    # No robot publishes again: the new merger gets the maps from the publishers' history.
    merger = rig.start_merger(robots="", discovery_period=0.2)
    assert rig.spin_until(lambda: rig.merged(*NAMES))
    assert all(merger.robots[n].version == 1 for n in NAMES)
    # The same map, up to which robot's frame is ``map`` (the first map discovery delivers
    # can be either robot's): every robot placed the same relative to the others.
    after = merger.result.placements

    def relative(placements, name):  # type: ignore[no-untyped-def]
        T_map_first = se2.matrix_from_pose(*placements[NAMES[0]])
        return se2.invert(T_map_first) @ se2.matrix_from_pose(*placements[name])

    for name in NAMES[1:]:
        assert np.allclose(relative(after, name), relative(before, name), atol=1e-6)
    assert_right_placements(merger, NAMES)
    # The occupancy grid and the robots' poses in map come with it, stamped from the input.
    assert rig.spin_until(lambda: rig.observer.grid is not None)
    grid = grid_from_msg(rig.observer.grid)
    assert rig.observer.grid.header.frame_id == "map"
    assert seconds_from_stamp(rig.observer.grid.header.stamp) == SIM_START_S + len(views["alpha"])
    assert np.count_nonzero(grid.cells == 100) > 100 and np.count_nonzero(grid.cells == 0) > 1000
    robot = rig.robots["bravo"]
    laser = (1.0, 0.5, 0.2)  # in bravo's map frame
    received: list[PoseStamped] = []
    rig.client_node.create_subscription(PoseStamped, "/robot_poses/bravo", received.append, 10)
    assert rig.spin_until(lambda: rig.client_node.count_publishers("/robot_poses/bravo") > 0)
    rig.spin_until(lambda: False, 0.3)
    robot.pose(laser, SIM_START_S + 500.25)
    assert rig.spin_until(lambda: bool(received), 5.0)
    assert seconds_from_stamp(received[-1].header.stamp) == SIM_START_S + 500.25
    T_map_bravo = se2.matrix_from_pose(*merger.result.placements["bravo"])
    want = se2.pose_from_matrix(T_map_bravo @ se2.matrix_from_pose(*laser))
    assert np.allclose(pose_from_msg(received[-1].pose), want, atol=1e-6)


def test_a_restarted_robot_starts_a_new_session_that_is_merged_again(rig: Rig) -> None:
    maps, views = office_maps()
    merger = rig.start_merger()
    for name in NAMES:
        rig.add_robot(name, maps[name], views[name])
    assert rig.spin_until(lambda: rig.merged(*NAMES))
    alpha_before = merger.result.placements["alpha"]
    # bravo's node restarts: a new map frame (its laser elsewhere at its new first scan) and
    # a new first keyframe. Its old map stays, as bravo_session1, in the same place.
    T_old_new = se2.matrix_from_pose(2.0, -1.0, 0.7)
    new_segments = se2.transform_segments(se2.invert(T_old_new), maps["bravo"])
    new_views = poses_in_own_frames((views["bravo"],), [T_old_new], ["bravo"])["bravo"]
    rig.remove_robot("bravo")
    rig.add_robot("bravo", new_segments, new_views, start=SIM_START_S + 1000.0)
    assert rig.spin_until(lambda: rig.merged("alpha", "bravo", "bravo_session1"))
    result = merger.result
    assert sorted(result.robots) == ["alpha", "bravo", "bravo_session1"]
    # The map frame did not move (when bravo was the reference, its old session is now).
    assert np.allclose(result.placements["alpha"], alpha_before, atol=0.01)  # matched again
    assert merger.robots["bravo_session1"].session == SIM_START_S
    assert merger.robots["bravo"].session == SIM_START_S + 1000.0
    # The new session is where the truth puts it: the old frame moved by T_old_new.
    T_map_old = se2.matrix_from_pose(*result.placements["bravo_session1"])
    want = se2.pose_from_matrix(T_map_old @ T_old_new)
    got = result.placements["bravo"]
    assert math.hypot(got[0] - want[0], got[1] - want[1]) < 0.05
    assert abs(math.remainder(got[2] - want[2], math.tau)) < math.radians(1.0)
    assert_right_placements(merger, ["alpha", "bravo_session1"])


def _key(stamp) -> tuple[int, int]:
    return (stamp.sec, stamp.nanosec)


def status_of(rig: Rig, robot: str):
    return rig.observer.diagnostics.get(f"map_merger/{robot}")


def test_a_silent_robot_turns_stale_and_its_map_stays(rig: Rig) -> None:
    maps, views = office_maps()
    merger = rig.start_merger(stale_timeout=1.0, diagnostics_period=0.2)
    for name in NAMES:
        rig.add_robot(name, maps[name], views[name])
    assert rig.spin_until(lambda: rig.merged(*NAMES))
    stamp = SIM_START_S + 100.0
    sent = [0.0]

    def sending(robots: tuple[str, ...], condition: Callable[[], bool]) -> Callable[[], bool]:
        def step() -> bool:
            nonlocal stamp
            if time.monotonic() - sent[0] > 0.05:  # stamps 0.1 s apart: 10 Hz for the merger
                stamp += 0.1
                sent[0] = time.monotonic()
                for robot in robots:
                    rig.robots[robot].pose((0.0, 0.0, 0.0), stamp)
            return condition()

        return step

    def level(robot: str) -> bytes | None:
        return getattr(status_of(rig, robot), "level", None)

    def hearing(robot: str) -> bool:
        """The robot's last status was made while its poses were arriving (not one made
        before: merging may take longer than stale_timeout after the maps arrived)."""
        status = status_of(rig, robot)
        values = {kv.key: kv.value for kv in getattr(status, "values", [])}
        silent = values.get("seconds since last input", "-")
        return silent != "-" and float(silent) < 0.5

    # Both robots send poses until both are heard and bravo is OK; then bravo falls silent.
    assert rig.spin_until(
        sending(
            ("alpha", "bravo"),
            lambda: hearing("alpha") and hearing("bravo") and level("bravo") == OK,
        ),
        20.0,
    )
    assert rig.spin_until(sending(("alpha",), lambda: level("bravo") == STALE), 20.0)
    silent = {kv.key: kv.value for kv in status_of(rig, "bravo").values}
    # not before stale_timeout (the value is shown to 0.01 s: 1.004 s reads "1.00")
    assert float(silent["seconds since last input"]) >= 1.0
    assert status_of(rig, "alpha").level == OK, status_of(rig, "alpha").message
    assert "its map stays" in status_of(rig, "bravo").message
    # bravo is still placed and drawn.
    assert merger.result.placements["bravo"] is not None
    assert rig.spin_until(lambda: "bravo" in rig.observer.global_maps[-1].segments, 5.0)
    assert len(rig.observer.global_maps[-1].segments["bravo"]) > 20
    values = {kv.key: kv.value for kv in status_of(rig, "alpha").values}
    # From the stamps (0.1 s apart), never faster than they say; a pose lost on a busy machine
    # only lowers it.
    assert 5.0 < float(values["pose rate (Hz)"]) <= 10.0 * 1.001
    assert (
        float(values["merge score: link value (m)"]) > 15.0
        or values["merge score: link value (m)"] == "-"
    )  # alpha may be the reference


def test_an_unmerged_robot_is_warn_with_its_best_pair_value(rig: Rig) -> None:
    maps, views = office_maps()
    rig.start_merger(diagnostics_period=0.2)
    rig.add_robot("alpha", maps["alpha"], views["alpha"])
    far = maps["bravo"][:4]  # four segments: no link can be valid
    rig.add_robot("bravo", far, views["bravo"][:2])
    assert rig.spin_until(lambda: rig.merger.result is not None and rig.merger.up_to_date())
    stamp = [SIM_START_S + 5]

    def levels() -> set[bytes]:
        stamp[0] += 0.1
        for name in NAMES:
            rig.robots[name].pose((0.0, 0.0, 0.0), stamp[0])
        return {getattr(status_of(rig, r), "level", None) for r in NAMES}

    assert rig.spin_until(lambda: levels() == {OK, WARN}, 20.0), levels()
    assert "unmerged" in (status_of(rig, "alpha").message + status_of(rig, "bravo").message)


def test_with_sim_time_outputs_carry_input_stamps_and_staleness_follows_the_clock(
    rig: Rig,
) -> None:
    maps, views = office_maps()
    clock_pub = rig.client_node.create_publisher(Clock, "/clock", 10)
    sim = [SIM_START_S + 100.0]  # after the maps' stamps (start + one per keyframe)
    sent: set[tuple[int, int]] = set()

    def tick(step: float = 0.05) -> None:
        sim[0] += step
        clock_pub.publish(Clock(clock=stamp_from_seconds(sim[0])))

    merger = rig.start_merger(
        use_sim_time=True, stale_timeout=30.0, diagnostics_period=0.5, merge_period=0.5
    )
    for name in NAMES:
        rig.add_robot(name, maps[name], views[name])
    # Timers run on the sim clock: nothing merges while it stands still.
    rig.spin_until(lambda: False, 1.0)
    assert merger.merges == 0

    def ticking(condition: Callable[[], bool]) -> Callable[[], bool]:
        def step() -> bool:
            tick()
            stamp = sim[0] - 0.013  # a scan's pose arrives a little after the scan
            sent.add(_key(stamp_from_seconds(stamp)))
            for name in NAMES:
                rig.robots[name].pose((0.0, 0.0, 0.0), stamp)
            return condition()

        return step

    assert rig.spin_until(ticking(lambda: rig.merged(*NAMES)), 40.0)
    assert rig.spin_until(ticking(lambda: status_of(rig, "alpha") is not None), 10.0)
    assert status_of(rig, "alpha").level == OK, status_of(rig, "alpha").message
    # Outputs are stamped from their inputs (the maps' and poses' stamps), never the clock.
    view = rig.observer.global_maps[-1]
    assert _key(view.stamp) in sent  # the newest pose it shows
    map_stamp = _key(stamp_from_seconds(SIM_START_S + len(views["alpha"])))
    assert _key(rig.observer.grid.header.stamp) == map_stamp
    assert rig.observer.diagnostic_stamps and all(
        _key(s) in sent | {map_stamp} for s in rig.observer.diagnostic_stamps
    )
    # Sim time jumps 40 s (past stale_timeout, 30 s) while far less wall time passes than
    # that: both robots go STALE at once (on the wall clock it would take 30 s).
    last = max(sent)

    def poses_in() -> bool:  # every pose sent has reached the merger (a busy machine queues)
        return all(_key(merger.robots[r].pose_stamp) == last for r in NAMES)

    assert rig.spin_until(poses_in, 20.0)
    tick(40.0)
    assert rig.spin_until(
        lambda: all(status_of(rig, r).level == STALE for r in NAMES) or (tick(0.01) and False),
        20.0,
    )
