"""CARMEN log parsing: beam geometry and malformed lines."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import pytest

from multi_robot_mapper.io.carmen import CarmenFormatError, beam_geometry, parse_flaser, read_carmen


def flaser(n: int, value: float = 1.0) -> str:
    ranges = " ".join([str(value)] * n)
    return f"FLASER {n} {ranges} 1.5 -2.0 0.3 9 9 9 12.5 host 12.6"


def test_beam_geometry_of_the_three_log_layouts() -> None:
    assert beam_geometry(180) == pytest.approx((-math.pi / 2, math.radians(1)))
    assert beam_geometry(181) == pytest.approx((-math.pi / 2, math.radians(1)))
    assert beam_geometry(361) == pytest.approx((-math.pi / 2, math.radians(0.5)))


def test_parse_reads_ranges_reference_pose_and_stamp_but_not_odometry() -> None:
    scan = parse_flaser(flaser(181, 2.5))
    assert scan.ranges.size == 181 and scan.ranges[0] == 2.5
    assert scan.reference_pose == (1.5, -2.0, 0.3)
    assert scan.timestamp == 12.5
    assert scan.angle_max == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("line", ["FLASER x", "FLASER 5 1 2 3", "FLASER 3 1 2 a 0 0 0 0 0 0 0 h 0"])
def test_malformed_lines_name_the_line(line: str) -> None:
    with pytest.raises(CarmenFormatError, match="line 7"):
        parse_flaser(line, 7)


def test_read_gzip_skips_other_records(tmp_path: Path) -> None:
    path = tmp_path / "x.log.gz"
    with gzip.open(path, "wt") as f:
        f.write("# comment\nODOM 1 2 3 0 0 0 1 h 1\n" + flaser(180) + "\n" + flaser(361) + "\n")
    assert [s.ranges.size for s in read_carmen(path)] == [180, 361]
