"""The motion prior of tracking (issue 47 item 5): the direction a match cannot observe, taken
from its point-to-line Hessian; the prior weighed along it only (the robot's recent motion:
test/core/local_mapping/test_motion.py)."""

from __future__ import annotations

import numpy as np
import pytest

from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.matching import IntegrateConfig, integrate
from multi_robot_mapper.core.matching.prior import (
    DECISIVE_SIGMA,
    MotionPrior,
    prior_support,
    weakest_directions,
)
from multi_robot_mapper.core.matching.refine import normal_equations, refine_many
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan

CONFIG = IntegrateConfig()
LASER = LaserModel(beams=361, range_noise=0.005, dropout=0.0, range_max=20.0)
# A 2.4 m wide corridor along x, 60 m long: its ends beyond the laser's reach.
CORRIDOR = np.array([[-30.0, -1.2, 30.0, -1.2], [-30.0, 1.2, 30.0, 1.2]])
ROOM = np.array(
    [[-3.0, -2.0, 3.0, -2.0], [3.0, -2.0, 3.0, 2.0], [3.0, 2.0, -3.0, 2.0], [-3.0, 2.0, -3.0, -2.0]]
)


def _scans(world: np.ndarray, moved: float, seed: int = 3) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    first = simulate_scan(world, (0.0, 0.0, 0.0), LASER, rng)
    second = simulate_scan(world, (moved, 0.1, 0.0), LASER, rng)
    return (
        first,
        second,
        *(extract_scan(s, ExtractionConfig())[0].segments for s in (first, second)),
    )


def test_the_weakest_direction_of_a_corridor_match_is_along_it() -> None:
    _, _, s1, s2 = _scans(CORRIDOR, 0.5)
    H, _ = normal_equations(s1, s2, np.array([[0.0, 0.5, 0.1]]), pair_tolerance(CONFIG))
    u, weakest = weakest_directions(H)
    assert abs(u[0, 0]) == pytest.approx(1.0, abs=1e-3)  # along x
    assert weakest[0] < 1e-6 < np.trace(H[0])


def test_the_prior_decides_the_corridor_offset_and_the_walls_the_rest() -> None:
    # Refined from 0.3 m ahead along the corridor and 0.15 m across it: without a prior the
    # offset along stays where it started (nothing observes it), the walls fix the one across;
    # with a prior at the truth, the offset along goes to the prior.
    _, _, s1, s2 = _scans(CORRIDOR, 0.5)
    start = np.array([[0.0, 0.8, 0.25]])
    alone = refine_many(s1, s2, start, pair_tolerance(CONFIG), CONFIG.refine_iterations)[0]
    prior = MotionPrior(np.array([0.0, 0.5, 0.0]), prior_support(0.01, 0.05) or 0.0, 0.05)
    pulled = refine_many(s1, s2, start, pair_tolerance(CONFIG), CONFIG.refine_iterations, prior)[0]
    assert alone[1] == pytest.approx(0.8, abs=0.01)
    assert alone[2] == pytest.approx(0.1, abs=0.01) and pulled[2] == pytest.approx(0.1, abs=0.01)
    assert pulled[1] == pytest.approx(0.5, abs=0.01)
    # The prior's own across-corridor guess (0.0) is not weighed: the walls observe that way.


def test_where_the_walls_observe_every_direction_the_prior_is_not_weighed() -> None:
    _, _, s1, s2 = _scans(ROOM, 0.5)
    start = np.array([[0.0, 0.6, 0.15]])
    wrong_prior = MotionPrior(np.array([0.0, 1.5, 1.0]), 100.0, 0.05)
    alone = refine_many(s1, s2, start, pair_tolerance(CONFIG), CONFIG.refine_iterations)[0]
    with_prior = refine_many(
        s1, s2, start, pair_tolerance(CONFIG), CONFIG.refine_iterations, wrong_prior
    )[0]
    np.testing.assert_allclose(with_prior, alone, atol=1e-9)
    assert alone[1:] == pytest.approx([0.5, 0.1], abs=0.01)


def test_a_corridor_match_with_a_decisive_prior_is_confident_where_the_prior_puts_it() -> None:
    first, second, s1, s2 = _scans(CORRIDOR, 0.5)
    guess = np.array([[0.0, 0.52, 0.1]])
    blind = integrate(s1, s2, CONFIG, heuristics=(), extra_hypotheses=guess, views=(first, second))
    prior = MotionPrior(guess[0], prior_support(0.01, 0.05) or 0.0, 0.05)
    tracked = integrate(
        s1, s2, CONFIG, heuristics=(), extra_hypotheses=guess, views=(first, second), prior=prior
    )
    assert blind.confidence < 0.5  # the corridor fits everywhere along it
    assert tracked.T_1_2[1:] == pytest.approx([0.52, 0.1], abs=0.02)
    assert tracked.confidence > 0.9
    assert tracked.evidence is not None and tracked.evidence.support < 0.1  # the walls' own
    assert tracked.evidence.prior_support > 1.0


def test_a_prior_is_decisive_only_within_a_third_of_the_tolerance() -> None:
    assert prior_support(DECISIVE_SIGMA * 1.01, 0.05) is None
    assert prior_support(0.0, 0.05) is None
    assert prior_support(0.05, 0.05) == pytest.approx(1.0)  # worth a metre of wall
    assert prior_support(0.025, 0.05) == pytest.approx(4.0)
