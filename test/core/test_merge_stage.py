"""A robot's map in its own frame after an offline run (core/merge_stage.py), on hand-made runs:
a ``local`` run's segments of the robot; after a merge, its main piece's keyframes placed at
their poses, the main piece being the one holding most of its placed scans."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merge_stage import own_frame_map
from multi_robot_mapper.core.offline import OfflineMap

WALL = np.array([[1.0, 0.0, 1.0, 2.0]])


def run(**fields: object) -> OfflineMap:
    segments = np.array([[0.0, 0.0, 1.0, 0.0], [5.0, 5.0, 6.0, 5.0], [0.0, 1.0, 0.0, 2.0]])
    made = OfflineMap(
        robots=["a", "b"],
        map_segments=segments,
        segment_robot=np.array([0, 1, 0]),
        trajectories={},
        robot_frames={"a": None, "b": None},
        stats={},
    )
    for name, value in fields.items():
        setattr(made, name, value)
    return made


def test_a_local_run_gives_the_robots_own_segments() -> None:
    np.testing.assert_array_equal(own_frame_map(run(), "a"), [[0, 0, 1, 0], [0, 1, 0, 2]])
    np.testing.assert_array_equal(own_frame_map(run(), "b"), [[5, 5, 6, 5]])


def test_after_a_merge_the_main_piece_is_placed_at_its_keyframes() -> None:
    keyframes = [
        Keyframe(0, 0.0, np.array([0.0, 0.0, 0.0]), WALL),
        Keyframe(1, 1.0, np.array([10.0, 0.0, np.pi / 2]), WALL),  # (1, 0)-(1, 2) turned
        Keyframe(2, 2.0, np.array([0.0, 0.0, 0.0]), np.zeros((0, 4))),  # owns no wall
        Keyframe(5, 5.0, np.array([3.0, 3.0, 0.0]), WALL, piece=5),
        Keyframe(6, 6.0, np.array([4.0, 3.0, 0.0]), WALL, piece=5),
    ]
    # Scans placed from keyframes 0, 5, 6, 6: the second piece holds most, it is the main one.
    anchors = {"a": (np.arange(4.0), np.array([0, 5, 6, 6]), np.zeros((4, 3)))}
    merged = run(merge_result=object(), keyframes={"a": keyframes}, anchors=anchors)
    np.testing.assert_allclose(own_frame_map(merged, "a"), [[4, 3, 4, 5], [5, 3, 5, 5]])
    # Most scans placed from the first piece: it is the main one, its empty keyframe skipped.
    anchors = {"a": (np.arange(3.0), np.array([0, 1, 6]), np.zeros((3, 3)))}
    merged = run(merge_result=object(), keyframes={"a": keyframes}, anchors=anchors)
    np.testing.assert_allclose(
        own_frame_map(merged, "a"), [[1, 0, 1, 2], [10, 1, 8, 1]], atol=1e-12
    )
    # A robot without keyframes: nothing.
    assert own_frame_map(merged, "b").shape == (0, 4)
