"""``mrm import-carmen``: a CARMEN log cut into K robots' runs in a rosbag2 bag."""

from __future__ import annotations

import gzip
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import carmen_log

from multi_robot_mapper.cli.import_carmen import increasing, split_runs
from multi_robot_mapper.cli.main import main
from multi_robot_mapper.io.bags import read_recordings
from multi_robot_mapper.io.carmen import read_carmen

Mrm = Callable[[list[str]], int]


def write_log(path: Path, count: int, beams: int = 180) -> Path:
    """A CARMEN log of ``count`` scans: scan i reads i + 1 m everywhere, stamp 100 + 0.5 i s,
    reference pose (i, -i, 0.01 i); odometry fields are set to garbage (never to be read)."""
    lines = ["# synthetic", "PARAM robot_use_laser on 1.0 host 1.0"]
    for i in range(count):
        ranges = " ".join([f"{i + 1:.3f}"] * beams)
        lines.append(
            f"FLASER {beams} {ranges} {i:.3f} {-i:.3f} {0.01 * i:.4f} 99 99 9 "
            f"{100 + 0.5 * i:.3f} host {100 + 0.5 * i:.3f}"
        )
        lines.append(f"ODOM 99 99 9 0 0 0 {100 + 0.5 * i:.3f} host 0")
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "wt") as stream:
        stream.write("\n".join(lines) + "\n")
    return path


def test_split_runs_known_answers() -> None:
    assert split_runs(10, 3, 0) == [(0, 3), (3, 7), (7, 10)]
    assert split_runs(10, 3, 2) == [(0, 3), (1, 7), (5, 10)]
    assert split_runs(10, 2, 50) == [(0, 5), (0, 10)]  # never before the first scan
    assert split_runs(4, 4, 0) == [(0, 1), (1, 2), (2, 3), (3, 4)]
    assert split_runs(910, 4, 0)[-1][1] == 910


def test_increasing_repairs_only_what_does_not_increase() -> None:
    stamps = increasing(np.array([1.0, 2.0, 2.0, 1.5, 3.0, 3.0]), step=0.001)
    np.testing.assert_allclose(stamps, [1.0, 2.0, 2.001, 2.002, 3.0, 3.001])
    np.testing.assert_array_equal(increasing(np.array([0.5, 1.0, 7.0])), [0.5, 1.0, 7.0])


def test_synthetic_log_with_overlap(mrm: Mrm, tmp_path: Path) -> None:
    log = write_log(tmp_path / "run.log", 12)
    out = tmp_path / "bag"
    assert (
        mrm(["import-carmen", str(log), "--robots", "3", "--overlap-scans", "2", "--out", str(out)])
        == 0
    )
    recordings = read_recordings(out)
    assert list(recordings) == ["robot1", "robot2", "robot3"]
    # Runs [0, 4), [4, 8), [8, 12), the last two extended two scans back.
    first_scan = {"robot1": 0, "robot2": 2, "robot3": 6}
    sizes = {"robot1": 4, "robot2": 6, "robot3": 6}
    for name, rec in recordings.items():
        assert len(rec.scans) == sizes[name]
        i0 = first_scan[name]
        # Scan i reads i + 1 m on every beam; its reference pose is (i, -i, 0.01 i).
        assert [s.scan.ranges[0] for s in rec.scans] == [i0 + 1.0 + j for j in range(sizes[name])]
        assert rec.ground_truth[1].pose == pytest.approx((i0 + 1, -(i0 + 1), 0.01 * (i0 + 1)))
        # Every robot starts at the log's first stamp, 0.5 s apart as in the log.
        stamps = [s.stamp for s in rec.scans]
        assert stamps == pytest.approx([100.0 + 0.5 * j for j in range(sizes[name])])
        assert [g.stamp for g in rec.ground_truth] == stamps
        assert {s.frame_id for s in rec.scans} == {f"{name}/laser"}
        assert {g.frame_id for g in rec.ground_truth} == {"world"}
    # Neighbours share the overlap scans (robot2's first two are robot1's last two).
    np.testing.assert_array_equal(
        recordings["robot2"].scans[0].scan.ranges, recordings["robot1"].scans[2].scan.ranges
    )


