"""``mrm simulate``: a readable multi-robot bag, clutter between the robot and its walls, one-line
errors, never an overwrite."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from multi_robot_mapper.core.building_runs import (
    simulate_building,
)
from multi_robot_mapper.core.buildings import (
    generate_building,
)
from multi_robot_mapper.core.simulation import (
    SIM_START_S,
    LaserModel,
)
from multi_robot_mapper.io.bags import read_recordings


def test_mrm_simulate_writes_a_readable_bag(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["--world", "corridors", "--beams", "361", "--rate", "20", "--duration", "2"]
    assert mrm(["simulate", "--robots", "3", "--out", str(tmp_path / "a"), *args]) == 0
    assert "wrote" in capsys.readouterr().out
    recordings = read_recordings(tmp_path / "a")
    assert list(recordings) == ["robot1", "robot2", "robot3"]
    for name, rec in recordings.items():
        assert len(rec.scans) == len(rec.ground_truth) == 40
        assert rec.scans[0].stamp == pytest.approx(SIM_START_S)
        assert {s.frame_id for s in rec.scans} == {f"{name}/laser"}
        assert {g.frame_id for g in rec.ground_truth} == {"world"}
        assert rec.scans[0].scan.ranges.size == 361
        assert rec.scans[1].stamp - rec.scans[0].stamp == pytest.approx(0.05, abs=1e-6)
    # Same seed, other storage: the same ranges, byte for byte.
    more = ["--storage", "sqlite3"]
    assert mrm(["simulate", "--robots", "3", "--out", str(tmp_path / "b"), *args, *more]) == 0
    again = read_recordings(tmp_path / "b")
    for name in recordings:
        first = [s.scan.ranges.tobytes() for s in recordings[name].scans]
        assert first == [s.scan.ranges.tobytes() for s in again[name].scans]


def test_mrm_simulate_clutter_puts_objects_between_the_robot_and_its_walls(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Same seed, same route: with clutter, some beams end short of the walls they reach in
    # the empty building, and none ends beyond them.
    args = ["--robots", "1", "--beams", "361", "--rate", "10", "--duration", "4"]
    assert mrm(["simulate", "--out", str(tmp_path / "empty"), *args, "--noise", "0"]) == 0
    crowd = ["--clutter", "0.5", "--noise", "0"]
    assert mrm(["simulate", "--out", str(tmp_path / "crowd"), *args, *crowd]) == 0
    assert "clutter 0.5 objects/m^2" in capsys.readouterr().out
    empty = read_recordings(tmp_path / "empty")["robot1"]
    crowded = read_recordings(tmp_path / "crowd")["robot1"]
    shorter = 0
    for a, b in zip(empty.scans, crowded.scans, strict=True):
        both = np.isfinite(a.scan.ranges) & np.isfinite(b.scan.ranges)
        assert np.all(b.scan.ranges[both] <= a.scan.ranges[both] + 1e-9)
        shorter += int(np.count_nonzero(b.scan.ranges[both] < a.scan.ranges[both] - 0.05))
    assert shorter > 0.01 * sum(len(a.scan.ranges) for a in empty.scans)


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--robots", "0"], "--robots"),
        (["--robots", "2", "--world", "moon"], "unknown world"),
        (["--robots", "2", "--rate", "0"], "--rate"),
        (["--robots", "2", "--beams", "1"], "--beams"),
        (["--robots", "2", "--noise", "-1"], "--noise"),
        (["--robots", "2", "--duration", "0"], "--duration"),
        (["--robots", "2", "--clutter", "3"], "--clutter"),
    ],
)
def test_mrm_simulate_errors_are_one_line(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], words: str
) -> None:
    assert mrm(["simulate", "--out", str(tmp_path / "bag"), *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mrm simulate: error: ") and words in err
    assert not (tmp_path / "bag").exists()


def test_mrm_simulate_never_overwrites(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "bag").mkdir()
    assert mrm(["simulate", "--robots", "1", "--out", str(tmp_path / "bag")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "already exists" in err


def test_mrm_simulate_generated_writes_a_bag_that_replay_reads(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "gen"
    args = ["--world", "generated", "--seed", "4", "--kind", "room_row", "--size", "40"]
    more = ["--laser", "lms", "--duration", "3", "--glass", "--people", "2", "--sparse"]
    assert mrm(["simulate", "--robots", "2", "--out", str(bag), *args, *more]) == 0
    said = capsys.readouterr().out
    assert "generated room_row building (seed 4, 40 m" in said and "overlap small" in said
    recordings = read_recordings(bag)
    assert list(recordings) == ["robot1", "robot2"]
    for rec in recordings.values():
        # 2.4 m at a scan per 0.5 m, and one per 15 degrees of turning (into rooms and out)
        assert 5 <= len(rec.scans) == len(rec.ground_truth) < 40
        assert rec.scans[0].scan.ranges.size == 181
    out = tmp_path / "local"
    assert mrm(["replay", str(bag), "--out", str(out), "--method", "local"]) == 0
    stats = json.loads((out / "stats.json").read_text())
    assert stats["method"] == "local" and set(stats["robots"]) == {"robot1", "robot2"}
    assert stats["scans_total"] == sum(len(r.scans) for r in recordings.values())


def test_mrm_simulate_generated_is_the_core_simulation(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "gen"
    args = ["--world", "generated", "--seed", "2", "--size", "30", "--overlap", "large"]
    more = ["--beams", "91", "--rate", "10", "--duration", "2"]
    assert mrm(["simulate", "--robots", "2", "--out", str(bag), *args, *more]) == 0
    capsys.readouterr()
    laser = LaserModel(beams=91, rate=10.0)
    runs = simulate_building(
        generate_building(2, size=30.0), 2, laser, seed=2, duration=2.0, overlap=0.6
    )
    recordings = read_recordings(bag)
    for run, rec in zip(runs, recordings.values(), strict=True):
        assert len(rec.scans) == len(run.scans) == 20
        for written, simulated in zip(rec.scans, run.scans, strict=True):
            as_sent = simulated.ranges.astype(np.float32)  # LaserScan ranges are float32
            np.testing.assert_array_equal(written.scan.ranges, as_sent)


def test_mrm_simulate_random_overlap_is_drawn_from_the_seed(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    said = []
    for name in ("a", "b"):
        args = ["--world", "generated", "--seed", "9", "--size", "25", "--overlap", "random"]
        more = ["--beams", "31", "--rate", "10", "--duration", "1"]
        assert mrm(["simulate", "--robots", "2", "--out", str(tmp_path / name), *args, *more]) == 0
        said.append(capsys.readouterr().out)
    assert said[0].replace("/a ", "/b ") == said[1]
    drawn = float(said[0].split("overlap random ")[1].split(",")[0])
    assert 0.0 <= drawn <= 0.9


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--size", "10"], "--size must be in [20, 200] m, got 10"),
        (["--people", "-1"], "--people must be in [0, 1000]"),
        (["--sparse", "0"], "--sparse must be in [0.05, 100] m"),
        (["--world", "office", "--glass"], "--glass only with --world generated"),
        (["--world", "rooms", "--kind", "mixed", "--overlap", "none"], "--kind, --overlap only"),
        (["--robots", "100", "--kind", "bare_corridors", "--size", "20"], "waypoints"),
    ],
)
def test_mrm_simulate_generated_errors_are_one_line(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], words: str
) -> None:
    base = ["simulate", "--robots", "2", "--out", str(tmp_path / "bag"), "--world", "generated"]
    assert mrm([*base, *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mrm simulate: error: ") and words in err
    assert not (tmp_path / "bag").exists()
