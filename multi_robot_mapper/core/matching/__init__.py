"""Pipeline stage 2: how two segment sets fit together, with no initial guess (INTEGRATE).

Amigoni, Gasparini & Gini 2006, Sec. III: angles between pairs of segments are geometric
landmarks; every rototranslation that superimposes an angle of S2 on an equal angle of S1 is a
hypothesis (Algorithm 2, with the heuristics of III-A that choose which angles); each
hypothesis is scored by the overlap length of matching segments (Algorithm 4). Then, beyond
the paper: the best few distinct hypotheses are refined by point-to-line least squares (Cox,
as in Wolter 5.1), corridor-like ones are also slid along their free direction, and the
winner is the one the two scans' beams agree with best (overlap, minus what one scan saw
through, plus what its beams confirm). Overlap alone cannot tell a corridor's true motion from
standing still, nor a scan from its mirror image behind the robot.

All of it is array code: landmarks x landmarks for hypotheses, and hypotheses x segments x
segments for the evaluation, restricted early to the nearly parallel triples that can score
and, with many hypotheses, to the few that a cheap prescreen on the longest segments ranks
best. Transforms are ``(theta, tx, ty)`` rows: ``T_1_2`` maps S2 coordinates into S1's frame.

Modules, in the order INTEGRATE runs them: ``config`` (IntegrateConfig), ``hypotheses``
(landmarks and hypotheses, Alg. 2), ``scoring`` (Alg. 4 values, refusal, prescreen),
``refine`` (Cox least squares), ``beams`` (free space), ``ranking`` (the distinct candidates,
their net scores, slides along corridors), ``integrate`` (Alg. 1, the whole match: it unpacks
its config into the few numbers each step takes).
"""

from multi_robot_mapper.core.geometry import Lines, lines_of, sample_segments
from multi_robot_mapper.core.matching.beams import seen_through, seen_through_many
from multi_robot_mapper.core.matching.config import IntegrateConfig
from multi_robot_mapper.core.matching.hypotheses import (
    HEURISTICS,
    Landmarks,
    distinct_hypotheses,
    endpoint_hypotheses,
    hypotheses,
    landmarks,
)
from multi_robot_mapper.core.matching.integrate import MatchResult, integrate
from multi_robot_mapper.core.matching.refine import refine, refine_many
from multi_robot_mapper.core.matching.scoring import (
    PairScores,
    PairTolerance,
    best_prescreened,
    cross_support,
    pair_tolerance,
    refusal,
    refused,
    score_pairs,
    transform_values,
)

__all__ = [
    "HEURISTICS",
    "IntegrateConfig",
    "Landmarks",
    "Lines",
    "MatchResult",
    "PairScores",
    "PairTolerance",
    "best_prescreened",
    "cross_support",
    "distinct_hypotheses",
    "endpoint_hypotheses",
    "hypotheses",
    "integrate",
    "landmarks",
    "lines_of",
    "pair_tolerance",
    "refine",
    "refine_many",
    "refusal",
    "refused",
    "sample_segments",
    "score_pairs",
    "seen_through",
    "seen_through_many",
    "transform_values",
]
