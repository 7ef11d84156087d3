"""partial_map in small messages between real nodes (issue 50): a robot_mapper publishes a
snapshot, then only what changed on ``partial_map_updates``; a map_merger started late gets the
latched snapshot, finds the updates it missed, asks for a snapshot (``partial_map_request``)
and then follows the updates, holding exactly the map the robot sent."""

from __future__ import annotations

from functools import cache

import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

from multi_robot_mapper.core.simulation import LaserModel, SimulatedRobot, simulate_robots
from multi_robot_mapper.io.messages import scan_to_msg, stamp_from_seconds
from multi_robot_mapper.ros.map_merger import MapMerger
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.robot_mapper import RobotMapper
from multi_robot_mapper.ros.testing import spin_until

EVERY = 4  # every 4th scan of the 40 Hz simulated drive: 10 Hz


@cache
def drive() -> SimulatedRobot:
    """Six seconds of one robot in the office world (seeded, the same every time)."""
    return simulate_robots("office", 1, LaserModel(), seed=0, duration=6.0)[0]


def scans() -> list[LaserScan]:
    run = drive()
    return [
        scan_to_msg(run.scans[i], "robot1/laser", stamp_from_seconds(run.stamps[i]), 0.025)
        for i in range(0, len(run.scans), EVERY)
    ]


def test_a_late_merger_gets_the_whole_map_then_follows_the_updates(ros_context) -> None:
    # Snapshots only at the start and when asked: everything else goes as updates.
    mapper = RobotMapper(
        context=ros_context,
        namespace="robot1",
        config=RobotMapperConfig(snapshot_period=3600.0),
        parameter_overrides=[Parameter("partial_map_period", value=0.1)],
    )
    driver = Node("driver", context=ros_context)
    publisher = driver.create_publisher(LaserScan, "/robot1/scan", qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(mapper)
    executor.add_node(driver)
    merger: MapMerger | None = None
    msgs = scans()
    quarter = len(msgs) // 4
    parts = [msgs[k * quarter : (k + 1) * quarter] for k in range(3)] + [msgs[3 * quarter :]]

    def send(part: list[LaserScan]) -> None:
        for msg in part:
            before = mapper.scans_received
            publisher.publish(msg)
            assert spin_until(executor, lambda b=before: mapper.scans_received > b, timeout=5.0)

    try:
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, timeout=10.0)
        send(parts[0])
        assert spin_until(executor, lambda: mapper.partial_maps_published > 0, timeout=30.0)
        send(parts[1])  # what changed now goes out as updates
        assert spin_until(
            executor, lambda: mapper.map_published and mapper.updates_published > 0, timeout=30.0
        )
        assert mapper.partial_maps_published == 1  # one snapshot, the rest updates

        # A merger started now: the latched snapshot is older than the updates that went by.
        merger = MapMerger(
            context=ros_context,
            parameter_overrides=[
                Parameter("robots", value="robot1"),
                Parameter("merge_period", value=3600.0),
            ],
        )
        executor.add_node(merger)
        state = merger.robots["robot1"]
        send(parts[2])
        assert spin_until(executor, lambda: state.stream.snapshots >= 2, timeout=30.0)
        assert mapper.snapshot_requests >= 1 and mapper.partial_maps_published >= 2
        assert merger.rejections.of("robot1").get("update_gap", 0) >= 1  # named, counted

        updates_before = state.stream.updates
        send(parts[3])
        assert spin_until(
            executor,
            lambda: mapper.map_published and state.stream.seq == mapper.planner.seq,
            timeout=30.0,
        )
        assert state.stream.updates > updates_before  # following the updates again
        assert state.stream.epoch == mapper.planner.epoch
        # The merger holds exactly what the robot sent: every keyframe, at the pose sent.
        sent = mapper.planner.sent
        assert sorted(kf.index for kf in state.all_keyframes) == sorted(sent)
        for kf in state.all_keyframes:
            np.testing.assert_allclose(
                kf.T_robotmap_keyframe, sent[kf.index].T_robotmap_keyframe, atol=1e-9
            )
            np.testing.assert_allclose(kf.segments, sent[kf.index].segments, atol=1e-9)
        # ... which is the robot's map to within the tolerances.
        assert len(sent) == len(mapper.mapper.keyframes()) == state.keyframes
    finally:
        executor.shutdown()
        if merger is not None:
            merger.destroy_node()
        mapper.destroy_node()
        driver.destroy_node()
