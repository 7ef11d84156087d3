"""The merger's robot bookkeeping without a node: sessions, saving and restoring."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.io.messages import PartialMapContents, stamp_from_seconds
from multi_robot_mapper.ros.merger_state import (
    RobotState,
    merge_inputs,
    older_than_loaded,
    restore_saved_map,
    result_of_saved,
    saved_map_of,
    store_partial_map,
)


def contents(session: float, keyframes: int, segments: int, stamp: float) -> PartialMapContents:
    rng = np.random.default_rng(int(session * 10) + keyframes)
    return PartialMapContents(
        segments=rng.normal(size=(segments, 4)),
        keyframe_poses=rng.normal(size=(keyframes, 3)),
        session=session,
        stamp=stamp_from_seconds(stamp),
        frame_id="robot1/map",
    )


def test_a_new_first_keyframe_keeps_the_old_map_as_an_earlier_session() -> None:
    robots = {"robot1": RobotState("robot1")}
    assert store_partial_map(robots, "robot1", contents(10.0, 5, 30, 14.0), 1, 2) is None
    first = robots["robot1"].segments
    assert store_partial_map(robots, "robot1", contents(10.0, 6, 32, 15.0), 2, 2) is None
    kept = store_partial_map(robots, "robot1", contents(50.0, 2, 8, 51.0), 3, 2)
    assert kept == "robot1_session1"
    old = robots["robot1_session1"]
    assert old.session == 10.0 and old.session_of == "robot1" and len(old.segments) == 32
    assert old.map_frame == "robot1/map_session1" and not old.subscriptions
    assert len(robots["robot1"].segments) == 8 and robots["robot1"].session == 50.0
    assert not np.array_equal(first, robots["robot1"].segments)
    # Both are merged like any two robots.
    assert sorted(merge_inputs(robots).maps) == ["robot1", "robot1_session1"]


def test_a_one_keyframe_restart_is_not_a_session_and_old_sessions_are_bounded() -> None:
    robots = {"robot1": RobotState("robot1")}
    store_partial_map(robots, "robot1", contents(1.0, 1, 4, 1.0), 1, 2)
    assert store_partial_map(robots, "robot1", contents(1.5, 1, 4, 1.5), 2, 2) is None
    for k, session in enumerate((2.0, 3.0, 4.0, 5.0)):
        store_partial_map(robots, "robot1", contents(session, 3, 10, session), 10 + k, 2)
    # Three restarts with real maps: the two newest earlier sessions are kept.
    assert sorted(robots) == ["robot1", "robot1_session2", "robot1_session3"]
    assert robots["robot1_session3"].session == 4.0
    none_kept = {"robot2": RobotState("robot2")}
    store_partial_map(none_kept, "robot2", contents(1.0, 3, 10, 1.0), 1, 0)
    assert store_partial_map(none_kept, "robot2", contents(2.0, 3, 10, 2.0), 2, 0) is None
    assert sorted(none_kept) == ["robot2"]


def merged_two() -> tuple[dict[str, RobotState], MergeResult]:
    robots = {"a": RobotState("a"), "b": RobotState("b"), "c": RobotState("c")}
    store_partial_map(robots, "a", contents(1.0, 3, 6, 9.0), 1, 2)
    store_partial_map(robots, "b", contents(2.0, 3, 5, 9.5), 1, 2)
    result = MergeResult(
        robots=["a", "b"],
        placements={"a": (0.0, 0.0, 0.0), "b": (1.0, 2.0, 0.3)},
        reference="a",
        links=[],
        pairs={},
        segments=np.arange(12.0).reshape(3, 4),
        segment_robot=np.array([0, 1, 1]),
        timings={},
        stats={},
    )
    return robots, result


def test_saving_and_restoring_into_an_empty_merger_gives_every_map_back() -> None:
    robots, result = merged_two()
    saved = saved_map_of(robots, result, "map")
    assert sorted(saved.robots) == ["a", "b"]  # c never sent a map
    assert saved.robots["b"].placement == (1.0, 2.0, 0.3) and saved.reference == "a"
    fresh: dict[str, RobotState] = {}
    assert sorted(restore_saved_map(fresh, saved, 2)) == ["a", "b"]
    for name in ("a", "b"):
        np.testing.assert_array_equal(fresh[name].segments, robots[name].segments)
        assert fresh[name].map_stamp == robots[name].map_stamp
        assert fresh[name].session == robots[name].session
    back = result_of_saved(saved)
    assert back.placements == result.placements and back.reference == "a"
    np.testing.assert_array_equal(back.segment_robot, result.segment_robot)


def test_restoring_keeps_newer_live_maps_and_turns_other_sessions_into_earlier_ones() -> None:
    robots, result = merged_two()
    saved = saved_map_of(robots, result, "map")
    live = {"a": RobotState("a"), "b": RobotState("b")}
    store_partial_map(live, "a", contents(1.0, 4, 9, 20.0), 1, 2)  # same session, newer
    store_partial_map(live, "b", contents(7.0, 3, 4, 21.0), 1, 2)  # b restarted since
    loaded = restore_saved_map(live, saved, 2)
    assert loaded == ["b_session1"]
    assert len(live["a"].segments) == 9  # the live map of the same session stays
    assert len(live["b"].segments) == 4 and live["b"].session == 7.0
    assert live["b_session1"].session == 2.0 and live["b_session1"].session_of == "b"


def test_a_snapshot_older_than_the_loaded_map_of_its_session_leaves_the_loaded_map() -> None:
    robots, result = merged_two()  # a: session 1.0, its map of t = 9.0
    fresh: dict[str, RobotState] = {}
    restore_saved_map(fresh, saved_map_of(robots, result, "map"), 2)
    state = fresh["a"]
    assert older_than_loaded(state, contents(1.0, 1, 2, 3.0))  # the latched snapshot of t = 3
    assert not older_than_loaded(state, contents(1.0, 4, 8, 9.5))  # newer: replaces it
    assert not older_than_loaded(state, contents(7.0, 1, 2, 8.0))  # another session
    store_partial_map(fresh, "a", contents(1.0, 4, 8, 9.5), 1, 2)
    assert not older_than_loaded(state, contents(1.0, 1, 2, 3.0))  # live maps: as they come
