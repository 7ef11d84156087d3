"""INTEGRATE (Amigoni Alg. 1): hypotheses, pruned evaluation, refinement, validity."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import sample_segments
from multi_robot_mapper.core.matching.beams import (
    BeamAgreement,
    ViewReturns,
    Views,
    beam_agreement,
    beam_limits,
    seen_through_many,
    viewpoints_of,
)
from multi_robot_mapper.core.matching.confidence import (
    RIGHT_ANGLE,
    RIGHT_DISTANCE,
    MatchEvidence,
    confidence,
)
from multi_robot_mapper.core.matching.config import IntegrateConfig
from multi_robot_mapper.core.matching.hypotheses import (
    HEURISTICS,
    LandmarkSettings,
    distinct_hypotheses,
    endpoint_hypotheses,
    hypotheses,
    landmark_settings,
    landmarks,
)
from multi_robot_mapper.core.matching.prior import (
    MotionPrior,
    excluded_by,
    support_with_prior,
)
from multi_robot_mapper.core.matching.ranking import (
    CandidateChoice,
    NetScoring,
    Ranked,
    Ranking,
    Slides,
    distinct_candidates,
    ranked,
)
from multi_robot_mapper.core.matching.refine import prior_weighs, refine_many
from multi_robot_mapper.core.matching.scoring import (
    Prescreen,
    pair_kept,
    pair_tolerance,
    pruned_values,
    refusal,
    support_and_slide,
)
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.segment_map import MapLike, SegmentMap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# How far (m) the best placement is slid either way along its least constrained direction to
# probe for a rival: twice the correctness tolerance, so that the probe is a wrong answer.
SLIDE_PROBE = 2.0 * RIGHT_DISTANCE


@dataclasses.dataclass(frozen=True)
class MatchResult:
    """The best transformation of S2 onto S1 and how much to trust it."""

    T_1_2: FloatArray  # (3,) theta, tx, ty
    value: float  # overlap length of matching segments under T_1_2 (m)
    fraction: float  # net value (overlap minus length seen through) / shorter set's length
    valid: bool  # passes min_match_value and min_match_fraction
    hypotheses: int  # distinct hypotheses generated
    evaluated: int  # hypotheses fully evaluated after pruning
    # P(right within 0.30 m / 5 deg), see core.matching.confidence; 0 and no evidence where
    # the caller did not want it (integrate's ``judged``)
    confidence: float = 0.0
    evidence: MatchEvidence | None = None  # what the confidence was computed from
    # seconds per stage: hypotheses, evaluation, refinement, ranking (free space and slides),
    # confidence
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)

    @property
    def matrix(self) -> FloatArray:
        return se2.matrix_from_pose(
            float(self.T_1_2[1]), float(self.T_1_2[2]), float(self.T_1_2[0])
        )


def pose_of_match(T_1_2: FloatArray) -> Pose:
    """INTEGRATE's (theta, tx, ty) as an (x, y, theta) pose."""
    return (float(T_1_2[1]), float(T_1_2[2]), float(T_1_2[0]))


def hypotheses_of(poses: list[Pose]) -> FloatArray:
    """(x, y, theta) poses as INTEGRATE hypotheses (theta, tx, ty)."""
    stacked = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return np.column_stack((stacked[:, 2], stacked[:, 0], stacked[:, 1]))


def integrate(
    segments1: MapLike,
    segments2: MapLike,
    config: IntegrateConfig,
    heuristics: tuple[str, ...] = HEURISTICS,
    ordered: tuple[bool, bool] = (True, True),
    extra_hypotheses: FloatArray | None = None,
    views: tuple[Views, Views] = (None, None),
    hypothesis_sets: tuple[MapLike, MapLike] | None = None,
    judged: Callable[[FloatArray], bool] | None = None,
    prior: MotionPrior | None = None,
) -> MatchResult:
    """Find how S2 lies in S1's frame with no initial guess (INTEGRATE steps 1-2).

    ``judged(T_1_2)`` says whether the chosen placement's confidence is wanted (None:
    always); where not, it is 0 with no evidence, the beams unread (a discarded placement).

    ``hypothesis_sets`` (same frames as S1 and S2) are the sets whose landmarks generate the
    hypotheses when they differ from the sets evaluated (a local mapper's last keyframe's scan,
    evaluated on the partial map around it).

    ``views`` are the scans each set was seen in (one scan at the set's origin, or several
    viewpoints for a submap), when known. Overlap length cannot tell a corridor's true motion
    from standing still (the visible wall moves with the robot); the beams can: under a wrong
    hypothesis one scan's walls lie where the other's beams passed (seen through), and few of
    its returns lie where the other's beams ended (confirmed). The ``refine_candidates`` best
    distinct hypotheses are refined and ranked by overlap - ``free_space_weight`` x seen
    through + ``confirmed_weight`` x confirmed + ``cross_support_weight`` x cross support
    (without views: overlap and cross support). Validity uses overlap minus seen through.

    Steps: hypotheses (Alg. 2 and the heuristics of III-A); values (Alg. 4 l. 5-19, after a
    prescreen when there are many); the best distinct ones, refused ones dropped (Alg. 4
    l. 6-7, 20-23); refinement; slides along corridors; the best net score wins. A motion
    ``prior`` (:mod:`~core.matching.prior`) decides the least constrained direction.

    The two sets' pair geometry is built once for the whole match (:func:`~core.matching.
    scoring.pair_kept`).
    """
    map1, map2 = SegmentMap.of(segments1), SegmentMap.of(segments2)
    with pair_kept(map1, map2):
        return _integrate(
            map1,
            map2,
            _settings(config),
            (heuristics, ordered, extra_hypotheses, hypothesis_sets),
            views,
            judged,
            prior,
        )


