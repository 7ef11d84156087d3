"""``mrm demo``: simulated Hokuyo scans through a real ``robot_mapper`` node, and a picture.

The scan source is the project's own simulator (a built-in office world); the node runs
in-process and its ``scan_segments`` output is drawn at the simulator's true laser poses, so the
picture shows what the front end extracts along a whole run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_segments
from multi_robot_mapper.core.geometry import split_stamp
from multi_robot_mapper.core.scan import scan_points
from multi_robot_mapper.core.simulation import (
    ROUTES,
    WORLDS,
    LaserModel,
    _arc_length,
    drive_path,
    simulate_scan,
)
from multi_robot_mapper.io import pictures
from multi_robot_mapper.io.messages import scan_to_msg, segments_from_marker, stamp_from_seconds
from multi_robot_mapper.ros.robot_mapper import RobotMapper
from multi_robot_mapper.ros.testing import isolated_context, spin_until

PICTURE = "demo_segments.png"


@dataclass
class DemoResult:
    scans_sent: int
    scans_answered: int
    segments_per_scan: list[int]
    latency_s: list[float]
    picture: Path


def run_demo(out_dir: Path, world: str = "office", seed: int = 0, every: int = 4) -> DemoResult:
    """Simulate one robot, run its scans through a robot_mapper node, draw what comes back."""
    walls = WORLDS[world]()
    laser = LaserModel()
    rng = np.random.default_rng(seed)
    route = np.asarray(ROUTES[world], dtype=np.float64)
    speed = 1.0  # m/s, once along the route
    duration = float(_arc_length(route)[-1]) / speed
    poses = drive_path(route, speed, laser.rate, duration)[::every]
    received: dict[tuple[int, int], np.ndarray] = {}
    latency: list[float] = []
    sent_at: dict[tuple[int, int], float] = {}

    with isolated_context() as context:
        node = RobotMapper(context=context, namespace="robot1")
        client = Node("demo_driver", context=context, namespace="robot1")
        scan_pub = client.create_publisher(LaserScan, "scan", qos_profile_sensor_data)

        def on_segments(msg: Marker) -> None:
            key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
            received[key] = segments_from_marker(msg)
            if key in sent_at:
                latency.append(time.monotonic() - sent_at[key])

        client.create_subscription(Marker, "scan_segments", on_segments, QoSProfile(depth=50))
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        executor.add_node(client)
        spin_until(executor, lambda: scan_pub.get_subscription_count() > 0, timeout=10.0)

        keys: list[tuple[int, int]] = []
        scans = []
        for i, pose in enumerate(poses):
            scan = simulate_scan(walls, tuple(pose), laser, rng)
            seconds = 100.0 + i * every / laser.rate
            key = split_stamp(seconds)
            stamp = stamp_from_seconds(seconds)
            keys.append(key)
            scans.append(scan)
            sent_at[key] = time.monotonic()
            scan_pub.publish(scan_to_msg(scan, "robot1/laser", stamp, 1.0 / laser.rate))
            spin_until(executor, lambda k=key: k in received, timeout=2.0)
        executor.shutdown()
        node.destroy_node()
        client.destroy_node()

    fig, (ax_map, ax_scan) = pictures.plt.subplots(1, 2, figsize=(15, 6.5), width_ratios=[1.6, 1.0])
    pictures.draw_segments(ax_map, walls, "0.75", width=4.0, label="simulated walls")
    placed = []
    for key, pose in zip(keys, poses, strict=True):
        if key in received and len(received[key]):
            T_world_laser = se2.matrix_from_pose(*pose)
            placed.append(se2.transform_segments(T_world_laser, received[key]))
    if placed:
        pictures.draw_segments(
            ax_map, np.vstack(placed), pictures.PALETTE[0], width=0.6, label="robot_mapper segments"
        )
    ax_map.plot(
        poses[:, 0], poses[:, 1], color=pictures.PALETTE[1], linewidth=1.0, label="robot path"
    )
    ax_map.legend(loc="upper left", fontsize=8)
    pictures.finish_metric_axes(
        ax_map,
        f"{len(placed)} scans' segments from robot_mapper, drawn at the simulator's true poses",
        pictures.segments_extent([walls]),
    )
    # One scan in the laser frame: raw points and the segments fitted to them.
    pick = len(scans) // 3
    valid = scan_points(scans[pick])
    local = extract_segments(valid.points, node.config.extraction)
    ax_scan.plot(
        valid.points[:, 0], valid.points[:, 1], ".", color="0.5", markersize=2, label="scan points"
    )
    pictures.draw_segments(
        ax_scan, local.segments, pictures.PALETTE[0], width=2.0, label="segments"
    )
    ends = local.segments.reshape(-1, 2)
    ax_scan.plot(ends[:, 0], ends[:, 1], "o", color=pictures.PALETTE[0], markersize=3)
    ax_scan.plot(
        [0], [0], marker=(3, 0, -90), color=pictures.PALETTE[1], markersize=12, label="laser"
    )
    ax_scan.legend(loc="upper left", fontsize=8)
    pictures.finish_metric_axes(
        ax_scan,
        f"scan {pick} in the laser frame: {len(local)} segments",
        pictures.segments_extent([local.segments]),
    )
    picture = pictures.save_figure(fig, out_dir / PICTURE)
    counts = [len(received[k]) for k in keys if k in received]
    return DemoResult(len(keys), len(counts), counts, latency, picture)