@pytest.mark.realdata
@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_intel_as_four_robots(mrm: Mrm, tmp_path: Path, storage: str) -> None:
    log = carmen_log("intel")
    out = tmp_path / "intel"
    assert (
        mrm(["import-carmen", str(log), "--robots", "4", "--out", str(out), "--storage", storage])
        == 0
    )
    scans = list(read_carmen(log))
    recordings = read_recordings(out)
    assert list(recordings) == ["robot1", "robot2", "robot3", "robot4"]
    assert sum(len(r.scans) for r in recordings.values()) == 910
    assert len({r.scans[0].stamp for r in recordings.values()}) == 1
    assert recordings["robot1"].scans[0].stamp == pytest.approx(scans[0].timestamp)
    for rec in recordings.values():
        assert {s.scan.ranges.size for s in rec.scans} == {180}
        assert len(rec.ground_truth) == len(rec.scans)
        stamps = [s.stamp for s in rec.scans]
        assert all(np.diff(stamps) > 0)
    # Runs [0, 228), [228, 455), [455, 682), [682, 910): 910 / 4 = 227.5 rounded half to even.
    assert [len(r.scans) for r in recordings.values()] == [228, 227, 227, 228]
    # A sample scan: robot3's 17th is log scan 455 + 17.
    sample = recordings["robot3"]
    log_scan = scans[455 + 17]
    assert sample.ground_truth[17].pose == pytest.approx(log_scan.reference_pose, abs=1e-12)
    np.testing.assert_array_equal(
        sample.scans[17].scan.ranges, np.float32(log_scan.ranges).astype(np.float64)
    )
    assert sample.scans[17].scan.angle_min == pytest.approx(-np.pi / 2)
    assert sample.scans[17].scan.angle_increment == pytest.approx(np.radians(1.0))
    # Stamps keep the log's spacing within a run (no repaired stamp between 455 and 472).
    assert sample.scans[17].stamp - sample.scans[0].stamp == pytest.approx(
        log_scan.timestamp - scans[455].timestamp, abs=1e-6
    )


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["{tmp}/missing.log", "--robots", "2"], "no such log file"),
        (["{log}", "--robots", "0"], "--robots must be in [1, 100] robots, got 0"),
        (["{log}", "--robots", "101"], "--robots must be in [1, 100] robots, got 101"),
        (["{log}", "--robots", "13"], "more than the 12 scans"),
        (["{log}", "--robots", "2", "--overlap-scans", "-1"], "--overlap-scans"),
        (["{bad}", "--robots", "2"], "no usable FLASER scan (FLASER lines skipped: 1 malformed"),
        (["{empty}", "--robots", "2"], "no usable FLASER scan"),
        (["{gzipbad}", "--robots", "2"], "cannot read"),
        (["{log}", "--robots", "2", "--range-max", "nan"], "--range-max must be in"),
        (["{log}", "--robots", "2", "--range-max", "-1"], "--range-max must be in"),
    ],
)
def test_errors_exit_2_with_one_line(
    mrm: Mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    log = write_log(tmp_path / "run.log.gz", 12)
    bad = tmp_path / "bad.log"
    bad.write_text("FLASER 3 1.0 2.0\n")
    empty = tmp_path / "empty.log"
    empty.write_text("# nothing\n")
    gzipbad = tmp_path / "bad.log.gz"
    gzipbad.write_bytes(b"\x1f\x8b\x08\x00" + bytes(range(256)) * 4)
    names = {"tmp": tmp_path, "log": log, "bad": bad, "empty": empty, "gzipbad": gzipbad}
    argv = [a.format(**names) for a in argv]
    assert mrm(["import-carmen", *argv, "--out", str(tmp_path / "bag")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mrm import-carmen: error: ")
    assert words in err
    assert not (tmp_path / "bag").exists()


def test_unwritable_or_existing_out(
    mrm: Mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = write_log(tmp_path / "run.log", 4)
    blocker = tmp_path / "file"
    blocker.write_text("a file, not a directory")
    assert mrm(["import-carmen", str(log), "--robots", "2", "--out", str(blocker / "bag")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot create" in err and str(blocker / "bag") in err
    assert mrm(["import-carmen", str(log), "--robots", "2", "--out", str(blocker)]) == 2
    assert "already exists" in capsys.readouterr().err


def _run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_nan_lines_are_skipped_so_replay_and_evaluate_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = write_log(tmp_path / "run.log", 8)
    lines = log.read_text().splitlines()  # FLASER of scan i on line 2 + 2 i
    lines[4] = lines[4].replace(" 2.000 2.000 ", " nan inf ", 1)  # ranges of scan 1
    lines[8] = lines[8].replace(" 3.000 -3.000 ", " nan -3.000 ", 1)  # pose of scan 3
    log.write_text("\n".join(lines) + "\n")
    bag, out = tmp_path / "bag", tmp_path / "ref"
    code, stdout, err = _run(capsys, "import-carmen", log, "--robots", 2, "--out", bag)
    assert code == 0, err
    assert "FLASER lines skipped: 2 with NaN/inf" in stdout
    recordings = read_recordings(bag)
    assert sum(len(r.scans) for r in recordings.values()) == 6
    code, _, err = _run(capsys, "replay", bag, "--out", out, "--method", "reference")
    assert code == 0, err
    code, _, err = _run(capsys, "evaluate", out, "--bag", bag)
    assert code == 0, err


def test_backward_and_negative_stamps_import_in_file_order(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The MIT infinite-corridor log's stamps start at -0.45 s and decrease.
    log = write_log(tmp_path / "run.log", 6)
    text = log.read_text()
    for i in range(6):
        stamp = f"{100 + 0.5 * i:.3f}"
        text = text.replace(f" {stamp} host {stamp}", f" {-0.45 - 0.25 * i:.3f} host 0")
    log.write_text(text)
    bag = tmp_path / "bag"
    code, _, err = _run(capsys, "import-carmen", log, "--robots", 1, "--out", bag)
    assert code == 0, err
    assert "backwards" in err and "start at -0.45 s" in err
    scans = read_recordings(bag)["robot1"].scans
    assert [s.scan.ranges[0] for s in scans] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]  # file order
    stamps = np.array([s.stamp for s in scans])
    assert stamps[0] > 0 and np.diff(stamps) == pytest.approx([0.25] * 5)


def test_import_summary_names_geometry_no_return_and_skipped_lines(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = write_log(tmp_path / "run.log", 6, beams=360)
    with log.open("a") as stream:
        stream.write(
            "ROBOTLASER1 0 -1.57 3.14 0.017 50 0.01 0 2 1 2 0 0 0 0 0 0 0 0 0 0 0 0 1 h 1\n"
        )
        stream.write("FLASER 360 1.0 2.0 3.0")  # a cut last line
    code, stdout, err = _run(capsys, "import-carmen", log, "--robots", 2, "--out", tmp_path / "b")
    assert code == 0, err
    assert "beams: 360 from -90 deg every 0.5 deg (179.5 deg" in stdout
    assert "no return: readings >=" in stdout
    assert "FLASER lines skipped: 1 cut (last line)" in stdout
    assert "ROBOTLASER1 1" in stdout
    scan = read_recordings(tmp_path / "b")["robot1"].scans[0].scan
    assert scan.angle_increment == pytest.approx(np.radians(0.5))
