"""Free space: what a robot's laser could see of its own map, cast from its keyframes, and cast
again only near new walls."""

from __future__ import annotations

import numpy as np
import pytest
from test_merge_reuse import corridor_maps

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging import (
    MapViews,
    MergeConfig,
    free_space_conflict,
    seen_through_length,
)
from multi_robot_mapper.core.merging.places import units_of
from multi_robot_mapper.core.worlds import polygon

CONFIG = MergeConfig()  # what free space reads of it is the same in every test's config


def test_free_space_is_what_the_laser_could_see_of_its_own_map() -> None:
    # A closed 10 m x 10 m room seen from its centre, facing +x, with a 180 degree view.
    room = polygon([(-5.0, -5.0), (5.0, -5.0), (5.0, 5.0), (-5.0, 5.0)])
    views = MapViews.of(room, np.array([[0.0, 0.0, 0.0]]), CONFIG.view_fan())
    ahead = np.array([[1.0, -2.0, 1.0, 2.0]])  # 4 m of wall in front: all in free space
    assert seen_through_length(views, ahead, CONFIG.free_space_limits()) == pytest.approx(
        4.0, abs=0.21
    )
    behind = np.array([[-1.0, -2.0, -1.0, 2.0]])  # behind the laser: never seen
    outside = np.array([[6.0, -2.0, 6.0, 2.0]])  # beyond the room's own wall
    along = np.array([[4.7, -2.0, 4.7, 2.0]])  # within free_space_margin of the wall
    short = np.array([[1.0, 0.0, 1.0, 0.5]])  # furniture-sized: not tested
    for segments in (behind, outside, along, short):
        assert seen_through_length(views, segments, CONFIG.free_space_limits()) == 0.0
    # Map b is moved into a's frame by T_a_b first: to x = 4.8 (margin) or x = 2 (free).
    T_a_b = se2.matrix_from_pose(3.8, 0.0, 0.0)
    assert free_space_conflict(room, views, ahead, None, T_a_b, CONFIG.free_space_limits()) == 0.0
    T_a_b = se2.matrix_from_pose(1.0, 0.0, 0.0)
    assert free_space_conflict(room, views, ahead, None, T_a_b, CONFIG.free_space_limits()) > 3.9


def test_a_grown_maps_views_are_cast_again_only_near_its_new_walls() -> None:
    from collections import OrderedDict

    from multi_robot_mapper.core.merging.free_space import MapViews, ViewRows

    keyframes = corridor_maps()["b"]
    shorter = units_of({"b": keyframes[:-4]})[("b", 0)]
    full = units_of({"b": keyframes})[("b", 0)]
    rows: ViewRows = OrderedDict()
    MapViews.of(shorter.segments, shorter.poses, CONFIG.view_fan(), rows)
    cast_before = len(rows)
    views = MapViews.of(full.segments, full.poses, CONFIG.view_fan(), rows)
    fresh = MapViews.of(full.segments, full.poses, CONFIG.view_fan())
    np.testing.assert_array_equal(views.poses, fresh.poses)
    np.testing.assert_array_equal(views.ranges, fresh.ranges)  # bit for bit
    # Views far from the new keyframes' walls were not cast again.
    assert 0 < len(rows) - cast_before < len(views.poses)
