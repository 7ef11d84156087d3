"""The paper's three methods on a known order (Amigoni et al. 2006, Sec. IV): sequential, tree and
pivot merging, and pivot leaving out a map it cannot integrate."""

from __future__ import annotations

import pytest
from test_link_graph import (
    CONFIG,
    TOLERANCE_M,
    TOLERANCE_RAD,
    in_own_frames,
    pose_error,
    random_frames,
    stranger_map,
    world_maps,
)

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging import (
    merge_pivot,
    merge_sequential,
    merge_tree,
)


@pytest.mark.parametrize(
    ("method", "integrations", "placed"),
    [(merge_sequential, 3, 3), (merge_tree, 6, 3), (merge_pivot, 3, 4)],
)
def test_the_three_methods_on_a_known_order(method: object, integrations: int, placed: int) -> None:
    """Pivot places every map; sequential and tree (the paper's IV-A, IV-B) integrate a
    small map with a large one, or large maps full of duplicates, and leave one out here
    (the problems the paper names) but never place one wrongly."""
    frames = random_frames(4, seed=6)
    maps = list(in_own_frames(world_maps("office", 4), frames, list("abcd")).values())
    result = method(maps, CONFIG)  # type: ignore[operator]
    assert result.integrations == integrations
    assert sum(pose is not None for pose in result.placements) >= placed
    for k, pose in enumerate(result.placements):
        if pose is None:
            continue
        error, turn = pose_error(se2.invert(frames[0]) @ frames[k], pose)
        assert error < TOLERANCE_M and turn < TOLERANCE_RAD, (result.method, k, error, turn)


def test_pivot_leaves_out_a_map_it_cannot_integrate_and_goes_on() -> None:
    frames = random_frames(4, seed=7)
    office = world_maps("office", 3)
    maps = list(
        in_own_frames((office[0], stranger_map(), *office[1:]), frames, list("abcd")).values()
    )
    result = merge_pivot(maps, CONFIG)
    assert result.placements[1] is None
    for k in (2, 3):
        pose = result.placements[k]
        assert pose is not None
        error, turn = pose_error(se2.invert(frames[0]) @ frames[k], pose)
        assert error < TOLERANCE_M and turn < TOLERANCE_RAD
