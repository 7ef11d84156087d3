"""What one merge update keeps for the next (issue 50: merging that scales with what changed):
known answers for the reuse in ``JointState``. Nothing changed: no place searched again, the
same placements; one map grown: only its places near the new keyframes made again; two mergers
in one process: nothing shared."""

from __future__ import annotations

import numpy as np
from test_joint import CONFIG, drives, moved
from test_link_graph import random_frames

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.core.merging.joint import JointState, merge_joint
from multi_robot_mapper.core.merging.places import PlaceIndex, places_of, units_of


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


def test_a_grown_map_remakes_only_the_places_near_its_new_keyframes() -> None:
    keyframes = corridor_maps()["a"]
    shorter = units_of({"a": keyframes[:-4]})[("a", 0)]
    full = units_of({"a": keyframes})[("a", 0)]
    index: PlaceIndex = PlaceIndex()
    before = places_of(shorter, CONFIG, index)
    after = places_of(full, CONFIG, index)
    fresh = places_of(full, CONFIG)
    # The same places as made from nothing, field by field.
    assert [p.centre for p in after] == [p.centre for p in fresh]
    for kept, made in zip(after, fresh, strict=True):
        assert kept.digest == made.digest
        np.testing.assert_array_equal(kept.segments, made.segments)
        np.testing.assert_array_equal(kept.views.ranges, made.views.ranges)
        np.testing.assert_array_equal(kept.views.poses, made.views.poses)
    # A place that no new keyframe or wall reaches (within place_radius of its centre) is the
    # shorter map's own object; the others are made again.
    new = full.owner >= len(full.index) - 4
    ends = np.vstack((full.poses[-4:, :2], full.segments[new, :2], full.segments[new, 2:]))
    old = {p.centre: p for p in before}
    far = [
        p
        for p in after
        if np.hypot(*(ends - p.T_unit_centre[:2]).T).min() > CONFIG.place_radius + 1.0
    ]
    assert far, "the corridor is longer than a place: some places lie far from its end"
    for place in far:
        assert place is old[place.centre]
    assert any(p is not old.get(p.centre) for p in after)


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
    kept = ("targets", "places", "intra", "seen", "verdicts", "matches")
    for name in kept:
        assert getattr(one, name) is not getattr(two, name), name
    assert one.fusion is not two.fusion


def test_a_grown_maps_views_are_cast_again_only_near_its_new_walls() -> None:
    from collections import OrderedDict

    from multi_robot_mapper.core.merging.free_space import MapViews, ViewRows

    keyframes = corridor_maps()["b"]
    shorter = units_of({"b": keyframes[:-4]})[("b", 0)]
    full = units_of({"b": keyframes})[("b", 0)]
    rows: ViewRows = OrderedDict()
    MapViews.of(shorter.segments, shorter.poses, CONFIG, rows)
    cast_before = len(rows)
    views = MapViews.of(full.segments, full.poses, CONFIG, rows)
    fresh = MapViews.of(full.segments, full.poses, CONFIG)
    np.testing.assert_array_equal(views.poses, fresh.poses)
    np.testing.assert_array_equal(views.ranges, fresh.ranges)  # bit for bit
    # Views far from the new keyframes' walls were not cast again.
    assert 0 < len(rows) - cast_before < len(views.poses)
