"""``mrm demo`` end to end, the scenario ``make demo`` plays: robot_mapper processes and a
map_merger, live over real topics; every robot placed is placed right, the files written, the
table printed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_replay import frame_segments, read_mcap

from multi_robot_mapper.cli.demo import DemoScenario, run_demo
from multi_robot_mapper.io.results import read_results
from multi_robot_mapper.io.saved_map import read_saved_map

pytestmark = pytest.mark.ros


def test_the_demo_places_robots_right_live_and_writes_its_files(tmp_path: Path) -> None:
    # The whole scenario: with 12 s per robot the last robot's map held too few places for
    # the joint graph's two agreeing links in about half the runs.
    scenario = DemoScenario()
    result = run_demo(tmp_path, scenario)
    # The merger places a robot only where the join model is sure (P >= 0.99): in the
    # simulated office, whose rooms repeat, the robots' few shared metres give P 0.95-0.998
    # (test_link_graph.SIMULATED_WORLD_JOIN_PROBABILITY), so a robot may stay unmerged, with its
    # reason. Whatever is placed is placed right, live and at the end.
    assert result.merged and set(result.merged) <= set(result.metrics.merged_robots), result.table
    assert result.live.observer.merged() == result.merged
    for robot in set(result.robots) - set(result.merged):
        assert any(f"map_merger/{robot}: " in s and "unmerged" in s for s in result.statuses)
    assert result.metrics.ate_rmse_m < 0.10
    files = ("bag", "result", "global map", "snapshots", "animation", "occupancy grid", "recording")
    for name in files:
        assert result.files[name].exists(), name
    assert (tmp_path / "bag" / "metadata.yaml").exists()
    back = read_results(tmp_path / "result")
    assert [r for r in back.robots if back.robot_frames[r] is not None] == result.merged
    # It records its bag where it lies now: mrm evaluate DIR/result needs no --bag.
    assert back.replayed is not None and back.replayed.bags == ((tmp_path / "bag").resolve(),)
    metrics = json.loads((tmp_path / "result" / "metrics.json").read_text())
    assert metrics["robots_merged"] == len(result.merged)
    saved = read_saved_map(tmp_path / "saved_map.json")
    assert sorted(saved.robots) == ["robot1", "robot2", "robot3"]
    # The merger's own last word: the final merge's placements.
    placed = sorted(r for r, robot in saved.robots.items() if robot.placement is not None)
    assert placed == result.merged, saved.robots
    # What the robots' mappers said on /diagnostics: every scan they got was counted.
    assert sum(result.live.scans_received.values()) > 0.3 * sum(result.live.play.published.values())
    assert any("map_merger/robot3" in line for line in result.statuses)
    # The merger's outputs as they arrived, in an MCAP file: the last global map shows every
    # merged robot's keyframes; TF placed each robot's map frame in map when it was merged.
    messages = read_mcap(result.files["recording"])
    topics = {topic for topic, _, _ in messages}
    robots = ["robot1", "robot2", "robot3"]
    assert {"/global_map", "/global_grid", "/tf", "/diagnostics"} <= topics
    assert any(topic.startswith("/trajectories/") for topic in topics)
    maps = [m for topic, _, m in messages if topic == "/global_map"]
    assert len(maps) > 1 and sorted(frame_segments(maps[-1].markers)) == result.merged
    children = {
        t.child_frame_id for topic, _, m in messages if topic == "/tf" for t in m.transforms
    }
    assert {f"{r}/map" for r in result.merged} | {f"{r}/laser" for r in robots} <= children
