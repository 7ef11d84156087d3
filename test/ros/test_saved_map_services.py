"""The merger's saved maps with real nodes, in-process (ros/saved_map_services.py): the save_map
and load_map services bring the map back into a merger without robots, and a merger that saves as
it merges publishes the saved placements at once after a restart."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_live_faults import NAMES, Rig, assert_right_placements, office_maps

from multi_robot_mapper.io.messages import (
    pose_from_msg,
)
from multi_robot_mapper.io.saved_map import read_saved_map
from multi_robot_mapper.ros.merger_config import MapMergerConfig
from multi_robot_mapper.ros.saved_map_services import SavedMapServices

pytestmark = pytest.mark.ros


@pytest.fixture
def rig(ros_context) -> Iterator[Rig]:  # type: ignore[no-untyped-def]
    """test_live_faults.py's rig: the real map_merger and robots publishing as robot_mapper."""
    r = Rig(ros_context)
    yield r
    r.close()


def test_save_and_load_services_bring_the_map_back_into_a_merger_without_robots(
    rig: Rig, tmp_path: Path
) -> None:
    maps, views = office_maps()
    map_file = tmp_path / "maps" / "global.json"
    merger = rig.start_merger(map_file=str(map_file))
    for name in NAMES:
        rig.add_robot(name, maps[name], views[name])
    assert rig.spin_until(lambda: rig.merged(*NAMES)), merger.result
    placements = dict(merger.result.placements)
    answer = rig.call("/save_map")
    assert answer.success and str(map_file) in answer.message
    saved = read_saved_map(map_file)
    assert sorted(saved.robots) == NAMES and saved.reference == merger.result.reference
    assert len(saved.segments) == len(merger.result.segments)

    # Every robot gone, the merger restarted: load_map gives the map back and merges it.
    for name in NAMES:
        rig.remove_robot(name)
    rig.stop_merger()
    merger = rig.start_merger(map_file=str(map_file))
    assert merger.result is None
    answer = rig.call("/load_map")
    assert answer.success and "alpha" in answer.message and "bravo" in answer.message
    assert rig.spin_until(lambda: rig.merged(*NAMES))
    # The saved map holds each robot's map and placement, not its keyframes: merged again
    # as whole maps, the robots land within millimetres of where the keyframe graph put them.
    for name in NAMES:
        got, before = merger.result.placements[name], placements[name]
        assert got is not None and before is not None
        assert np.hypot(got[0] - before[0], got[1] - before[1]) < 0.01
        assert abs(got[2] - before[2]) < 0.002
    assert_right_placements(merger, NAMES)

    # load_on_start does the same at start-up; a missing file is an answer, not a crash.
    rig.stop_merger()
    merger = rig.start_merger(map_file=str(map_file), load_on_start=True)
    assert sorted(r for r in merger.robots if len(merger.robots[r].segments)) == NAMES
    assert rig.spin_until(lambda: rig.merged(*NAMES))
    rig.stop_merger()
    rig.start_merger(map_file=str(tmp_path / "none.json"))
    answer = rig.call("/load_map")
    assert not answer.success and "no such saved map" in answer.message


def test_the_merger_saves_as_it_merges_and_a_restart_publishes_the_saved_placements_at_once(
    rig: Rig, tmp_path: Path
) -> None:
    maps, views = office_maps()
    map_file = tmp_path / "on_exit.json"
    rig.start_merger(map_file=str(map_file), save_on_shutdown=True)
    for name in NAMES:
        rig.add_robot(name, maps[name], views[name])
    assert rig.spin_until(lambda: rig.merged(*NAMES))
    assert map_file.exists()  # saved after a merge: a killed merger leaves a recent file
    rig.stop_merger()  # and on shutdown
    saved = read_saved_map(map_file)
    assert all(saved.robots[n].placement is not None for n in NAMES)
    other = next(n for n in NAMES if n != saved.reference)
    assert 0.0 < (saved.robots[other].probability or 0.0) <= 1.0

    # Started again with no robot left and no merge to come (merge_period of an hour): the
    # saved placements are published from the file alone, each with its probability.
    for name in NAMES:
        rig.remove_robot(name)
        rig.observer.frames[name].clear()
    rig.observer.probabilities.clear()
    merger = rig.start_merger(map_file=str(map_file), load_on_start=True, merge_period=3600.0)
    assert rig.spin_until(lambda: all(rig.observer.frames[n] for n in NAMES), 10.0)
    assert rig.spin_until(lambda: len(rig.observer.probabilities) == len(NAMES), 10.0)
    assert merger.merges == 0
    assert merger._saved_placed == frozenset(NAMES)  # what the file holds: kept till replaced
    for name in NAMES:
        got = pose_from_msg(rig.observer.frames[name][-1].pose)
        np.testing.assert_allclose(got, saved.robots[name].placement, atol=1e-9)
    assert rig.observer.probabilities[saved.reference] == 1.0
    assert rig.observer.probabilities[other] == saved.robots[other].probability


class _Saves(SavedMapServices):
    """The autosave rule alone: a merger's result by hand, each save counted, not written."""

    def __init__(self) -> None:
        self.config = MapMergerConfig(save_on_shutdown=True)
        self.result = None
        self.saved: list[frozenset[str]] = []
        self.logged: list[str] = []

    def save_map(self, path: str | None = None) -> str:
        self.saved.append(frozenset(p for p, pose in self.result.placements.items() if pose))
        self._saved_placed, self._saved_at = self.saved[-1], time.monotonic()
        return ""

    def get_logger(self) -> SimpleNamespace:
        return SimpleNamespace(warning=self.logged.append, info=self.logged.append)

    def merged(self, placed: str, pending: int) -> None:
        poses = {name: (0.0, 0.0, 0.0) if name in placed else None for name in "abc"}
        self.result = SimpleNamespace(placements=poses, stats={"matches_pending": pending})
        self.autosave()


def test_an_update_with_places_pending_is_saved_only_when_it_places_more_than_the_file() -> None:
    merger = _Saves()
    merger.merged("a", pending=2)  # the first placement, places still pending: saved
    merger.merged("ab", pending=1)  # one more robot placed: saved at once
    merger.merged("a", pending=1)  # b not matched again yet: a restart must not lose it
    merger.merged("ac", pending=1)  # c placed but b missing: not more than the file
    merger.merged("ab", pending=1)  # as the file, within the period: nothing new
    assert merger.saved == [frozenset("a"), frozenset("ab")]
    merger.merged("a", pending=0)  # a whole merge that withdrew b: saved (its placements are final)
    assert merger.saved[-1] == frozenset("a")


def test_a_restart_never_saves_fewer_placements_than_the_file_it_loaded_while_places_wait() -> None:
    merger = _Saves()
    merger._saved_placed = frozenset("abc")  # as load_map leaves it: the file's robots
    merger.merged("ab", pending=3)  # c not matched again yet
    assert merger.saved == []
    merger.save_on_exit()  # stopped now: the file keeps c
    assert merger.saved == [] and "that file is kept" in merger.logged[-1]
    merger.merged("abc", pending=1)  # as many as the file: saved on exit, not before
    assert merger.saved == []
    merger.save_on_exit()
    assert merger.saved == [frozenset("abc")]
