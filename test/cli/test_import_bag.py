"""``mrm import-bag``: a bag cut into K robots with a truth file, cut as ``mrm import-carmen``
cuts a log."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
from test_recordings import (
    T0,
    mrm,
    room_drive,
    ros1_scan,
    scan_reading,
    write_ros1_bag,
    write_truth,
)

from multi_robot_mapper.io.bags import (
    read_recordings,
)


def test_a_cut_with_a_truth_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """12 scans (scan i reads i + 1 m) cut into 3 robots with 2 scans of overlap; the truth
    file poses every third scan: each robot keeps the reference poses of its own scans."""
    stamps = T0 + 0.1 * np.arange(12)
    poses = np.column_stack((np.arange(12.0), -np.arange(12.0), 0.01 * np.arange(12)))
    bag = write_ros1_bag(
        tmp_path / "run.bag",
        {"/scan": [(t, ros1_scan(t, scan_reading(i + 1.0), i)) for i, t in enumerate(stamps)]},
    )
    truth = write_truth(tmp_path / "run.truth.csv", range(0, 12, 3), stamps, poses)
    out = tmp_path / "cut"
    args = ("import-bag", bag, "--robots", 3, "--overlap-scans", 2, "--truth", truth, "--out", out)
    code, printed, err = mrm(capsys, *args)
    assert code == 0, err
    assert "reference poses per robot: robot1 2, robot2 2, robot3 2" in printed
    recordings = read_recordings(out)
    # Runs [0, 4), [2, 8), [6, 12): every run starts at the bag's first stamp.
    first = {"robot1": 0, "robot2": 2, "robot3": 6}
    for name, rec in recordings.items():
        i0 = first[name]
        count = len(rec.scans)
        assert [s.scan.ranges[0] for s in rec.scans] == [i0 + 1.0 + j for j in range(count)]
        assert [s.stamp for s in rec.scans] == pytest.approx(stamps[:count], abs=1e-6)
        assert {s.frame_id for s in rec.scans} == {f"{name}/laser"}
        posed = [i for i in range(i0, i0 + count) if i % 3 == 0]
        np.testing.assert_allclose([g.pose for g in rec.ground_truth], poses[posed])
        assert [g.stamp for g in rec.ground_truth] == pytest.approx(
            [stamps[i - i0] for i in posed], abs=1e-6
        )


def test_import_bag_and_import_carmen_cut_alike(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same scans as a CARMEN log and as a ROS 1 bag with its truth file: both commands
    write the same robots, scans, stamps and reference poses."""
    stamps, poses, scans = room_drive(15, stamp0=100.0)
    lines = []
    for t, pose, scan in zip(stamps, poses, scans, strict=True):
        ranges = " ".join(f"{r:.6f}" for r in scan.ranges)
        x, y, theta = (repr(float(v)) for v in pose)
        lines.append(f"FLASER 180 {ranges} {x} {y} {theta} 0 0 0 {float(t)!r} h {float(t)!r}")
    log = tmp_path / "run.log.gz"
    with gzip.open(log, "wt") as stream:
        stream.write("\n".join(lines) + "\n")
    bag = write_ros1_bag(
        tmp_path / "run.bag",
        {"/scan": [(t, ros1_scan(t, s)) for t, s in zip(stamps, scans, strict=True)]},
    )
    truth = write_truth(tmp_path / "run.truth.csv", range(15), stamps, poses)
    common = ("--robots", 3, "--overlap-scans", 1)
    assert (
        mrm(capsys, "import-carmen", log, *common, "--range-max", 80, "--out", tmp_path / "c")[0]
        == 0
    )
    assert (
        mrm(capsys, "import-bag", bag, *common, "--truth", truth, "--out", tmp_path / "b")[0] == 0
    )
    from_log, from_bag = read_recordings(tmp_path / "c"), read_recordings(tmp_path / "b")
    assert list(from_log) == list(from_bag) == ["robot1", "robot2", "robot3"]
    for name in from_log:
        a, b = from_log[name], from_bag[name]
        assert [s.stamp for s in a.scans] == pytest.approx([s.stamp for s in b.scans], abs=1e-6)
        for x, y in zip(a.scans, b.scans, strict=True):
            np.testing.assert_allclose(x.scan.ranges, y.scan.ranges, atol=1e-6)
            assert x.scan.angle_increment == pytest.approx(y.scan.angle_increment)
        np.testing.assert_allclose(
            [g.pose for g in a.ground_truth], [g.pose for g in b.ground_truth], atol=1e-9
        )
