"""INTEGRATE's choice among its hypotheses, beyond Amigoni's Alg. 4 l. 20-23: the best distinct
hypotheses, their net scores (overlap, what the scans' beams see through and confirm, the
support across the weakest direction) and slides along corridors. Each step takes the few
numbers it reads (:class:`CandidateChoice`, :class:`NetScoring`, :class:`Slides`,
:class:`Ranking`); :func:`~core.matching.integrate.integrate` unpacks them from its config."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.beams import Views, seen_through_many
from multi_robot_mapper.core.matching.prior import MotionPrior
from multi_robot_mapper.core.matching.refine import prior_weighs, refine_many
from multi_robot_mapper.core.matching.scoring import (
    PairTolerance,
    information,
    refused,
    score_pairs,
    transform_values,
)
from multi_robot_mapper.core.segment_map import SegmentMap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# A refined slid hypothesis replaces the slid one unless its net score is this much lower (m):
# the slide grid is coarse, the refinement is the precise answer.
_POLISH_TOLERANCE = 0.25


class CandidateChoice(NamedTuple):
    """Which hypotheses are refined: of the ``pool`` best valued, the best ``kept`` that are
    at least ``separation`` (m) or ``angle_separation`` (rad) apart (IntegrateConfig's
    ``candidate_pool``, ``refine_candidates``, ``candidate_separation``,
    ``candidate_angle_separation``)."""

    pool: int
    kept: int
    separation: float
    angle_separation: float


class NetScoring(NamedTuple):
    """What a net score reads: the pair tolerances, the beams' limits (``beams.beam_limits``)
    and the weights of the length seen through, the length confirmed and the cross support
    (IntegrateConfig's ``free_space_weight``, ``confirmed_weight``,
    ``cross_support_weight``)."""

    tolerance: PairTolerance
    beams: tuple[float, int, float, float]
    free_space_weight: float
    confirmed_weight: float
    cross_support_weight: float


class Slides(NamedTuple):
    """The slides along corridors: the best ``candidates`` whose cross support is below
    ``below_support`` are tried every ``step`` (m) within ``reach`` (m) either way
    (IntegrateConfig's ``slide_candidates``, ``slide_below_support``, ``slide_step``,
    ``slide_range``)."""

    candidates: int
    below_support: float
    reach: float
    step: float


@dataclasses.dataclass(frozen=True)
class Ranking:
    """What ranking the refined candidates reads: the net score, the crossing refusal
    (``scoring.refusal``), the slides and the refinement's iterations (0: none)."""

    scoring: NetScoring
    refusal: tuple[float, float, float]
    slides: Slides
    iterations: int


class Ranked(NamedTuple):
    """The refined candidates and the slid hypotheses, their values and net scores, and the
    row of the best one."""

    transforms: FloatArray
    values: FloatArray
    scores: FloatArray
    pick: int


def ranked(
    map1: SegmentMap,
    map2: SegmentMap,
    transforms: FloatArray,
    candidates: IntArray,
    refined: FloatArray,
    views: tuple[Views, Views],
    ranking: Ranking,
    prior: MotionPrior | None = None,
) -> Ranked:
    """The ``refined`` candidates (rows ``candidates`` of ``transforms``, refined) with the
    hypotheses slid along corridors, ranked by their net score: a refined one that was refused
    (or lost its overlap) falls back to its unrefined hypothesis, and the best one, when slid,
    is refined too. With a motion ``prior`` nothing the walls leave unobserved is slid: the
    prior decides the offset along the corridor."""
    scoring = ranking.scoring
    refined_values, scores, support, slide = net_scores(map1, map2, refined, views, scoring)
    if ranking.iterations > 0:
        # A refinement that slid into a crossing (or lost its overlap) falls back to the
        # unrefined hypothesis, which passed the refusal test.
        bad = refused(map1, map2, refined, *ranking.refusal) | (refined_values <= 0.0)
        if bad.any():
            refined[bad] = transforms[candidates[bad]]
            refined_values[bad], scores[bad], support[bad], slide[bad] = net_scores(
                map1, map2, refined[bad], views, scoring
            )
    # The prior decides the offset along a corridor where it counts: nothing to slide there.
    support[prior_weighs(map1, map2, refined, scoring.tolerance, prior)] = np.inf
    slid_transforms, slid_values, slid_scores = slid(
        map1, map2, (refined, scores, support, slide), views, ranking
    )
    refined = np.vstack((refined, slid_transforms))
    refined_values = np.concatenate((refined_values, slid_values))
    scores = np.concatenate((scores, slid_scores))
    pick = int(np.argmax(scores))
    if pick >= len(candidates) and ranking.iterations > 0:
        # A slid hypothesis sits on a grid along the corridor: refine it too (the damped
        # steps leave it where it is along a bare corridor).
        polished = refine_many(
            map1, map2, refined[pick : pick + 1], scoring.tolerance, ranking.iterations
        )
        polished_value, polished_score, _, _ = net_scores(map1, map2, polished, views, scoring)
        if (
            polished_score[0] >= scores[pick] - _POLISH_TOLERANCE
            and not refused(map1, map2, polished, *ranking.refusal)[0]
        ):
            refined[pick], refined_values[pick] = polished[0], polished_value[0]
    return Ranked(refined, refined_values, scores, pick)


