"""A scan that contradicts its own stream never moves the map (issue 46, item 5).

The stream guard (core/scan_stream.py) rule by rule: test/core/test_scan_stream.py. Here the
local mapper's front end: a scan of junk or of another place is held and set aside, never
placed where the robot cannot have driven. Then the whole path: replay (run_offline) and a
robot_mapper node, each counting every hostile scan, and a drive with hostile scans
interleaved whose final pose stays where the clean drive's is."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hostile_streams import JUNK_KINDS, REAL_KINDS, hostile_stream, office_drive
from local_mapping_drives import feed, stranger_scan
from rclpy.parameter import Parameter
from test_robot_mapper import DRIVE_EVERY, Harness, assert_pose_close, drive
from test_robot_mapper import truth_in_robot_map as truth_at
from test_scan_stream import PERIOD, laser_scans

from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.core.local_mapping.held import OUTLIER
from multi_robot_mapper.core.pipeline import TimedLaserScan, run_offline
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.core.worlds import WORLDS
from multi_robot_mapper.io.messages import (
    pose_from_msg,
    scan_to_msg,
    seconds_from_stamp,
    stamp_from_seconds,
)
from multi_robot_mapper.ros.testing import spin_until

# --- the local mapper's front end ------------------------------------------------------------


def test_junk_and_scans_of_other_places_are_set_aside_and_the_map_kept(office_drive) -> None:  # type: ignore[no-untyped-def]
    # Between good scans: a scan of another building, random ranges, and a scan of the office
    # from 6 m further along the corridor, which the search places right, 6 m away, at 0.99:
    # but no robot drives 6 m in 12.5 ms. Each is held, then set aside when the next scan is
    # placed from the map: the map is the clean drive's.
    stamps, scans, truth = office_drive
    clean, attacked = LocalMapper(), LocalMapper()
    rng = np.random.default_rng(3)
    x, y, theta = truth[60]
    junk = {
        40: stranger_scan(),
        50: dataclasses.replace(scans[50], ranges=rng.uniform(0.1, 30.0, 1081)),
        60: simulate_scan(WORLDS["office"](), (x + 6.0, y, theta), LaserModel(), rng),
    }
    for k in range(80):
        feed(clean, float(stamps[k]), scans[k])
        feed(attacked, float(stamps[k]), scans[k])
        if k in junk:
            update = feed(attacked, float(stamps[k]) + 0.0125, junk[k])
            assert not update.accepted and attacked.scans_held == 1
            if k == 60:
                here = np.asarray(attacked.pose)
                assert any(
                    a.confidence > 0.99
                    and abs(np.hypot(*(np.asarray(a.pose) - here)[:2]) - 6) < 0.1
                    for a in attacked.last_attempts
                )
    assert attacked.set_aside_reasons == {OUTLIER: 3} and attacked.pieces_started == 0
    assert attacked.scans_accepted == clean.scans_accepted == 80
    np.testing.assert_array_equal(attacked.trajectory()[1], clean.trajectory()[1])


# --- the whole path: replay and the node -----------------------------------------------------


def test_replay_refuses_each_hostile_kind_and_counts_it() -> None:
    good = laser_scans(30)
    turned = dataclasses.replace(good[0], angle_min=0.2 + good[0].angle_min)
    turned = dataclasses.replace(turned, angle_max=turned.angle_min + 360 * turned.angle_increment)
    items = [TimedLaserScan(10.0 + k * PERIOD, scan) for k, scan in enumerate(good[:20])]
    hostile = [
        TimedLaserScan(11.95, turned),  # angle fields
        TimedLaserScan(11.96, good[3]),  # ranges copied
        TimedLaserScan(11.9, good[20]),  # the last stamp again
        TimedLaserScan(11.5, good[21]),  # a step back
        TimedLaserScan(2.0, good[22]),  # far back
        TimedLaserScan(5000.0, good[23]),  # far ahead
    ]
    later = [TimedLaserScan(12.0 + k * PERIOD, scan) for k, scan in enumerate(good[24:])]
    out = run_offline({"robot1": items + hostile + later}, "local", ExtractionConfig())
    assert out.stats["scans_rejected"] == {
        "angle_fields": 1,
        "copied_ranges": 1,
        "duplicate_stamp": 1,
        "stale_stamp": 1,
        "stamp_jump_back": 1,
        "stamp_jump_ahead": 1,
    }
    assert out.stats["map_resets"] == 0
    assert out.stats["robots"]["robot1"]["scans_accepted"] == 26  # every good scan


def test_replay_of_a_bag_played_twice_starts_the_map_over_as_the_node_does() -> None:
    # The same 10 scans (one a second) twice: the second play jumps back 9 s and stays there,
    # its scans exact copies of the first play's. The map starts over, nothing is refused.
    played = [TimedLaserScan(10.0 + k, scan) for k, scan in enumerate(laser_scans(10))]
    out = run_offline({"robot1": played + played}, "local", ExtractionConfig())
    assert out.stats["map_resets"] == 1 and out.stats["scans_rejected"] == {}
    assert out.stats["robots"]["robot1"]["scans_accepted"] == 10  # the second play's map
    assert "jumped back 9 s" in out.stats["stream_notices"][0]


@pytest.mark.ros
def test_a_robot_mapper_node_counts_every_hostile_scan_and_its_poses_stay_right(
    ros_context,  # type: ignore[no-untyped-def]
) -> None:
    # The noise-free room of the other node tests would repeat its ranges: a drive instead,
    # with the copy rule on (the shipped copy_window).
    h = Harness(ros_context, parameter_overrides=[Parameter("copy_window", value=200)])
    try:
        run = drive()
        sent = list(range(0, len(run.scans), DRIVE_EVERY))
        hostile_after = {sent[3]: "angle_fields", sent[5]: "copied_ranges", sent[7]: "duplicate"}
        hostile_after |= {sent[9]: "stale", sent[11]: "far_back", sent[13]: "far_ahead"}
        hostile_after |= {sent[15]: "stranger"}
        for i in sent:
            t = float(run.stamps[i])
            h.send(scan_to_msg(run.scans[i], "robot1/laser", stamp_from_seconds(t), 0.025))
            kind = hostile_after.get(i)
            if kind is None:
                continue
            scan, stamp = run.scans[i + 1], t + 0.05
            if kind == "angle_fields":
                scan = dataclasses.replace(scan, angle_min=scan.angle_min + 0.2)
                scan = dataclasses.replace(scan, angle_max=scan.angle_max + 0.2)
            elif kind == "copied_ranges":
                scan = run.scans[sent[2]]
            elif kind == "stranger":
                scan = stranger_scan()
            else:
                stamp = {"duplicate": t, "stale": t - 0.3, "far_back": t - 60.0}.get(kind, t + 1e4)
            h.send(scan_to_msg(scan, "robot1/laser", stamp_from_seconds(stamp), 0.025))
        rejected = h.mapper.rejections.of("robot1")
        assert rejected == {
            "angle_fields": 1,
            "copied_ranges": 1,
            "duplicate_stamp": 1,
            "stale_stamp": 1,
            "stamp_jump_back": 1,
            "stamp_jump_ahead": 1,
        }
        assert h.mapper.mapper.set_aside_reasons == {OUTLIER: 1} and h.mapper.map_resets == 0
        for kind in rejected:  # named in a warning
            assert any(f"({kind})" in line for line in h.logged), kind
        assert h.mapper.mapper.scans_accepted == len(sent)
        assert spin_until(h.executor, lambda: len(h.poses) == len(sent), timeout=5.0)
        for pose in h.poses:  # every good scan's, where the drive was
            want = truth_at(run, seconds_from_stamp(pose.header.stamp))
            assert_pose_close(pose_from_msg(pose.pose), want, metres=0.05, radians=0.02)
    finally:
        h.close()


def test_hostile_scans_interleaved_into_a_drive_leave_its_final_pose_where_it_was() -> None:
    # A 120-scan drive of the office at 10 Hz with 60 hostile scans of every kind interleaved
    # (bench/hostile_scans.py runs 300 + 200 on several seeds): through replay, the final pose
    # is the clean run's within 5 cm / 1 deg, no exception, every hostile scan counted.
    run = office_drive(120, seed=1)
    stream = hostile_stream(run, 60, seed=1)
    assert set(stream.kinds) - {""} == set(REAL_KINDS + JUNK_KINDS)
    extraction = ExtractionConfig()
    clean = run_offline({"robot1": stream.good()}, "local", extraction)
    attacked = run_offline({"robot1": stream.scans}, "local", extraction)
    (_, clean_poses), (stamps, poses) = (
        clean.trajectories["robot1"],
        attacked.trajectories["robot1"],
    )
    np.testing.assert_array_equal(stamps, run.stamps)  # every good scan, no hostile one
    moved = np.hypot(*(poses[-1, :2] - clean_poses[-1, :2]))
    turned = abs(math.remainder(poses[-1, 2] - clean_poses[-1, 2], math.tau))
    assert moved < 0.05 and turned < math.radians(1.0)
    robot = attacked.stats["robots"]["robot1"]
    assert attacked.stats["mapping_errors"] == 0
    counted = sum(attacked.stats["scans_rejected"].values()) + robot["scans_set_aside"]
    assert counted + robot["scans_held"] == 60
