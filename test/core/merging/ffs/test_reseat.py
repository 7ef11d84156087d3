"""Reseating a turned body (issue 51) with known answers: a body in place is not moved, a turned
one is brought back within the fan's step."""

from __future__ import annotations

import numpy as np
from test_far import VIEWS, building_bodies

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.ffs import FfsConfig
from multi_robot_mapper.core.merging.ffs.bodies import placed
from multi_robot_mapper.core.merging.ffs.far import coarser
from multi_robot_mapper.core.merging.ffs.reseat import (
    _CELL,
    _SHIFT_STEP,
    _WIDTH,
    BODY_FAN,
    _channels,
    _field,
    fan_scores,
    reseat,
    run_ffs_reseated,
)

# View 3 turned 25 deg about its sensor and moved 12 cm: further than a narrow field reaches.
TURNED = VIEWS.copy()
TURNED[3] += [0.12, -0.08, np.radians(25.0)]


def _free() -> np.ndarray:
    free = np.ones(len(VIEWS), dtype=bool)
    free[0] = False
    return free


def test_a_body_in_place_is_not_moved() -> None:
    moved, count = reseat(building_bodies(FfsConfig()), VIEWS, _free(), BODY_FAN, 1)
    assert count == 0 and np.array_equal(moved, VIEWS)


def test_the_turned_body_alone_is_reseated_within_the_fans_step() -> None:
    moved, count = reseat(building_bodies(FfsConfig()), TURNED, _free(), BODY_FAN, 1)
    assert count == 1
    assert np.array_equal(np.delete(moved, 3, axis=0), np.delete(TURNED, 3, axis=0))
    assert np.hypot(*(moved[3, :2] - VIEWS[3, :2])) <= 0.15
    assert abs(se2.wrap_angle(moved[3, 2] - VIEWS[3, 2])) <= np.radians(3.0)


def test_the_run_with_reseating_brings_the_turned_body_back() -> None:
    fixed = ~_free()
    config = FfsConfig(sigma_start=0.10, time_budget=0.0, max_iterations=300)
    result = run_ffs_reseated(building_bodies(config), TURNED, config, fixed=fixed)
    metres = np.hypot(*(result.poses[:, :2] - VIEWS[:, :2]).T).max()
    degrees = np.degrees(np.abs(se2.wrap_angle(result.poses[:, 2] - VIEWS[:, 2]))).max()
    assert result.iterations == len(result.potentials)
    assert metres <= 0.01 and degrees <= 0.5, (metres, degrees)


def test_fan_scores_are_the_four_channel_potential_at_every_pose() -> None:
    """Two look-ups per point (the channels a face has a share in) give the potential summed
    over all four channels, the module's definition, at every turn and shift of the fan."""
    level = coarser(building_bodies(FfsConfig()), _SHIFT_STEP)
    points, directions = placed(level, TURNED)
    own = level.body == 3
    centre = TURNED[3, :2].copy()
    scores = fan_scores(level, (points, directions), own, centre, BODY_FAN)
    arm = points[own] - centre
    cos, sin = np.cos(BODY_FAN.turns), np.sin(BODY_FAN.turns)
    rotations = [np.array([[c, -s], [s, c]]) for c, s in zip(cos, sin, strict=True)]
    every = np.vstack([arm @ rotation.T + centre for rotation in rotations])
    # The same window and cells as fan_scores': the fan's reach about every turned point.
    reach = 4 * _SHIFT_STEP + 3.0 * _WIDTH
    lo = every.min(axis=0) - reach
    size = np.ceil((every.max(axis=0) + reach - lo) / _CELL).astype(int) + 1
    field = _field(points[~own], directions[~own], level.masses[~own], lo, (size[0], size[1]))
    expected = np.zeros_like(scores)
    for t, rotation in enumerate(rotations):
        turned = arm @ rotation.T + centre
        shares = _channels(directions[own] @ rotation.T) * level.masses[own][:, None]
        for a, dx in enumerate(BODY_FAN.shifts):
            for b, dy in enumerate(BODY_FAN.shifts):
                cells = np.floor((turned - lo) / _CELL).astype(int) + 3 * np.array([dx, dy])
                expected[t, a, b] = np.sum(field[:, cells[:, 0], cells[:, 1]].T * shares)
    assert np.unravel_index(np.argmax(scores), scores.shape) == np.unravel_index(
        np.argmax(expected), expected.shape
    )
    assert np.allclose(scores, expected, rtol=1e-9)
