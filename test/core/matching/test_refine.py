"""Cox point-to-line refinement of hypotheses, with known answers."""

from __future__ import annotations

import dataclasses

import numpy as np
from test_integrate import CONFIG, ROOM

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching import (
    refine,
    refine_many,
)
from multi_robot_mapper.core.matching.scoring import pair_tolerance


def test_refinement_pulls_several_hypotheses_at_once() -> None:
    T_1_2 = np.array([0.4, 1.0, -0.5])
    moved = se2.transform_segments(
        se2.invert(se2.matrix_from_pose(T_1_2[1], T_1_2[2], T_1_2[0])), ROOM
    )
    start = T_1_2 + np.array([[0.02, 0.05, -0.04], [-0.015, -0.06, 0.03], [0.0, 0.0, 0.0]])
    refined = refine_many(ROOM, moved, start, pair_tolerance(CONFIG), CONFIG.refine_iterations)
    np.testing.assert_allclose(refined, np.tile(T_1_2, (3, 1)), atol=1e-4)
    # refine() is the one-hypothesis case.
    np.testing.assert_allclose(
        refine(ROOM, moved, start[0], pair_tolerance(CONFIG), CONFIG.refine_iterations),
        T_1_2,
        atol=1e-4,
    )


def test_no_refinement_leaves_hypotheses_unchanged() -> None:
    start = np.array([[0.1, 0.2, 0.3], [1.0, -1.0, 2.0]])
    config = dataclasses.replace(CONFIG, refine_iterations=0)
    np.testing.assert_array_equal(
        refine_many(ROOM, ROOM, start, pair_tolerance(config), config.refine_iterations), start
    )
