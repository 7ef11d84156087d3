"""Held scans (core/local_mapping/held.py): a held scan follows the one before it only when a
confident match places it where the robot can have driven in the time between them."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.held import HeldScan, follow_match
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.core.worlds import WORLDS

CONFIG = LocalMapperConfig()  # plausible_speed 3 m/s: a reach of 3 m/s x elapsed + 0.3 m
LASER = LaserModel(beams=361, range_noise=0.005, dropout=0.0)
FIRST, SECOND = (8.0, 3.0, 0.3), (8.7, 3.2, 0.45)  # 0.73 m apart in the office


def held(world: str, pose: tuple[float, float, float], stamp: float, seed: int) -> HeldScan:
    view = simulate_scan(WORLDS[world](), pose, LASER, np.random.default_rng(seed))
    return HeldScan(stamp, extract_scan(view, ExtractionConfig())[0].segments, view)


def test_a_held_scan_follows_the_one_before_only_within_the_robots_reach() -> None:
    previous = held("office", FIRST, 10.0, seed=0)
    # 1 s later the robot can have driven 3.3 m: it follows, placed where it is.
    result = follow_match(CONFIG, previous, held("office", SECOND, 11.0, seed=1), None)
    assert result is not None
    T_1_2 = se2.invert(se2.matrix_from_pose(*FIRST)) @ se2.matrix_from_pose(*SECOND)
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
    assert np.hypot(dx, dy) < 0.03 and abs(dtheta) < np.radians(0.5)
    # 0.1 s later, 0.6 m at 3 m/s: the same match is too far...
    soon = held("office", SECOND, 10.1, seed=1)
    assert follow_match(CONFIG, previous, soon, None) is None
    assert follow_match(CONFIG, previous, soon, top_speed=1.0) is None  # a slower robot too
    # ... unless the robot is known to drive faster (5 m/s: 0.8 m).
    assert follow_match(CONFIG, previous, soon, top_speed=5.0) is not None
    # A scan stamped before the held one had no time at all (0.3 m).
    assert follow_match(CONFIG, previous, held("office", SECOND, 9.0, seed=1), None) is None


def test_a_scan_of_another_building_never_follows() -> None:
    previous = held("office", FIRST, 10.0, seed=0)
    stranger = held("corridors", (16.0, 8.0, np.pi / 2), 20.0, seed=2)
    assert follow_match(CONFIG, previous, stranger, top_speed=100.0) is None
