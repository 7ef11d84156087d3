"""INTEGRATE's choice among its hypotheses (core/matching/ranking.py): the best distinct
hypotheses, best first, near-duplicates and worthless ones left out."""

from __future__ import annotations

import numpy as np

from multi_robot_mapper.core.matching import IntegrateConfig
from multi_robot_mapper.core.matching.ranking import CandidateChoice, distinct_candidates
from multi_robot_mapper.core.matching.scoring import refusal
from multi_robot_mapper.core.segment_map import SegmentMap

CONFIG = IntegrateConfig()


def test_distinct_candidates_are_apart() -> None:
    transforms = np.array(
        [[0.0, 0.0, 0.0], [0.01, 0.05, 0.0], [0.0, 1.0, 0.0], [np.pi, 0.0, 0.0], [0.0, 1.1, 0.0]]
    )
    values = np.array([5.0, 4.0, 3.0, 2.0, 1.0])
    choice = CandidateChoice(
        CONFIG.candidate_pool, 10, CONFIG.candidate_separation, CONFIG.candidate_angle_separation
    )
    empty = SegmentMap.of(np.zeros((0, 4)))
    picked = distinct_candidates(empty, empty, transforms, values, choice, refusal(CONFIG))
    assert list(picked) == [0, 2, 3]


def test_only_valued_hypotheses_of_the_pool_are_kept_best_first_up_to_the_count() -> None:
    # Four hypotheses metres apart: those valued 0 or less are never candidates, the rest come
    # best first, at most ``kept`` of the ``pool`` best valued.
    transforms = np.array([[0.0, 0.0, 0.0], [0.0, 5.0, 0.0], [0.0, 10.0, 0.0], [0.0, 15.0, 0.0]])
    values = np.array([3.0, 0.0, -1.0, 4.0])
    empty = SegmentMap.of(np.zeros((0, 4)))

    def picked(pool: int, kept: int) -> list[int]:
        choice = CandidateChoice(pool, kept, 0.5, 0.1)
        found = distinct_candidates(empty, empty, transforms, values, choice, refusal(CONFIG))
        return found.tolist()

    assert picked(10, 10) == [3, 0]
    assert picked(10, 1) == [3]
    assert picked(1, 10) == [3]
    assert picked(10, 0) == []
    choice = CandidateChoice(10, 10, 0.5, 0.1)
    nothing = distinct_candidates(
        empty, empty, transforms, -np.abs(values), choice, refusal(CONFIG)
    )
    assert nothing.size == 0
