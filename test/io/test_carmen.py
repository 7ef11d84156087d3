"""CARMEN log parsing: beam geometry as CARMEN's reader has it, the no-return value, and lines
that are skipped and counted (NaN/inf, malformed, cut, other message types)."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import carmen_log

from multi_robot_mapper.core.scan import scan_points
from multi_robot_mapper.io.carmen import (
    CarmenFormatError,
    beam_geometry,
    carmen_scan_data,
    monotonic_stamps,
    parse_flaser,
    read_carmen,
)


def flaser(
    n: int, value: float | str = 1.0, stamp: float = 12.5, pose: str = "1.5 -2.0 0.3"
) -> str:
    ranges = " ".join([str(value)] * n)
    return f"FLASER {n} {ranges} {pose} 9 9 9 {stamp} host {stamp}"


def write(path: Path, lines: list[str], newline_at_end: bool = True) -> Path:
    text = "\n".join(lines) + ("\n" if newline_at_end else "")
    if path.suffix == ".gz":
        with gzip.open(path, "wt") as stream:
            stream.write(text)
    else:
        path.write_text(text)
    return path


def test_beam_geometry_as_carmens_reader_has_it() -> None:
    # 181 and 361 beams span 180 deg; 180 and 360 keep the 1 and 0.5 deg step (179, 179.5 deg).
    assert beam_geometry(180) == pytest.approx((-math.pi / 2, math.radians(1)))
    assert beam_geometry(181) == pytest.approx((-math.pi / 2, math.radians(1)))
    assert beam_geometry(360) == pytest.approx((-math.pi / 2, math.radians(0.5)))
    assert beam_geometry(361) == pytest.approx((-math.pi / 2, math.radians(0.5)))
    assert parse_flaser(flaser(360)).angle_max == pytest.approx(math.radians(89.5))
    assert parse_flaser(flaser(361)).angle_max == pytest.approx(math.radians(90.0))
    assert parse_flaser(flaser(180)).angle_max == pytest.approx(math.radians(89.0))
    assert parse_flaser(flaser(91)).angle_increment == pytest.approx(math.radians(2.0))


def test_parse_reads_ranges_reference_pose_and_stamp_but_not_odometry() -> None:
    scan = parse_flaser(flaser(181, 2.5))
    assert scan.ranges.size == 181 and scan.ranges[0] == 2.5
    assert scan.reference_pose == (1.5, -2.0, 0.3)
    assert scan.timestamp == 12.5
    assert scan.angle_max == pytest.approx(math.pi / 2)


@pytest.mark.parametrize(
    "line",
    [
        "FLASER x",
        "FLASER 5 1 2 3",
        "FLASER 3 1 2 a 0 0 0 0 0 0 0 h 0",
        "FLASER 999999999 1 2 3",
        "FLASER -4 1 2 3 4 5 6 7 8 9 10 h 11",
        "FLASER 3 1 2 3 0 0 0 0 0 0 1e300 h 0",
    ],
)
def test_malformed_lines_name_the_line(line: str) -> None:
    with pytest.raises(CarmenFormatError, match="line 7"):
        parse_flaser(line, 7)


def test_read_gzip_skips_other_records(tmp_path: Path) -> None:
    path = write(
        tmp_path / "x.log.gz", ["# comment", "ODOM 1 2 3 0 0 0 1 h 1", flaser(180), flaser(361)]
    )
    log = read_carmen(path)
    assert [s.ranges.size for s in log] == [180, 361]
    assert log.other_lines == {"comment": 1, "ODOM": 1}


@pytest.mark.parametrize(
    "bad",
    [
        flaser(180, "nan"),
        flaser(180, "inf"),
        flaser(180, pose="nan 0 0"),
        flaser(180, pose="0 inf 0"),
        flaser(180, stamp=float("nan")),
        flaser(180, stamp=float("-inf")),
    ],
)
def test_lines_with_nan_or_inf_are_skipped_and_counted(tmp_path: Path, bad: str) -> None:
    log = read_carmen(write(tmp_path / "x.log", [flaser(180, 2.0), bad, flaser(180, 3.0)]))
    assert [s.ranges[0] for s in log] == [2.0, 3.0]
    assert log.skipped == {"with NaN/inf": 1} and log.skipped_lines == (2,)
    assert "FLASER lines skipped: 1 with NaN/inf (lines 2)" in log.summary()
    for scan in log:
        assert np.isfinite(scan.ranges).all() and np.isfinite(scan.reference_pose).all()


def test_other_message_types_and_a_cut_last_line_are_skipped_and_counted(tmp_path: Path) -> None:
    cut = flaser(180, 4.0)[:400]
    lines = [
        flaser(180, 2.0),
        "ROBOTLASER1 0 -1.57 3.14 0.017 50 0.01 0 3 1 2 3 0 0 0 0 0 0 0 0 0 0 0 0 1 h 1",
        "RAWLASER1 0 -1.57 3.14 0.017 50 0.01 0 3 1 2 3 0 1 h 1",
        "FLASER 3 1 2",  # malformed, not last
        flaser(180, 3.0),
        cut,
    ]
    log = read_carmen(write(tmp_path / "x.log", lines, newline_at_end=False))
    assert [s.ranges[0] for s in log] == [2.0, 3.0]
    assert log.skipped == {"malformed": 1, "cut (last line)": 1}
    assert log.other_lines == {"ROBOTLASER1": 1, "RAWLASER1": 1}
    text = "\n".join(log.summary())
    assert "1 malformed, 1 cut (last line) (lines 4, 6)" in text
    assert "ROBOTLASER1 1" in text


def test_truncated_gzip_keeps_the_lines_read(tmp_path: Path) -> None:
    whole = write(tmp_path / "x.log.gz", [flaser(180, 1.0 + i, stamp=i) for i in range(400)])
    data = whole.read_bytes()
    cut = tmp_path / "cut.log.gz"
    cut.write_bytes(data[: len(data) * 2 // 3])
    log = read_carmen(cut)
    assert log.truncated and 0 < len(log) < 400
    assert [s.ranges[0] for s in log] == [1.0 + i for i in range(len(log))]
    assert any("truncated" in line for line in log.summary())


def _marker_log(tmp_path: Path, marker: float, param: str | None, far: float | None = None) -> Path:
    """Scans of walls at 3-6 m whose last 20 beams get no return (``marker``); with ``far``,
    every scan also has 60 beams that see a far wall at that range."""
    lines = [] if param is None else [f"PARAM robot_front_laser_max {param} host 0"]
    for i in range(10):
        ranges = np.linspace(3.0, 6.0, 180) + 0.01 * i
        if far is not None:
            ranges[60:120] = far + 0.01 * i
        ranges[-20:] = marker
        text = " ".join(f"{r:.3f}" for r in ranges)
        lines.append(f"FLASER 180 {text} 0 0 0 0 0 0 {i} h {i}")
    return write(tmp_path / "m.log", lines)


def test_no_return_from_the_top_of_the_histogram_no_phantom_walls(tmp_path: Path) -> None:
    # A 16-bit-millimetre laser marks no return with 32.767 m: a fixed 50 m cut made walls of it.
    log = read_carmen(_marker_log(tmp_path, 32.767, None))
    assert log.no_return.source.startswith("value repeating at the top")
    assert log.no_return.marker == pytest.approx(32.767)
    assert 32.0 < log.no_return.range_max < 32.767
    for scan in log:
        points = scan_points(carmen_scan_data(scan)).points
        assert len(points) == 160 and np.hypot(*points.T).max() < 6.1
    assert "no return: readings >= 32.667 m" in "\n".join(log.summary())


def test_no_return_from_the_logs_param(tmp_path: Path) -> None:
    log = read_carmen(_marker_log(tmp_path, 81.91, "80.99"))
    assert log.no_return.range_max == pytest.approx(80.99)
    assert log.no_return.source == "PARAM robot_front_laser_max"
    assert "the log marks no return with 81.91 m (200 readings)" in log.no_return.describe()


def test_a_param_the_readings_contradict_is_not_used(tmp_path: Path) -> None:
    # edmonton: robot_front_laser_max 10 m, yet a quarter of its readings lie at 10-51 m.
    log = read_carmen(_marker_log(tmp_path, 51.15, "10", far=25.0))
    assert log.no_return.range_max == pytest.approx(51.05)
    assert "PARAM robot_front_laser_max 10 m not used" in log.no_return.describe()
    assert len(scan_points(carmen_scan_data(log[0])).points) == 160


def test_no_marker_and_no_param_keeps_every_reading(tmp_path: Path) -> None:
    lines = [flaser(180, 2.0 + i) for i in range(3)]
    log = read_carmen(write(tmp_path / "x.log", lines))
    assert log.no_return.source.startswith("none found")
    assert all(len(scan_points(carmen_scan_data(s)).points) == 180 for s in log)


def test_range_max_override(tmp_path: Path) -> None:
    log = read_carmen(_marker_log(tmp_path, 32.767, None), range_max=5.0)
    assert log.no_return.source == "--range-max" and log[0].range_max == 5.0


def test_monotonic_stamps_of_a_clock_running_backwards_below_zero() -> None:
    # The MIT infinite-corridor log's stamps start at -0.45 s and decrease.
    logged = -0.45 - 0.2 * np.arange(6)
    logged[3] -= 0.5  # one uneven step
    stamps, notes = monotonic_stamps(logged, "mit.log")
    assert (np.diff(stamps) > 0).all() and stamps[0] > 0
    np.testing.assert_allclose(np.diff(stamps), [0.2, 0.2, 0.7, 0.001, 0.001])
    assert any("backwards" in n for n in notes) and any("start at -0.45 s" in n for n in notes)


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("name", "source", "range_max", "beams"),
    [
        ("freiburg-079", "PARAM robot_front_laser_max", 80.99, 360),
        ("csail", "PARAM robot_front_laser_max", 50.0, 361),
        ("intel", "value repeating at the top of the range histogram", 81.73, 180),
        ("edmonton", "value repeating at the top of the range histogram", 51.05, 180),
    ],
)
def test_real_logs_no_return_and_geometry(
    name: str, source: str, range_max: float, beams: int
) -> None:
    log = read_carmen(carmen_log(name))
    assert log.no_return.source == source
    assert log.no_return.range_max == pytest.approx(range_max)
    assert {s.ranges.size for s in log} == {beams}
    assert not log.skipped
