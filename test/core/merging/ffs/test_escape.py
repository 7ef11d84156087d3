"""Weak bodies brought out of a wrong minimum together (core/merging/ffs/escape.py, issue 51),
with known answers on the synthetic building of `test_far.py`: two views turned together far
beyond the re-seating fan stay in a wrong minimum after the rounds and come back with the
escape pass; the map at its answer is left as the rounds leave it."""

from __future__ import annotations

import numpy as np
from test_far import VIEWS, building_bodies

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.ffs import FfsConfig
from multi_robot_mapper.core.merging.ffs.escape import depth, run_ffs_escaped, weak_groups
from multi_robot_mapper.core.merging.ffs.reseat import run_ffs_reseated, seated

CONFIG = FfsConfig(sigma_start=0.15, time_budget=0.0, max_iterations=300)
FIXED = np.arange(len(VIEWS)) == 0
# Views 3 and 4 turned -45 deg together about view 4's sensor and moved 0.4 m.
TURNED = seated(VIEWS, np.array([3, 4]), 4, (np.radians(-45.0), 0.4, 0.0))


def _deviation(poses: np.ndarray) -> tuple[float, float]:
    metres = float(np.hypot(*(poses[:, :2] - VIEWS[:, :2]).T).max())
    degrees = float(np.degrees(np.abs(se2.wrap_angle(poses[:, 2] - VIEWS[:, 2]))).max())
    return metres, degrees


def test_the_rounds_leave_the_pair_in_a_wrong_minimum_of_two_weak_bodies() -> None:
    bodies = building_bodies(CONFIG)
    rounds = run_ffs_reseated(bodies, TURNED, CONFIG, fixed=FIXED)
    metres, _ = _deviation(rounds.poses)
    measured = depth(bodies, rounds.poses, CONFIG)
    assert metres > 0.5
    assert [list(group) for group in weak_groups(measured, ~FIXED)] == [[3, 4]]
    assert measured.total < depth(bodies, VIEWS, CONFIG).total


def test_the_escape_pass_brings_the_pair_back() -> None:
    result = run_ffs_escaped(building_bodies(CONFIG), TURNED, CONFIG, fixed=FIXED)
    metres, degrees = _deviation(result.poses)
    assert metres <= 0.01 and degrees <= 0.5, (metres, degrees)
    assert result.iterations == len(result.potentials)


def test_the_map_at_its_answer_is_left_as_the_rounds_leave_it() -> None:
    bodies = building_bodies(CONFIG)
    rounds = run_ffs_reseated(bodies, VIEWS, CONFIG, fixed=FIXED)
    escaped = run_ffs_escaped(bodies, VIEWS, CONFIG, fixed=FIXED)
    assert weak_groups(depth(bodies, rounds.poses, CONFIG), ~FIXED) == []
    assert np.array_equal(escaped.poses, rounds.poses)
    assert escaped.iterations == rounds.iterations