def slid(
    map1: SegmentMap,
    map2: SegmentMap,
    scored: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    views: tuple[Views, Views],
    ranking: Ranking,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Hypotheses slid along the direction their matched walls leave free, with their values
    and net scores (``scored``: the transforms, their net scores, cross supports and least
    constrained directions).

    In a corridor every wall is parallel: no angle fixes the offset along it and end points
    rarely do, so the true offset may be missing from the hypotheses. The best
    ``slides.candidates`` whose cross support is below ``slides.below_support`` are tried at
    every ``slides.step`` within ``slides.reach`` along that direction; free space (what each
    scan saw down the corridor) tells the offsets apart. Refused ones are dropped.
    """
    transforms, scores, support, direction = scored
    slides = ranking.slides
    top = np.argsort(-scores, kind="stable")[: slides.candidates]
    top = top[support[top] < slides.below_support]
    if top.size == 0 or slides.reach <= 0.0:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0)
    offsets = np.arange(-slides.reach, slides.reach + 1e-9, slides.step)
    offsets = offsets[np.abs(offsets) > 1e-9]
    shifted = np.repeat(transforms[top], offsets.size, axis=0)
    step = np.tile(offsets, top.size)
    shifted[:, 1] += step * np.repeat(direction[top, 0], offsets.size)
    shifted[:, 2] += step * np.repeat(direction[top, 1], offsets.size)
    keep = ~refused(map1, map2, shifted, *ranking.refusal)
    shifted = shifted[keep]
    values, net, _, _ = net_scores(map1, map2, shifted, views, ranking.scoring)
    return shifted, values, net


def net_scores(
    map1: SegmentMap,
    map2: SegmentMap,
    transforms: FloatArray,
    views: tuple[Views, Views],
    scoring: NetScoring,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Value, net score, cross support and least constrained direction of each transform.

    The net score is the overlap (Alg. 4 l. 18) minus the length seen through in the other
    scan's free space plus ``cross_support_weight`` x the cross support: in a corridor the
    overlap of the long walls barely changes with the offset along them (standing still even
    wins, the visible stretch of wall moving with the robot), and what tells the offsets
    apart is the little that crosses the corridor (door jambs, its end).
    """
    scores = score_pairs(map1, map2, transforms, scoring.tolerance)
    count = len(transforms)
    values = transform_values(scores, count)
    support, direction = information(map1, scores, count)
    through, confirmed = seen_through_many(map1, map2, transforms, views, scoring.beams)
    net = (
        values
        - scoring.free_space_weight * through
        + scoring.confirmed_weight * confirmed
        + scoring.cross_support_weight * support
    )
    return values, net, support, direction


def distinct_candidates(
    map1: SegmentMap,
    map2: SegmentMap,
    transforms: FloatArray,
    values: FloatArray,
    choice: CandidateChoice,
    refusal: tuple[float, float, float],
) -> IntArray:
    """Indices of the best ``choice.kept`` hypotheses, near-duplicates suppressed.

    Hypotheses are taken best first (Alg. 4 l. 20-23), of the ``choice.pool`` best valued;
    one within ``choice.separation`` (and ``choice.angle_separation``) of a hypothesis
    already taken is the same answer and is skipped; a refused one (long walls crossing,
    Alg. 4 l. 6-7, by ``refusal``: ``scoring.refusal``) is skipped too.
    """
    order = np.argsort(-values, kind="stable")
    order = order[values[order] > 0.0][: choice.pool]
    if order.size == 0:
        return order
    pool = transforms[order]
    free = np.ones(len(order), dtype=bool)
    allowed = np.zeros(len(order), dtype=bool)
    checked, chunk = 0, 8  # the refusal test runs on the pool best first, in growing chunks
    taken: list[int] = []
    while len(taken) < choice.kept and free.any():
        k = int(np.argmax(free))  # best remaining, the pool being sorted
        if k >= checked:
            end = min(len(order), k + chunk)
            allowed[k:end] = ~refused(map1, map2, pool[k:end], *refusal)
            checked, chunk = end, 2 * chunk
        if not allowed[k]:
            free[k] = False
            continue
        taken.append(int(order[k]))
        turn = np.abs(se2.wrap_angle(pool[:, 0] - pool[k, 0]))
        shift = np.hypot(pool[:, 1] - pool[k, 1], pool[:, 2] - pool[k, 2])
        free &= (turn > choice.angle_separation) | (shift > choice.separation)
    return np.asarray(taken, dtype=np.int64)
