"""``mrm demo`` end to end, on a shorter scenario: robot_mapper processes and a map_merger,
live over real topics; every robot merged, the files written, the table printed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from multi_robot_mapper.cli.demo import DemoScenario, run_demo
from multi_robot_mapper.io.results import read_results
from multi_robot_mapper.io.saved_map import read_saved_map

pytestmark = pytest.mark.ros


def test_the_demo_merges_every_robot_live_and_writes_its_files(tmp_path: Path) -> None:
    scenario = DemoScenario(duration=12.0, stagger=4.0)
    result = run_demo(tmp_path, scenario)
    assert result.merged == ["robot1", "robot2", "robot3"], result.table
    assert result.live.settled
    assert "robots merged      3 / 3" in result.table
    assert result.metrics.ate_rmse_m < 0.10
    for name in ("bag", "result", "global map", "snapshots", "animation", "occupancy grid"):
        assert result.files[name].exists(), name
    assert (tmp_path / "bag" / "metadata.yaml").exists()
    back = read_results(tmp_path / "result")
    assert all(back.robot_frames[r] is not None for r in back.robots)
    metrics = json.loads((tmp_path / "result" / "metrics.json").read_text())
    assert metrics["robots_merged"] == 3
    saved = read_saved_map(tmp_path / "saved_map.json")
    assert sorted(saved.robots) == ["robot1", "robot2", "robot3"]
    # What the robots' mappers said on /diagnostics: every scan they got was counted.
    assert sum(result.live.scans_received.values()) > 0.3 * sum(result.live.play.published.values())
    assert any("map_merger/robot3" in line for line in result.statuses)
