"""The local map a scan is tracked against (issue 47 item 5): the last keyframe and those before
it, fused in the last keyframe's frame, made again only when they change."""

from __future__ import annotations

import dataclasses

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeScan
from multi_robot_mapper.core.local_mapping.local_map import LocalMaps
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan

# An L-shaped corridor driven along its first leg: each keyframe's laser looks ahead.
WALLS = np.array(
    [
        [-2.0, -1.0, 8.0, -1.0],
        [-2.0, 1.0, 6.0, 1.0],
        [6.0, 1.0, 6.0, 8.0],
        [8.0, -1.0, 8.0, 8.0],
        [-2.0, -1.0, -2.0, 1.0],
    ]
)
CONFIG = LocalMapperConfig(local_map_keyframes=3, fusion_tolerance=0.05)


@dataclasses.dataclass(frozen=True)
class _Known:
    poses: dict[int, tuple[float, float, float]]
    scans: dict[int, KeyframeScan]


POSES = {0: (0.0, 0.0, 0.0), 1: (2.0, 0.0, 0.1), 2: (4.0, 0.1, -0.05)}


def _keyframes() -> dict[int, KeyframeScan]:
    rng = np.random.default_rng(5)
    laser = LaserModel(beams=361, range_noise=0.005, dropout=0.0)
    scans = {}
    for k, pose in POSES.items():
        view = simulate_scan(WALLS, pose, laser, rng)
        scans[k] = KeyframeScan(
            k, float(k), extract_scan(view, ExtractionConfig())[0].segments, view
        )
    return scans


def _distance_to_walls(points: np.ndarray) -> np.ndarray:
    a, b = WALLS[:, :2], WALLS[:, 2:]
    ab = b - a
    t = np.clip(np.einsum("pwk,wk->pw", points[:, None, :] - a, ab) / np.sum(ab**2, 1), 0, 1)
    nearest = a[None] + t[..., None] * ab[None]
    return np.asarray(np.min(np.linalg.norm(points[:, None, :] - nearest, axis=2), axis=1))


def test_the_local_map_lies_on_the_walls_in_the_last_keyframes_frame() -> None:
    scans = _keyframes()
    local = LocalMaps().around(2, [1, 0], _Known(POSES, scans), CONFIG)
    assert local is not None and local.keyframe == 2
    T_world_last = se2.matrix_from_pose(*POSES[2])
    ends = se2.transform_segments(T_world_last, local.segments).reshape(-1, 2)
    assert np.percentile(_distance_to_walls(ends), 95) < 0.03
    # The walls behind the last keyframe's laser (x < 3.5: it looks forward, 180 degrees):
    # seen by the older keyframes only, yet in the map.
    assert (ends[:, 0] < 3.5).any()
    # Each keyframe's laser, where it stood in the last keyframe's frame.
    stood = [se2.pose_from_matrix(T_world_last @ v.T_set_laser) for v in local.viewpoints]
    np.testing.assert_allclose(stood, [POSES[k] for k in (0, 1, 2)], atol=1e-9)


def test_the_local_map_is_made_again_only_when_its_keyframes_move() -> None:
    scans = _keyframes()
    maps = LocalMaps()
    first = maps.around(2, [1, 0], _Known(POSES, scans), CONFIG)
    assert maps.around(2, [1, 0], _Known(dict(POSES), scans), CONFIG) is first
    moved = dict(POSES) | {0: (0.0, 0.05, 0.0)}  # an optimisation moved a keyframe
    assert maps.around(2, [1, 0], _Known(moved, scans), CONFIG) is not first
    assert maps.around(2, [], _Known(POSES, scans), CONFIG) is None  # the keyframe alone