@dataclasses.dataclass(frozen=True)
class _Settings:
    """What one match reads of INTEGRATE's config, step by step (:func:`_settings`): the
    random heuristic's seed; the landmarks, the tolerance between two landmarks' angles (rad),
    the number of distinct hypotheses kept and the (rad, m) cell that makes two hypotheses one;
    the prescreen; the choice of candidates; their ranking; validity (``min_match_value``,
    ``min_match_fraction``, ``min_cross_support``) and the beams the evidence is read by
    (``confirm_margin``, ``free_space_spread``, ``view_point_length``)."""

    seed: int
    landmarks: LandmarkSettings
    angle_tolerance: float
    max_hypotheses: int
    cells: tuple[float, float]
    prescreen: Prescreen
    choice: CandidateChoice
    ranking: Ranking
    validity: tuple[float, float, float]
    evidence_beams: tuple[float, int, float]


def _settings(config: IntegrateConfig) -> _Settings:
    """``config`` unpacked for one match (as KISS-ICP's ``get_registration`` does)."""
    scoring = NetScoring(
        pair_tolerance(config),
        beam_limits(config),
        config.free_space_weight,
        config.confirmed_weight,
        config.cross_support_weight,
    )
    slides = Slides(
        config.slide_candidates, config.slide_below_support, config.slide_range, config.slide_step
    )
    return _Settings(
        config.seed,
        landmark_settings(config),
        config.angle_difference_tolerance,
        config.max_hypotheses,
        (config.hypothesis_angle_cell, config.hypothesis_distance_cell),
        Prescreen(config.prescreen_match_angle, config.prescreen_segments, config.candidate_pool),
        CandidateChoice(
            config.candidate_pool,
            config.refine_candidates,
            config.candidate_separation,
            config.candidate_angle_separation,
        ),
        Ranking(scoring, refusal(config), slides, config.refine_iterations),
        (config.min_match_value, config.min_match_fraction, config.min_cross_support),
        (config.confirm_margin, config.free_space_spread, config.view_point_length),
    )


# integrate's heuristics, ordered, extra hypotheses and hypothesis sets
_Generation: TypeAlias = tuple[
    tuple[str, ...], tuple[bool, bool], FloatArray | None, tuple[MapLike, MapLike] | None
]


def _integrate(
    map1: SegmentMap,
    map2: SegmentMap,
    settings: _Settings,
    generation: _Generation,
    views: tuple[Views, Views],
    judged: Callable[[FloatArray], bool] | None,
    prior: MotionPrior | None,
) -> MatchResult:
    """:func:`integrate` of two maps (``generation``: how it makes its hypotheses)."""
    heuristics, ordered, extra_hypotheses, hypothesis_sets = generation
    clock = _StageClock()
    rng = np.random.default_rng(settings.seed)
    sources = (map1, map2) if hypothesis_sets is None else hypothesis_sets
    transforms, extras = _all_hypotheses(
        sources, heuristics, ordered, extra_hypotheses, settings, rng
    )
    clock.lap("hypotheses")
    if len(transforms) == 0:
        return _no_match(0, 0, clock)
    ranking = settings.ranking
    tolerance = ranking.scoring.tolerance
    values, evaluated = pruned_values(map1, map2, transforms, tolerance, settings.prescreen, extras)
    # Alg. 4 l. 20-23 (keep the best), widened: the best few DISTINCT hypotheses are refused
    # (l. 6-7) or refined, then ranked by their net score (overlap and the scans' beams).
    candidates = distinct_candidates(
        map1, map2, transforms, values, settings.choice, ranking.refusal
    )
    clock.lap("evaluation")
    if candidates.size == 0:
        return _no_match(len(transforms), evaluated, clock)
    refined = refine_many(map1, map2, transforms[candidates], tolerance, ranking.iterations, prior)
    clock.lap("refinement")
    best = ranked(map1, map2, transforms, candidates, refined, views, ranking, prior)
    clock.lap("ranking")
    setting = (views, settings, prior)
    return _judged_result(map1, map2, best, setting, judged, clock, transforms, evaluated)


