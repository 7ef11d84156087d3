"""``mrm simulate``: a readable multi-robot bag, clutter between the robot and its walls, one-line
errors, never an overwrite."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from multi_robot_mapper.core.simulation import (
    SIM_START_S,
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
