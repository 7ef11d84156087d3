"""The keyframe map (core/local_mapping/keyframe_map.py): a wall seen again from another
keyframe stays one wall, owned by the oldest; keyframes carry their walls when they move; a
joined piece is expressed in the kept piece's frame; pieces never fuse until joined."""

from __future__ import annotations

import numpy as np
import pytest

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeMap, KeyframeScan
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.scan import LaserScanData

CONFIG = LocalMapperConfig()
VIEW = LaserScanData(np.full(3, 5.0), -0.1, 0.1, 0.1, 0.1, 30.0)  # unused by the map
WALL = np.array([[0.0, 1.0, 4.0, 1.0]])  # in the frame of a keyframe at the origin


def empty() -> KeyframeMap:
    return KeyframeMap(
        pair_tolerance(CONFIG.integrate), CONFIG.fusion_tolerance, CONFIG.fusion_radius
    )


def add(keyframes: KeyframeMap, pose: tuple[float, float, float], piece: int) -> int:
    """A keyframe at ``pose`` that sees WALL (given in the frame at the origin)."""
    index = len(keyframes)
    seen = se2.transform_segments(se2.invert(se2.matrix_from_pose(*pose)), WALL)
    keyframes.add(KeyframeScan(index, float(index), seen, VIEW), pose, piece)
    keyframes.fuse(index)
    return index


def test_a_wall_seen_again_stays_one_wall_owned_by_the_oldest_keyframe() -> None:
    keyframes = empty()
    add(keyframes, (0.0, 0.0, 0.0), 0)
    add(keyframes, (1.0, 0.0, 0.3), 0)  # turned and moved: the same wall in another frame
    np.testing.assert_allclose(keyframes.map_segments(0), WALL, atol=1e-9)
    owned = [len(kf.segments) for kf in keyframes.keyframes()]
    assert owned == [1, 0]
    assert keyframes.take_changed() == [0, 1] and keyframes.take_changed() == []


def test_a_moved_keyframe_carries_its_walls() -> None:
    keyframes = empty()
    add(keyframes, (0.0, 0.0, 0.0), 0)
    keyframes.take_changed()
    keyframes.set_poses({0: (2.0, -1.0, np.pi / 2)})
    expected = se2.transform_segments(se2.matrix_from_pose(2.0, -1.0, np.pi / 2), WALL)
    np.testing.assert_allclose(keyframes.map_segments(), expected, atol=1e-9)
    assert keyframes.take_changed() == [0]
    keyframes.set_poses({0: (2.0, -1.0, np.pi / 2)})  # the same pose: nothing changed
    assert keyframes.take_changed() == []


def test_pieces_do_not_fuse_until_joined_then_share_the_kept_frame() -> None:
    keyframes = empty()
    add(keyframes, (0.0, 0.0, 0.0), 0)
    # A new piece, its frame its first keyframe: the same wall, in that frame, stays apart.
    T_kept_moved = se2.matrix_from_pose(1.0, 0.0, 0.0)
    keyframes.add(KeyframeScan(1, 1.0, WALL - [1.0, 0.0, 1.0, 0.0], VIEW), (0.0, 0.0, 0.0), 1)
    keyframes.fuse(1)
    assert len(keyframes.map_segments(0)) == len(keyframes.map_segments(1)) == 1
    keyframes.join(1, 0, T_kept_moved)
    assert keyframes.pieces.tolist() == [0, 0] and keyframes.members(1).size == 0
    np.testing.assert_allclose(keyframes.pose(1), (1.0, 0.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(keyframes.map_segments(0), np.vstack((WALL, WALL)), atol=1e-9)


def test_near_keyframes_come_nearest_first_within_their_piece() -> None:
    keyframes = empty()
    for pose, piece in [((0, 0, 0), 0), ((3, 0, 0), 0), ((1, 0, 0), 0), ((0.5, 0, 0), 4)]:
        keyframes.add(KeyframeScan(len(keyframes), 0.0, WALL, VIEW), pose, piece)
    assert keyframes.near((0.0, 0.0, 0.0), 0, 2.0).tolist() == [0, 2]
    assert keyframes.near((2.9, 0.0, 0.0), 0, 10.0).tolist() == [1, 2, 0]
    assert keyframes.near((2.9, 0.0, 0.0), 0, 10.0, before=2).tolist() == [1, 0]
    assert keyframes.near((0.0, 0.0, 0.0), 4, 1.0).tolist() == [3]


def test_a_keyframe_is_added_only_with_the_next_index() -> None:
    keyframes = empty()
    with pytest.raises(ValueError, match="keyframe 1 added as keyframe 0"):
        keyframes.add(KeyframeScan(1, 0.0, WALL, VIEW), (0.0, 0.0, 0.0), 0)
    assert len(keyframes) == 0
