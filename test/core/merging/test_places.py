"""The places of a map: a grown map remakes only the places near its new keyframes."""

from __future__ import annotations

import numpy as np
from test_joint import CONFIG
from test_merge_reuse import corridor_maps

from multi_robot_mapper.core.merging.places import PlaceIndex, places_of, units_of


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
