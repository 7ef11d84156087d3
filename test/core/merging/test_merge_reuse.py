"""What one merge update keeps for the next (issue 50: merging that scales with what changed):
known answers for the reuse in ``JointState``. Nothing changed: no place searched again, the
same placements; two mergers in one process: nothing shared. One map grown: only its places
and views near the new keyframes made again (`test_places.py`, `test_free_space.py`)."""

from __future__ import annotations

import numpy as np
from test_joint import CONFIG, drives, moved
from test_link_graph import random_frames

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.core.merging.joint import JointState, merge_joint


def corridor_maps(seed: int = 6) -> dict[str, list[Keyframe]]:
    """Two robots' keyframes along the corridors world, each in a map frame anywhere."""
    _, corridors = drives("corridors", 2)
    world = {"a": corridors[0], "b": corridors[1]}
    frames = dict(zip(world, random_frames(2, seed=seed), strict=True))
    return {name: moved(world[name], frames[name]) for name in world}


def state_of(result: MergeResult) -> JointState:
    assert isinstance(result.state, JointState)
    return result.state


def test_a_second_whole_merge_with_nothing_changed_searches_no_place() -> None:
    keyframes = corridor_maps()
    first = merge_joint(keyframes, CONFIG, budget=0.0)
    assert first.unmerged == [] and first.stats["matches_computed"] > 0
    again = merge_joint(keyframes, CONFIG, previous=first, budget=0.0)
    assert again.stats["matches_computed"] == 0 and again.stats["matches_pending"] == 0
    # Every pair's verdict and the graph's solution are the last update's own objects.
    assert again.verdicts == first.verdicts  # type: ignore[attr-defined]
    for pair, verdict in again.verdicts.items():  # type: ignore[attr-defined]
        assert verdict is first.verdicts[pair]  # type: ignore[attr-defined]
    assert state_of(again).solution is state_of(first).solution
    assert again.placements == first.placements
    for name in keyframes:
        np.testing.assert_array_equal(again.keyframe_poses[name], first.keyframe_poses[name])
    np.testing.assert_array_equal(again.segments, first.segments)


def test_two_mergers_in_one_process_share_nothing() -> None:
    # Each merge's state is its own (no module-level cache): merging other maps in between
    # neither reaches into the first merger's state nor changes what it gives.
    first_maps, other_maps = corridor_maps(seed=6), corridor_maps(seed=9)
    first = merge_joint(first_maps, CONFIG, budget=0.0)
    other = merge_joint(other_maps, CONFIG, budget=0.0)
    again = merge_joint(first_maps, CONFIG, budget=0.0)
    assert again.stats["matches_computed"] == first.stats["matches_computed"]
    assert again.placements == first.placements
    one, two = state_of(first), state_of(other)
    assert one.places.index.keys().isdisjoint(two.places.index.keys()) or all(
        one.places.index[k] is not two.places.index[k]
        for k in one.places.index.keys() & two.places.index.keys()
    )
    kept = ("targets", "places", "intra", "judged", "matches")
    for name in kept:
        assert getattr(one, name) is not getattr(two, name), name
    for name in ("by_key", "latest", "seen", "evidence"):
        assert getattr(one.judged, name) is not getattr(two.judged, name), name
    assert one.fusion is not two.fusion


def test_an_update_weighs_each_join_of_groups_once_per_maps_and_placements(monkeypatch) -> None:
    # A join of groups is weighed with its walls in free space on every map of both groups
    # (group_conflict); an update that changed nothing the join is made of takes the weight
    # the last update measured, and gives the same merge.
    from test_verdicts import three_robots

    from multi_robot_mapper.core.merging import joint

    keyframes, first = three_robots()
    assert state_of(first).conflicts, "three robots in one group: joins were weighed"

    def never(*_: object) -> float:
        raise AssertionError("a join weighed again on the same maps and placements")

    monkeypatch.setattr(joint, "group_conflict", never)
    again = merge_joint(keyframes, CONFIG, previous=first, budget=0.0)
    assert state_of(again).conflicts is state_of(first).conflicts
    assert again.placements == first.placements


def test_an_update_after_a_map_grew_brings_the_kept_graph_up_to_date() -> None:
    # ISAM2 kept between updates (kept_graph): the update after robot a's map grew by two
    # keyframes takes the last update's graph and adds them. The same update without a kept
    # graph (a merger started again) solves the same graph from the rigid start: both reach
    # its optimum (Levenberg-Marquardt stops at its relative tolerance, 1e-5) and place the
    # robots alike (here to 0.2 µm; the test allows 0.1 mm).
    keyframes = corridor_maps()
    shorter = {**keyframes, "a": keyframes["a"][:-2]}
    first, again = (merge_joint(shorter, CONFIG, budget=0.0) for _ in range(2))
    kept = state_of(first).graph.kept
    assert first.unmerged == [] and kept is not None
    grown = merge_joint(keyframes, CONFIG, previous=first, budget=0.0)
    assert state_of(grown).graph.kept is kept and len(kept.keys) == len(kept.graph) > 0
    state_of(again).graph.kept = None
    afresh = merge_joint(keyframes, CONFIG, previous=again, budget=0.0)
    fresh_graph = state_of(afresh).graph.kept
    assert fresh_graph is not None and fresh_graph is not kept
    assert len(fresh_graph.graph.edges) == len(kept.graph.edges)
    assert kept.graph.objective() <= fresh_graph.graph.objective() * (1 + 1e-6)
    for name in keyframes:
        got, want = grown.keyframe_poses[name], afresh.keyframe_poses[name]
        assert np.hypot(*(got[:, :2] - want[:, :2]).T).max() < 1e-4
        assert np.abs(got[:, 2] - want[:, 2]).max() < 1e-4