def _no_match(hypotheses: int, evaluated: int, clock: _StageClock) -> MatchResult:
    """No placement: ``hypotheses`` made, ``evaluated`` of them in full, none kept."""
    return MatchResult(np.zeros(3), 0.0, 0.0, False, hypotheses, evaluated, seconds=clock.seconds)


def _all_hypotheses(
    sources: tuple[MapLike, MapLike],
    heuristics: tuple[str, ...],
    ordered: tuple[bool, bool],
    extra_hypotheses: FloatArray | None,
    settings: _Settings,
    rng: np.random.Generator,
) -> tuple[FloatArray, int]:
    """The hypotheses (theta, tx, ty) to evaluate, the extra ones first, and how many extra
    ones there are: the extra ones (predictions), then the distinct ones of the landmarks of
    the two sets (Alg. 2 and the heuristics of III-A) and of their end points."""
    source1, source2 = SegmentMap.of(sources[0]), SegmentMap.of(sources[1])
    marking = settings.landmarks
    marks1 = landmarks(source1, heuristics, marking, ordered[0], rng) if len(source1) > 1 else None
    marks2 = landmarks(source2, heuristics, marking, ordered[1], rng) if len(source2) > 1 else None
    raw = (
        hypotheses(
            source1, marks1, source2, marks2, settings.angle_tolerance, settings.max_hypotheses
        )
        if marks1 is not None and marks2 is not None
        else np.zeros((0, 3))
    )
    if "endpoints" in heuristics and len(source1) and len(source2):
        raw = np.vstack((raw, endpoint_hypotheses(source1, source2, marking.min_length)))
    transforms, _ = distinct_hypotheses(raw, *settings.cells, settings.max_hypotheses)
    # Extra hypotheses (predictions) come first and are always evaluated in full.
    extra = (
        np.zeros((0, 3))
        if extra_hypotheses is None
        else np.asarray(extra_hypotheses, dtype=np.float64).reshape(-1, 3)
    )
    return np.vstack((extra, transforms)), len(extra)


def _judged_result(
    map1: SegmentMap,
    map2: SegmentMap,
    ranked: Ranked,
    setting: tuple[tuple[Views, Views], _Settings, MotionPrior | None],
    judged: Callable[[FloatArray], bool] | None,
    clock: _StageClock,
    transforms: FloatArray,
    evaluated: int,
) -> MatchResult:
    """The best ranked placement as the match: its validity (net value, fraction and cross
    support) and, where ``judged`` wants it, its confidence (of the ``transforms``
    hypotheses, ``evaluated`` were evaluated in full; ``setting``: the views, the settings and
    the motion prior)."""
    views, settings, _ = setting
    scoring = settings.ranking.scoring
    min_value, min_fraction, min_support = settings.validity
    refined, pick = ranked.transforms, ranked.pick
    best_T, best_value = refined[pick], float(ranked.values[pick])
    # Validity on the net value: overlap that the other scan's free space contradicts counts
    # against it (two unrelated rectilinear places easily overlap by a third).
    through, _ = seen_through_many(map1, map2, best_T[None, :], views, scoring.beams)
    best_score = best_value - scoring.free_space_weight * float(through[0])
    fraction = best_score / max(min(map1.total_length, map2.total_length), 1e-9)
    best_support, slide, total = support_and_slide(map1, map2, best_T, scoring.tolerance)
    valid = best_score >= min_value and fraction >= min_fraction and best_support >= min_support
    probability, evidence = 0.0, None
    if judged is None or judged(best_T):
        evidence = _evidence_of(
            (map1, map2), ranked, setting, (best_support, slide, total), fraction
        )
        probability = confidence(evidence.features())
        clock.lap("confidence")
    return MatchResult(
        best_T.copy(),
        best_value,
        fraction,
        bool(valid),
        len(transforms),
        evaluated,
        probability,
        evidence,
        clock.seconds,
    )


