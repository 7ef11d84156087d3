"""The merger's saved map file: round trip, atomic writes, one clear line for bad files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from multi_robot_mapper.io.saved_map import (
    SavedMap,
    SavedMapError,
    SavedRobot,
    read_saved_map,
    write_saved_map,
)


def sample() -> SavedMap:
    rng = np.random.default_rng(3)
    robots = {
        "robot1": SavedRobot(
            "robot1/map",
            1e9 + 0.025,
            (1_000_000_012, 500),
            (0.0, 0.0, 0.0),
            rng.normal(size=(5, 4)),
            rng.normal(size=(3, 3)),
        ),
        "robot2": SavedRobot(
            "robot2/map", 1e9, None, None, rng.normal(size=(2, 4)), np.zeros((1, 3))
        ),
        "robot1_session1": SavedRobot(
            "robot1/map_session1",
            5.0,
            (3, 0),
            (1.0, 2.0, 0.5),
            rng.normal(size=(4, 4)),
            np.zeros((2, 3)),
            "robot1",
            0.97,
        ),
    }
    return SavedMap(
        "map", "robot1", robots, rng.normal(size=(7, 4)), np.array([0, 0, 1, 1, 1, 2, 2])
    )


def test_a_saved_map_reads_back_exactly(tmp_path: Path) -> None:
    saved = sample()
    path = write_saved_map(tmp_path / "deep" / "map.json", saved)
    back = read_saved_map(path)
    assert back.map_frame == "map" and back.reference == "robot1"
    assert sorted(back.robots) == sorted(saved.robots)
    for name, robot in saved.robots.items():
        got = back.robots[name]
        fields = ("map_frame", "session", "map_stamp", "placement", "session_of", "probability")
        assert [getattr(got, f) for f in fields] == [getattr(robot, f) for f in fields]
        np.testing.assert_array_equal(got.segments, robot.segments)  # JSON floats are exact
        np.testing.assert_array_equal(got.keyframe_poses, robot.keyframe_poses)
    np.testing.assert_array_equal(back.segments, saved.segments)
    np.testing.assert_array_equal(back.segment_robot, saved.segment_robot)
    assert [p.name for p in path.parent.iterdir()] == ["map.json"]  # no temporary left


def test_a_failed_save_keeps_the_previous_file(tmp_path: Path) -> None:
    path = write_saved_map(tmp_path / "map.json", sample())
    before = path.read_bytes()
    broken = sample()
    broken.robots["robot2"].segments[0, 0] = np.nan
    with pytest.raises(SavedMapError, match="NaN"):
        write_saved_map(path, broken)
    assert path.read_bytes() == before


def test_an_unwritable_place_is_one_clear_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(SavedMapError, match="cannot write"):
        write_saved_map(blocker / "map.json", sample())


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{", "invalid JSON"),
        ("[]", "not a saved map"),
        ('{"format": "multi_robot_mapper.saved_map", "version": 9}', "version 9"),
        ('{"format": "multi_robot_mapper.saved_map", "version": 1}', "'robots'"),
    ],
)
def test_unreadable_files_name_the_problem(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "map.json"
    path.write_text(content)
    with pytest.raises(SavedMapError, match=message) as caught:
        read_saved_map(path)
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["robots"]["robot2"].__setitem__("segments", [[1, 2, 3]]), "robot2.segments"),
        (
            lambda d: d["robots"]["robot2"].__setitem__("segments", [[1, 2, 3, "x"]]),
            "robot2.segments",
        ),
        (lambda d: d["robots"]["robot1"].__setitem__("placement", [1, 2]), "robot1.placement"),
        (lambda d: d["robots"]["robot1"].__setitem__("map_stamp", [1, -2]), "robot1.map_stamp"),
        (lambda d: d["robots"]["robot1"].__setitem__("probability", 1.5), "robot1.probability"),
        (lambda d: d["robots"]["robot1"].__setitem__("probability", "x"), "robot1.probability"),
        (lambda d: d.__setitem__("reference", "nobody"), "'reference'"),
        (lambda d: d["global"].__setitem__("segment_robot", [0, 9, 0, 0, 0, 0, 0]), "outside"),
        (lambda d: d["global"].__setitem__("segment_robot", [0]), "one index per segment"),
    ],
)
def test_bad_fields_are_refused_by_name(tmp_path: Path, edit, message: str) -> None:
    path = write_saved_map(tmp_path / "map.json", sample())
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    with pytest.raises(SavedMapError, match=message):
        read_saved_map(path)


def test_a_file_without_probabilities_reads_them_as_unknown(tmp_path: Path) -> None:
    """Files written before the placements' probabilities were saved still load."""
    path = write_saved_map(tmp_path / "map.json", sample())
    data = json.loads(path.read_text())
    for entry in data["robots"].values():
        del entry["probability"]
    path.write_text(json.dumps(data))
    assert all(robot.probability is None for robot in read_saved_map(path).robots.values())


def test_a_missing_file_says_so(tmp_path: Path) -> None:
    with pytest.raises(SavedMapError, match="no such saved map"):
        read_saved_map(tmp_path / "nothing.json")
