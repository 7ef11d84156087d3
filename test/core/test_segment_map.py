"""SegmentMap: a map's segments and what is derived from them, made once per map."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from multi_robot_mapper.core.geometry import lines_of
from multi_robot_mapper.core.segment_map import SegmentMap

WALLS = np.array(
    [[0.0, 0.0, 4.0, 0.0], [4.0, 0.0, 4.0, 3.0], [1.0, 1.0, 1.0, 1.5], [0.0, 3.0, 2.0, 3.0]]
)


def test_derived_geometry_is_the_arrays_and_made_once() -> None:
    segment_map = SegmentMap.of(WALLS)
    lines = lines_of(WALLS)
    assert segment_map.lines is segment_map.lines
    for name in ("direction", "angle", "length", "normal_offset"):
        assert np.array_equal(getattr(segment_map.lines, name), getattr(lines, name))
    assert segment_map.total_length == pytest.approx(4.0 + 3.0 + 0.5 + 2.0)
    assert np.array_equal(segment_map.longest_first, [0, 1, 3, 2])
    assert np.array_equal(segment_map.longest(2).segments, WALLS[[0, 1]])
    assert segment_map.longest(2) is segment_map.longest(2)
    x1, y1, x2, y2 = segment_map.columns
    assert np.array_equal(np.column_stack((x1, y1, x2, y2)), WALLS)
    assert np.allclose(np.column_stack(segment_map.centres), 0.5 * (WALLS[:, :2] + WALLS[:, 2:]))


def test_a_map_is_a_read_only_copy_and_its_digest_follows_the_content() -> None:
    walls = WALLS.copy()
    segment_map = SegmentMap.of(walls)
    walls[0, 0] = 9.0  # the caller's array, not the map's
    assert segment_map.segments[0, 0] == 0.0
    with pytest.raises(ValueError):
        segment_map.segments[0, 0] = 1.0
    with pytest.raises(ValueError):
        segment_map.lines.length[0] = 1.0
    assert SegmentMap.of(segment_map) is segment_map
    assert SegmentMap.of(WALLS).digest == segment_map.digest
    assert SegmentMap.of(walls).digest != segment_map.digest
    assert len(SegmentMap.of(np.zeros((0, 4)))) == 0
    assert SegmentMap.of(np.zeros((0, 4))).total_length == 0.0


def test_what_a_block_holds_is_dropped_after_it_and_a_map_pickles_as_its_segments() -> None:
    segment_map = SegmentMap.of(WALLS)
    made: list[int] = []

    def make() -> int:
        made.append(1)
        return len(made)

    assert segment_map.held("k") is None
    with segment_map.holding("k", make) as outer:
        with segment_map.holding("k", make) as inner:  # the enclosing block's
            assert outer == inner == 1 and segment_map.held("k") == 1
        assert segment_map.held("k") == 1
    assert segment_map.held("k") is None and made == [1]
    for count in range(20):
        segment_map.longest(count)
    assert len(segment_map._longest) <= 8  # a few counts kept, not every one asked
    for again in (pickle.loads(pickle.dumps(segment_map)), copy.deepcopy(segment_map)):
        assert np.array_equal(again.segments, WALLS)
        assert again.digest == segment_map.digest
        assert not again.segments.flags.writeable
