"""The joint merge's global map (core/merging/global_map.py): every keyframe's segments at its
optimised pose, fused map by map, and fused again only from the first map that changed."""

from __future__ import annotations

import numpy as np
from test_consistency import line_units

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging import MergeConfig, global_map
from multi_robot_mapper.core.merging.global_map import fuse_keyframes
from multi_robot_mapper.core.merging.places import units_of

CONFIG = MergeConfig()


def _scene() -> tuple[list[str], dict, list, dict]:
    """Three robots in one corridor, each map placed at its true frame."""
    names = ["a", "b", "c"]
    frames = [
        se2.matrix_from_pose(*p) for p in ((0.0, 0.0, 0.0), (2.0, 0.3, 0.1), (4.0, -0.2, -0.1))
    ]
    units = units_of(line_units(names, frames))
    order = [(n, 0) for n in names]
    poses = {
        (n, 0): np.array(
            [se2.pose_from_matrix(T @ se2.matrix_from_pose(*p)) for p in units[(n, 0)].poses]
        )
        for n, T in zip(names, frames, strict=True)
    }
    return names, units, order, poses


CACHE = global_map.FusionCache()


def _fresh(names, units, order, poses):  # type: ignore[no-untyped-def]
    CACHE.last = None
    return fuse_keyframes(names, units, order, poses, CONFIG, CACHE)


def test_keyframes_fused_at_their_poses_cover_the_corridor_once() -> None:
    names, units, order, poses = _scene()
    segments, robot, keyframe = _fresh(names, units, order, poses)
    # Both walls of the corridor, fused across the three robots' keyframes: every segment
    # lies on y = +1 or y = -1 in map, and each is owned by a keyframe of some robot.
    assert len(segments) > 0
    np.testing.assert_allclose(np.abs(segments[:, [1, 3]]), 1.0, atol=1e-6)
    assert set(robot.tolist()) <= {0, 1, 2} and len(keyframe) == len(segments)


def test_an_update_reuses_the_fusion_of_unchanged_maps_and_fuses_the_rest_again() -> None:
    names, units, order, poses = _scene()
    first = _fresh(names, units, order, poses)
    cached = CACHE.last
    assert cached is not None
    # The same maps, keyframes moved by far less than a millimetre: the result is reused.
    nudged = {k: v + np.array([1e-5, -1e-5, 1e-6]) for k, v in poses.items()}
    again = fuse_keyframes(names, units, order, nudged, CONFIG, CACHE)
    assert again[0] is cached[2][-1].segments
    for got, want in zip(again, first, strict=True):
        np.testing.assert_array_equal(got, want)
    # The last map moved by 5 cm: the first two maps' fusion is reused, the last fused again,
    # and the result is what a fusion from nothing gives.
    moved = dict(poses)
    moved[order[-1]] = poses[order[-1]] + np.array([0.05, 0.0, 0.0])
    update = fuse_keyframes(names, units, order, moved, CONFIG, CACHE)
    assert CACHE.last is not None
    assert CACHE.last[2][1] is cached[2][1]
    assert CACHE.last[2][2] is not cached[2][2]
    for got, want in zip(update, _fresh(names, units, order, moved), strict=True):
        np.testing.assert_allclose(got, want)
    # A keyframe turned by 3 mrad barely moves, but its walls 1.1 m away move by 3.4 mm:
    # within a quarter of fusion_tolerance (12.5 mm), reused. Turned by 20 mrad they move
    # 22 mm: that map is fused again.
    for turn, reused in ((0.003, True), (0.02, False)):
        fuse_keyframes(names, units, order, moved, CONFIG, CACHE)
        kept = CACHE.last
        turned = dict(moved)
        turned[order[-1]] = moved[order[-1]] + np.array([0.0, 0.0, turn])
        fuse_keyframes(names, units, order, turned, CONFIG, CACHE)
        assert (CACHE.last[2][2] is kept[2][2]) is reused  # type: ignore[index]
    # Another config, or another set of robots: nothing is reused.
    fuse_keyframes(names, units, order, moved, CONFIG, CACHE)
    kept = CACHE.last
    other = fuse_keyframes(names, units, order, moved, MergeConfig(fusion_tolerance=0.04), CACHE)
    assert CACHE.last[2][0] is not kept[2][0]  # type: ignore[index]
    assert len(other[0]) > 0
