"""End to end through the real ``mrm`` command: bag in, replay, evaluate; bad bags refused.

The reference round trip proves the evaluator and the plumbing, not a mapping method: scans
placed at their own reference poses must score ATE ~ 0, every robot merged, full coverage.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from conftest import carmen_log
from test_bags import raw_bag
from test_link_graph import SIMULATED_WORLD_JOIN_PROBABILITY

from multi_robot_mapper.cli.main import main


def mrm(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def assert_reference_round_trip(capsys, bag: Path, out: Path, robots: int) -> dict:
    code, _, err = mrm(capsys, "replay", bag, "--out", out, "--method", "reference")
    assert code == 0, err
    for name in ("map.json", "map.png", "map.svg", "robots.json", "stats.json"):
        assert (out / name).is_file(), name
    assert len(list((out / "trajectories").glob("*.tum"))) == robots
    code, _, err = mrm(capsys, "evaluate", out, "--bag", bag, "--json")
    assert code == 0, err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["ate_rmse_m"] < 1e-3
    assert metrics["ate_all_rmse_m"] < 1e-3
    assert metrics["robots_merged"] == metrics["robots_total"] == robots
    assert metrics["pair_success"] == 1.0
    assert metrics["map_coverage"] >= 0.99
    assert metrics["map_precision"] >= 0.99
    return metrics


@pytest.mark.realdata
def test_import_carmen_replay_reference_evaluate_on_intel(capsys, tmp_path: Path) -> None:
    bag = tmp_path / "intel4"
    code, _, err = mrm(capsys, "import-carmen", carmen_log("intel"), "--robots", 4, "--out", bag)
    assert code == 0, err
    metrics = assert_reference_round_trip(capsys, bag, tmp_path / "ref", robots=4)
    assert metrics["scans_total"] == 910 and metrics["scans_unposed"] == 0


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_simulate_replay_reference_evaluate(capsys, tmp_path: Path, storage: str) -> None:
    bag = tmp_path / "sim"
    code, _, err = mrm(
        capsys,
        "simulate",
        "--robots",
        2,
        "--out",
        bag,
        "--duration",
        4,
        "--rate",
        10,
        "--storage",
        storage,
    )
    assert code == 0, err
    assert_reference_round_trip(capsys, bag, tmp_path / "ref", robots=2)


def test_simulate_replay_local_evaluate_scores_each_robot_in_its_own_frame(
    capsys, tmp_path: Path
) -> None:
    bag = tmp_path / "sim"
    args = ("--robots", 2, "--out", bag, "--duration", 4, "--rate", 10, "--seed", 3)
    assert mrm(capsys, "simulate", *args)[0] == 0
    out = tmp_path / "local"
    code, _, err = mrm(capsys, "replay", bag, "--out", out, "--method", "local")
    assert code == 0, err
    robots = json.loads((out / "robots.json").read_text())
    assert robots == {"robot1": "unmerged", "robot2": "unmerged"}
    stats = json.loads((out / "stats.json").read_text())
    assert stats["method"] == "local" and set(stats["robots"]) == {"robot1", "robot2"}
    assert mrm(capsys, "evaluate", out, "--bag", bag, "--json")[0] == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["robots_merged"] == 0  # never claimed: no merging in 'local'
    assert metrics["pair_success"] >= 0.95
    for robot in metrics["robots"].values():
        assert robot["ate_own_frame_m"] < 0.05
        assert robot["reported_unmerged"]


def replayed_and_evaluated(capsys, tmp_path: Path, method: str) -> tuple[Path, dict[str, Any]]:
    """Two simulated robots replayed by ``method`` (every robot must be merged) and evaluated:
    the bag and the metrics."""
    bag = tmp_path / "sim"
    args = ("--robots", 2, "--out", bag, "--duration", 20, "--rate", 10, "--seed", 3)
    assert mrm(capsys, "simulate", *args)[0] == 0
    out = tmp_path / method
    # 20 s in the simulated office give the right join P 0.95 (test_link_graph's
    # SIMULATED_WORLD_JOIN_PROBABILITY): merged at 0.9 through --set.
    bar = f"merge.join_probability={SIMULATED_WORLD_JOIN_PROBABILITY}"
    code, _, err = mrm(capsys, "replay", bag, "--out", out, "--method", method, "--set", bar)
    assert code == 0, err
    robots = json.loads((out / "robots.json").read_text())
    assert all(frame != "unmerged" for frame in robots.values()), robots
    assert mrm(capsys, "evaluate", out, "--bag", bag, "--json")[0] == 0
    return bag, json.loads((out / "metrics.json").read_text())


def test_simulate_replay_pivot_evaluate_merges_the_robots(capsys, tmp_path: Path) -> None:
    bag, metrics = replayed_and_evaluated(capsys, tmp_path, "pivot")
    assert metrics["robots_merged"] == metrics["robots_total"] == 2
    assert metrics["ate_rmse_m"] < 0.15
    assert metrics["map_precision"] > 0.9
    # The merging parameters come from config/map_merger.yaml and --set merge.*: a link
    # threshold no link can reach leaves the second robot unmerged, reported as such.
    strict = tmp_path / "strict"
    shipped = Path(__file__).resolve().parents[2] / "config" / "map_merger.yaml"
    code, _, err = mrm(
        capsys,
        *("replay", bag, "--out", strict, "--method", "pivot", "--merger-config", shipped),
        *("--set", "merge.link_min_wall=1000", "--set", "local_mapping.keyframe_distance=0.5"),
        *("--set", f"merge.join_probability={SIMULATED_WORLD_JOIN_PROBABILITY}"),
    )
    assert code == 0, err
    frames = json.loads((strict / "robots.json").read_text())
    unmerged = [v for v in frames.values() if isinstance(v, str) and v.startswith("unmerged")]
    assert len(unmerged) == 1, frames
    code, _, err = mrm(
        capsys, "replay", bag, "--out", strict, "--set", "merge.pairwise.link_min_value=-1"
    )
    assert code == 2 and "merge.pairwise.link_min_value" in err


def test_replay_ffs_merges_and_an_unknown_method_exits_2(capsys, tmp_path: Path) -> None:
    bag, metrics = replayed_and_evaluated(capsys, tmp_path, "ffs")
    assert metrics["robots_merged"] == 2 and metrics["ate_rmse_m"] < 0.15
    with pytest.raises(SystemExit) as exited:  # argparse's choices name the known ones
        mrm(capsys, "replay", bag, "--out", tmp_path / "icp", "--method", "icp")
    assert exited.value.code == 2 and "icp" in capsys.readouterr().err
    assert not (tmp_path / "icp").exists()


def bad_bags(tmp_path: Path) -> dict[str, Path]:
    from multi_robot_mapper.core.scan import LaserScanData
    from multi_robot_mapper.io.bags import RobotRecording, TimedScan, write_recordings

    good = tmp_path / "good"
    scan = LaserScanData(
        ranges=[1.0] * 10,
        angle_min=0.0,
        angle_max=0.9,
        angle_increment=0.1,
        range_min=0.0,
        range_max=5.0,
    )
    write_recordings(good, {"robot1": RobotRecording("robot1", [TimedScan(1.0, "l", scan)], [])})
    mcap_file = next(good.glob("*.mcap"))
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(mcap_file.read_bytes()[: mcap_file.stat().st_size // 2])
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    return {
        "missing": tmp_path / "nope",
        "empty": empty,
        "truncated": truncated,
        "no scan topics": good,  # asked for a pattern that matches nothing below
        "unknown message type": raw_bag(tmp_path / "odd", {"/robot1/scan": "std_msgs/msg/String"}),
    }


@pytest.mark.parametrize(
    "case", ["missing", "empty", "truncated", "no scan topics", "unknown message type"]
)
def test_bad_bags_give_one_line_and_exit_2(capsys, tmp_path: Path, case: str) -> None:
    bag = bad_bags(tmp_path)[case]
    extra = ["--scan-topics", "/*/lidar"] if case == "no scan topics" else []
    code, out, err = mrm(
        capsys, "replay", bag, "--out", tmp_path / "o", "--method", "reference", *extra
    )
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("mrm replay: error:")
    assert "Traceback" not in err + out
