"""Places searched on other maps (core/merging/place_matching.py): a time budget leaves the
places not yet matched for the next update, which ends where a merge with no budget does;
targets and places are kept per map content, the most recently used."""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from test_joint import CONFIG, drives, moved
from test_link_graph import random_frames

from multi_robot_mapper.core.merging.joint import merge_joint
from multi_robot_mapper.core.merging.place_matching import KEPT, cached


def test_what_is_kept_is_made_once_and_the_least_recently_used_dropped_first() -> None:
    store: OrderedDict[int, str] = OrderedDict()
    made: list[int] = []

    def make(key: int) -> str:
        made.append(key)
        return f"made {key}"

    for key in range(KEPT):
        assert cached(store, key, lambda key=key: make(key)) == f"made {key}"
    assert cached(store, 0, lambda: make(0)) == "made 0"  # kept: not made again, used last
    assert made == list(range(KEPT))
    cached(store, KEPT, lambda: make(KEPT))  # one too many: the least recently used goes
    assert len(store) == KEPT and 1 not in store and 0 in store
    cached(store, 1, lambda: make(1))
    assert made == [*range(KEPT + 1), 1]


def test_a_time_budget_leaves_places_for_the_next_update() -> None:
    _, corridors = drives("corridors", 2)
    world = {"a": corridors[0], "b": corridors[1]}
    frames = dict(zip(world, random_frames(2, seed=6), strict=True))
    keyframes = {n: moved(world[n], frames[n]) for n in world}
    first = merge_joint(keyframes, CONFIG, budget=1e-9)  # one place match, then out of time
    assert first.stats["matches_computed"] == 1 and first.stats["matches_pending"] > 0
    result = first
    for _ in range(first.stats["matches_pending"] + 1):
        if result.stats["matches_pending"] == 0:
            break
        result = merge_joint(keyframes, CONFIG, previous=result, budget=1e-9)
    assert result.stats["matches_pending"] == 0
    everything = merge_joint(keyframes, CONFIG, budget=0.0)
    for name in world:
        np.testing.assert_allclose(result.placements[name], everything.placements[name], atol=1e-3)  # type: ignore[arg-type]