def _evidence_of(
    sets: tuple[SegmentMap, SegmentMap],
    ranked: Ranked,
    setting: tuple[tuple[Views, Views], _Settings, MotionPrior | None],
    spread: tuple[float, FloatArray, float],
    fraction: float,
) -> MatchEvidence:
    """What the confidence of the best ranked placement is read from: the beams of both sets
    on it, how far it beats its best rival (a distinct placement, beyond the correctness
    tolerance), the fit's ``spread`` (support, least constrained direction, matched length). A
    rival the motion prior rules out is none, nor is a slide along the direction it decides."""
    (map1, map2), (views, settings, prior) = sets, setting
    refined, scores, pick = ranked.transforms, ranked.scores, ranked.pick
    best_T = refined[pick]
    support, slide, total = spread
    rivals = _distinct_from(refined, best_T)
    tolerance = settings.ranking.scoring.tolerance
    counts = prior_weighs(map1, map2, best_T[None, :], tolerance, prior)
    weighed = prior if counts.size and counts[0] else None
    if weighed is not None:
        rivals &= ~excluded_by(weighed, refined, slide)
    return match_evidence(
        map1,
        map2,
        best_T,
        views,
        settings.evidence_beams,
        score=float(scores[pick]),
        rival_score=float(scores[rivals].max()) if rivals.any() else 0.0,
        rival_T=refined[rivals][int(np.argmax(scores[rivals]))] if rivals.any() else None,
        support=support,
        prior_support=support_with_prior(support, total, weighed) - support,
        fraction=fraction,
        slide=slide if weighed is None else None,
    )


class _StageClock:
    """Seconds per stage, each lap from the previous one."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + now - self._last
        self._last = now


def _distinct_from(transforms: FloatArray, T: FloatArray) -> BoolArray:
    """Rows farther from ``T`` (theta, tx, ty) than the correctness tolerance: rival answers."""
    turn = np.abs(se2.wrap_angle(transforms[:, 0] - T[0]))
    shift = np.hypot(transforms[:, 1] - T[1], transforms[:, 2] - T[2])
    return np.asarray((turn >= RIGHT_ANGLE) | (shift >= RIGHT_DISTANCE))


def match_evidence(
    map1: MapLike,
    map2: MapLike,
    T_1_2: FloatArray,
    views: tuple[Views, Views],
    beams: tuple[float, int, float],
    *,
    score: float,
    rival_score: float,
    support: float,
    fraction: float,
    rival_T: FloatArray | None = None,
    slide: FloatArray | None = None,
    prior_support: float = 0.0,
) -> MatchEvidence:
    """The evidence for the placement ``T_1_2`` (theta, tx, ty) of S2 in S1: each side's
    returns (points along its segments when its views are unknown) judged by the other side's
    beams, with the score, the rival's, the fit's spread, and how the beams judge the best
    rival placement: ``rival_T``, or the placement slid by :data:`SLIDE_PROBE` either way
    along ``slide`` (the least constrained direction) where the beams like that better. A
    slide along a bare corridor explains the beams as well as the best placement, and the
    hypotheses need not contain it (they come from where segments end). ``beams``: the
    ``confirm_margin``, ``free_space_spread`` and ``view_point_length`` the beams judge by."""
    margin, spread, cap = beams
    sides = [viewpoints_of(v) for v in views]
    returns = [
        ViewReturns.of(viewpoints, cap)
        if viewpoints is not None
        else ViewReturns(*_segment_returns(SegmentMap.of(segments).segments, cap))
        for viewpoints, segments in zip(sides, (map1, map2), strict=True)
    ]

    def judge(row: FloatArray) -> list[BeamAgreement]:
        """S2's returns judged by S1's beams, and S1's by S2's (unjudged: every return
        outside), with S2 placed by ``row``."""
        T = se2.matrix_from_pose(float(row[1]), float(row[2]), float(row[0]))
        return [
            beam_agreement(
                returns[1 - side], T if side == 0 else se2.invert(T), viewpoints, margin, spread
            )
            if viewpoints is not None
            else BeamAgreement.unjudged(returns[1 - side].total)
            for side, viewpoints in enumerate(sides)
        ]

    judged = judge(T_1_2)
    rivals = [] if rival_T is None else [np.asarray(rival_T, dtype=np.float64)]
    if slide is not None:
        step = SLIDE_PROBE * np.asarray(slide, dtype=np.float64)
        rivals += [T_1_2 + np.array([0.0, sign * step[0], sign * step[1]]) for sign in (-1, 1)]
    rival = BeamAgreement.nothing()
    for row in rivals:
        pair = judge(row)
        candidate = pair[0] + pair[1]
        if rival.total <= 0.0 or _explained(candidate) > _explained(rival):
            rival = candidate
    return MatchEvidence(
        judged[0], judged[1], score, rival_score, support, fraction, rival, prior_support
    )


def _explained(agreement: BeamAgreement) -> float:
    """Metres of returns the beams confirm, less those they see through."""
    return agreement.confirmed - agreement.seen_through


def _segment_returns(segments: FloatArray, spacing: float) -> tuple[FloatArray, FloatArray]:
    """Points every ``spacing`` along segments, each standing for ``spacing`` of surface."""
    if len(segments) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    points, _ = sample_segments(segments, spacing)
    return points, np.full(len(points), spacing)
