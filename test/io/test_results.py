"""The replay result folder: exact round trip, and one clear ResultsError per malformed file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from multi_robot_mapper.io.results import (
    REPLAYED_FILE,
    ReplayedBags,
    ReplayResult,
    ResultsError,
    read_results,
    read_tum,
    write_results,
)


def _result() -> ReplayResult:
    rng = np.random.default_rng(3)
    stamps1 = 1_718_000_000.0 + np.cumsum(rng.uniform(0.02, 0.03, 50))
    poses1 = np.column_stack(
        (rng.normal(0, 5, 50), rng.normal(0, 5, 50), rng.uniform(-np.pi, np.pi, 50))
    )
    stamps2 = 1_718_000_000.123456789 + 0.025 * np.arange(7)
    poses2 = np.column_stack((np.arange(7.0), -np.arange(7.0), np.full(7, 3.0)))
    return ReplayResult(
        method="pivot",
        robots=["robot1", "robot2", "robot3"],
        map_segments=rng.normal(0, 3, (12, 4)),
        segment_robot=np.array([0, 0, 1, 1, 1, 0, 1, 0, 0, 1, 1, 1]),
        trajectories={
            "robot1": (stamps1, poses1),
            "robot2": (stamps2, poses2),
            "robot3": (np.zeros(0), np.zeros((0, 3))),
        },
        robot_frames={"robot1": (0.0, 0.0, 0.0), "robot2": (1.5, -2.0, 0.7), "robot3": None},
        stats={"scans_total": 60, "total_s": 1.25, "scans_rejected": {"no_beams": 1}},
        replayed=ReplayedBags(
            bags=(Path("/data/run one.bag"), Path("/data/run2")),
            names=("robot1", "robot2"),
            scan_topics="/scan",
            beam_geometry="-90,1",
            truth_files=(Path("/data/a.truth.csv"), Path("/data/b.truth.csv")),
        ),
    )


def test_round_trip_is_exact(tmp_path: Path) -> None:
    original = _result()
    write_results(tmp_path / "out", original)
    back = read_results(tmp_path / "out")
    assert back.method == "pivot"
    assert back.robots == original.robots
    np.testing.assert_array_equal(back.map_segments, original.map_segments)
    np.testing.assert_array_equal(back.segment_robot, original.segment_robot)
    assert back.segment_robot.dtype == np.int64
    for robot in original.robots:
        stamps, poses = original.trajectories[robot]
        got_stamps, got_poses = back.trajectories[robot]
        # %.9f gives back the very same float64 stamps: association can be exact.
        np.testing.assert_array_equal(got_stamps, stamps)
        assert got_poses.shape == poses.shape
        np.testing.assert_allclose(got_poses[:, :2], poses[:, :2], rtol=0, atol=1e-12)
        dtheta = (got_poses[:, 2] - poses[:, 2] + np.pi) % (2 * np.pi) - np.pi
        np.testing.assert_allclose(dtheta, 0.0, atol=1e-12)
    assert back.robot_frames == original.robot_frames
    assert back.stats == original.stats
    assert back.replayed == original.replayed
    assert json.loads((tmp_path / "out" / "robots.json").read_text())["robot3"] == "unmerged"


def test_tum_lines_are_standard(tmp_path: Path) -> None:
    write_results(tmp_path, _result())
    lines = [
        line
        for line in (tmp_path / "trajectories" / "robot2.tum").read_text().splitlines()
        if not line.startswith("#")
    ]
    assert len(lines) == 7
    fields = lines[0].split()
    assert len(fields) == 8
    assert fields[0] == "1718000000.123456717"  # the float64 nearest 1718000000.123456789, %.9f
    x, y, z, qx, qy, qz, qw = map(float, fields[1:])
    assert (x, y, z, qx, qy) == (0.0, 0.0, 0.0, 0.0, 0.0)
    assert qz == pytest.approx(np.sin(1.5)) and qw == pytest.approx(np.cos(1.5))


def test_read_tum_accepts_a_hand_written_file(tmp_path: Path) -> None:
    path = tmp_path / "t.tum"
    path.write_text("# comment\n\n1.0 1 2 0 0 0 0.7071067811865476 0.7071067811865476\n")
    stamps, poses = read_tum(path)
    np.testing.assert_array_equal(stamps, [1.0])
    np.testing.assert_allclose(poses, [[1.0, 2.0, np.pi / 2]], atol=1e-12)


def _edit_json(path: Path, key: str, value: object) -> None:
    data = json.loads(path.read_text())
    data[key] = value
    path.write_text(json.dumps(data))


BREAKAGES = {
    "map.json missing": (lambda d: (d / "map.json").unlink(), "map.json"),
    "map.json not json": (lambda d: (d / "map.json").write_text("{nope"), "map.json"),
    "map.json a list": (lambda d: (d / "map.json").write_text("[]"), "map.json"),
    "segments of 3": (lambda d: _edit_json(d / "map.json", "segments", [[1, 2, 3]]), "map.json"),
    "segments text": (
        lambda d: _edit_json(d / "map.json", "segments", [["a", 1, 2, 3]]),
        "map.json",
    ),
    "segment_robot short": (
        lambda d: _edit_json(d / "map.json", "segment_robot", [0, 1]),
        "map.json",
    ),
    "segment_robot out of range": (
        lambda d: _edit_json(d / "map.json", "segment_robot", [0] * 11 + [3]),
        "map.json",
    ),
    "robot name a path": (
        lambda d: _edit_json(d / "map.json", "robots", ["robot1", "../x", "robot3"]),
        "map.json",
    ),
    "trajectory missing": (
        lambda d: (d / "trajectories" / "robot2.tum").unlink(),
        "robot2.tum",
    ),
    "trajectory 7 fields": (
        lambda d: (d / "trajectories" / "robot2.tum").write_text("1 2 3 4 5 6 7\n"),
        "robot2.tum",
    ),
    "trajectory text": (
        lambda d: (d / "trajectories" / "robot2.tum").write_text("1 2 3 x 0 0 0 1\n"),
        "robot2.tum",
    ),
    "trajectory nan": (
        lambda d: (d / "trajectories" / "robot2.tum").write_text("1 nan 3 0 0 0 0 1\n"),
        "robot2.tum",
    ),
    "trajectory stamps back": (
        lambda d: (d / "trajectories" / "robot2.tum").write_text(
            "2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n"
        ),
        "robot2.tum",
    ),
    "trajectory bad quaternion": (
        lambda d: (d / "trajectories" / "robot2.tum").write_text("1 0 0 0 0 0 0 2\n"),
        "robot2.tum",
    ),
    "robots.json missing": (lambda d: (d / "robots.json").unlink(), "robots.json"),
    "robots.json robot missing": (
        lambda d: (d / "robots.json").write_text('{"robot1": "unmerged"}'),
        "robots.json",
    ),
    "robots.json bad pose": (
        lambda d: _edit_json(d / "robots.json", "robot2", {"x": 1, "y": "2", "theta": 0}),
        "robots.json",
    ),
    "robots.json bad word": (
        lambda d: _edit_json(d / "robots.json", "robot2", "merged"),
        "robots.json",
    ),
    "stats.json missing": (lambda d: (d / "stats.json").unlink(), "stats.json"),
    "stats.json a number": (lambda d: (d / "stats.json").write_text("3"), "stats.json"),
    "replay.json a list": (lambda d: (d / REPLAYED_FILE).write_text("[]"), "replay.json"),
    "replay.json no bag": (
        lambda d: _edit_json(d / REPLAYED_FILE, "bags", []),
        "replay.json: 'bags' must name",
    ),
    "replay.json relative bag": (
        lambda d: _edit_json(d / REPLAYED_FILE, "bags", ["run.bag"]),
        "replay.json: 'bags' must be a list of absolute paths",
    ),
    "replay.json names a string": (
        lambda d: _edit_json(d / REPLAYED_FILE, "names", "robot1,robot2"),
        "replay.json: 'names'",
    ),
    "replay.json no scan topics": (
        lambda d: _edit_json(d / REPLAYED_FILE, "scan_topics", None),
        "replay.json: 'scan_topics'",
    ),
    "replay.json geometry a number": (
        lambda d: _edit_json(d / REPLAYED_FILE, "beam_geometry", 1),
        "replay.json: 'beam_geometry'",
    ),
    "replay.json truth relative": (
        lambda d: _edit_json(d / REPLAYED_FILE, "truth", ["a.truth.csv"]),
        "replay.json: 'truth'",
    ),
}


@pytest.mark.parametrize("case", sorted(BREAKAGES))
def test_malformed_files_raise_one_line_naming_the_file(tmp_path: Path, case: str) -> None:
    write_results(tmp_path, _result())
    read_results(tmp_path)  # intact first
    breakage, file_name = BREAKAGES[case]
    breakage(tmp_path)
    with pytest.raises(ResultsError) as info:
        read_results(tmp_path)
    message = str(info.value)
    assert file_name in message
    assert "\n" not in message


def test_a_folder_without_the_replay_record_reads_as_before(tmp_path: Path) -> None:
    """Results from before replay.json, or not made from bags: read, with no record; writing
    such a result over a folder drops the record of bags it was not made from."""
    write_results(tmp_path, _result())
    assert (tmp_path / REPLAYED_FILE).is_file()
    (tmp_path / REPLAYED_FILE).unlink()
    assert read_results(tmp_path).replayed is None
    write_results(tmp_path, _result())
    unrecorded = _result()
    unrecorded.replayed = None
    write_results(tmp_path, unrecorded)
    assert not (tmp_path / REPLAYED_FILE).exists()
    assert read_results(tmp_path).replayed is None


def test_missing_folder_raises(tmp_path: Path) -> None:
    with pytest.raises(ResultsError, match="no such result folder"):
        read_results(tmp_path / "absent")


def test_writer_refuses_inconsistent_owners(tmp_path: Path) -> None:
    result = _result()
    result.segment_robot = result.segment_robot[:-1]
    with pytest.raises(ValueError, match="segment_robot"):
        write_results(tmp_path, result)
