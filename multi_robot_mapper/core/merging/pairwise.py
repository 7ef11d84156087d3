"""One pair of maps: how map b lies in map a, and whether to trust it."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.correlation import (
    Drawing,
    correlation_peaks,
    placement_scores,
    rotation_candidates,
)
from multi_robot_mapper.core.matching import (
    MatchResult,
    integrate,
    refine_many,
    refusal,
    refused,
    score_pairs,
)
from multi_robot_mapper.core.matching.scoring import PairTolerance, pair_kept, pair_tolerance
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.free_space import (
    FreeDrawing,
    FreeSpaceLimits,
    MapViews,
    free_space_conflict,
    seen_through_allowance,
)
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.segment_map import MapLike, SegmentMap

FloatArray = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class Link:
    """How map b lies in map a: ``T_a_b`` and how much to trust it."""

    robot_a: str
    robot_b: str
    T_a_b: Pose  # x, y, theta: robot b's map frame in robot a's
    value: float  # overlap length of matching segments under T_a_b (m)
    fraction: float  # value / shorter map's total segment length
    valid: bool  # passes the link_* thresholds
    tight_fraction: float = 0.0  # overlap within tight_distance / shorter map's length
    seen_through: float = 0.0  # m of either map in the other's free space (0: not checked)
    uniqueness: float = 0.0  # correlation score / best distinct placement's (link_min_uniqueness)

    @property
    def matrix(self) -> FloatArray:
        return se2.matrix_from_pose(*self.T_a_b)


@dataclasses.dataclass(frozen=True)
class MapSignature:
    """What a pair result was computed on: enough to tell whether a map changed much."""

    count: int
    length: float  # total segment length (m)
    digest: str  # content hash: equal digests are equal maps

    @staticmethod
    def of(segments: MapLike) -> MapSignature:
        """The signature of a map (its digest made once per :class:`SegmentMap`: pass the
        map that lives as long as its content)."""
        segment_map = SegmentMap.of(segments)
        return MapSignature(len(segment_map), segment_map.total_length, segment_map.digest)

    def close_to(self, earlier: MapSignature, change: tuple[float, float]) -> bool:
        """Did the map change little since ``earlier``? (Then a pair result is reused.)

        Identical content, or: segment count within ``change[0]`` % (at least 2 segments)
        and total length within ``change[1]`` % of the earlier map's (``merge.pairwise``'s
        ``reuse_count_change`` and ``reuse_length_change``: :func:`reuse_change`). A growing
        map is re-matched once it grew by that much since the result was computed.
        """
        if self.digest == earlier.digest:
            return True
        count_change, length_change = change
        count_slack = max(2.0, count_change / 100.0 * earlier.count)
        length_slack = length_change / 100.0 * earlier.length
        return (
            abs(self.count - earlier.count) <= count_slack
            and abs(self.length - earlier.length) <= length_slack
        )


def reuse_change(config: MergeConfig) -> tuple[float, float]:
    """How much a map may change (%, segment count and total length) before a match found on
    it is made again (:meth:`MapSignature.close_to`)."""
    return config.pairwise.reuse_count_change, config.pairwise.reuse_length_change


@dataclasses.dataclass(frozen=True)
class PairRecord:
    """The INTEGRATE result of one pair of maps and the maps it was computed on."""

    link: Link
    signature_a: MapSignature
    signature_b: MapSignature
    reused: bool  # taken from the previous run instead of computed


def longest(segments: FloatArray, count: int) -> FloatArray:
    """The ``count`` longest segments, longest first."""
    if len(segments) == 0:
        return segments.reshape(0, 4)
    return np.asarray(segments[SegmentMap.of(segments).longest_first[:count]])


@dataclasses.dataclass(frozen=True)
class MapMatch:
    """The result of matching two maps: the best transformation and the verdict."""

    result: MatchResult  # INTEGRATE's T_1_2 (theta, tx, ty): map b in map a; value, fraction
    tight_fraction: float  # overlap within tight_distance / shorter judged set's length
    valid: bool  # INTEGRATE's validity with the link_* thresholds, tight overlap, free space,
    # uniqueness
    integrate_calls: int
    seen_through: float = 0.0  # m of either map in the other's free space (0: not checked)
    uniqueness: float = 0.0  # score / score of the best distinct placement

    @property
    def matrix(self) -> FloatArray:
        return self.result.matrix


def match_maps(
    map_a: MapLike,
    map_b: MapLike,
    config: MergeConfig,
    views_a: MapViews | None = None,
    views_b: MapViews | None = None,
    drawings: tuple[Drawing, Drawing] | None = None,
) -> MapMatch:
    """How map b lies in map a, and whether to trust it.

    1. Candidates: INTEGRATE's own hypotheses (Amigoni Alg. 2: equal angles between pairs of
       the ``hypothesis_segments`` longest segments, ranked on the ``coarse_segments`` longest)
       and the ``correlation_candidates`` best placements of the map correlation
       (:mod:`~multi_robot_mapper.core.evidence.correlation`: every translation, for each rotation
       the wall directions allow; with the robots' views, walls in the other's free space count
       against). On large maps landmarks miss the true placement of a small overlap, and on
       self-similar buildings a corridor slid along itself overlaps more than it.
    2. The best ``_REFINED`` distinct places are refined (Cox, on the ``judge_segments``
       longest segments) and scored by the correlation: the best one and its rivals.
    3. INTEGRATE evaluates the best place (Alg. 4), and the link is valid when it passes the
       ``link_*`` thresholds: value, fraction and cross support; the overlap within
       ``tight_distance`` (one place coincides to centimetres, look-alike places only
       roughly); free space (with views, neither map may lie in the other's free space beyond
       ``link_max_seen_through`` or that fraction of the value); and, with both robots' views,
       uniqueness (a score at least ``link_min_uniqueness`` times the best rival's: a place
       that fits twice is ambiguous). Uniqueness needs free space: on walls alone a repeated
       building fits at several places and every link would be ambiguous; with it, a smaller
       overlap (``viewed_link_*``) is trusted.

    ``drawings`` are the two maps drawn for the correlation (:func:`draw_map`) when the
    caller keeps them from one pair to the next.
    """
    map_a, map_b = SegmentMap.of(map_a), SegmentMap.of(map_b)
    if len(map_a) == 0 or len(map_b) == 0:
        return no_match()
    drawing_a, drawing_b = drawings or (
        draw_map(map_a, views_a, config.free_drawing()),
        draw_map(map_b, views_b, config.free_drawing()),
    )
    judge_a = map_a.longest(config.pairwise.judge_segments)
    judge_b = map_b.longest(config.pairwise.judge_segments)
    candidates = _candidates(map_a, map_b, drawing_a, drawing_b, config)
    # The judges' pair geometry: built once for refusal, refinement, INTEGRATE, tight overlap.
    with pair_kept(judge_a, judge_b):
        places = _best_places(judge_a, judge_b, drawing_a, drawing_b, candidates, config)
        if places is None:
            return no_match()
        refined, scores = places
        best = int(np.argmax(scores))
        rivals = np.array([_distinct(row, refined[best]) for row in refined], dtype=bool)
        uniqueness = _uniqueness(scores, best, rivals)
        viewed = views_a is not None and views_b is not None
        result = _place_evaluated(
            judge_a, judge_b, candidates, refined[best], refined[~rivals], viewed, config
        )
        if result.value <= 0.0:
            return MapMatch(result, 0.0, False, _INTEGRATE_CALLS, 0.0, uniqueness)
        return _judged_link(
            map_a, map_b, judge_a, judge_b, views_a, views_b, result, uniqueness, link_tests(config)
        )


def _place_evaluated(
    judge_a: SegmentMap,
    judge_b: SegmentMap,
    candidates: FloatArray,
    chosen: FloatArray,
    same: FloatArray,
    viewed: bool,
    config: MergeConfig,
) -> MatchResult:
    """INTEGRATE's evaluation of the ``chosen`` place on the longest segments ``judge_a`` and
    ``judge_b``, from the refined places ``same`` as it and the candidates near it."""
    # INTEGRATE evaluates the chosen place (Alg. 4): every start there (the refined one and
    # the candidates near it), the best refined.
    near = [row for row in candidates if not _distinct(row, chosen)]
    same_place = np.vstack((same, *near))
    return integrate(
        judge_a,
        judge_b,
        config.link_config(hypotheses=len(same_place), viewed=viewed),
        heuristics=(),
        ordered=(False, False),
        extra_hypotheses=same_place,
    )


_INTEGRATE_CALLS = 2  # per pair of maps: INTEGRATE's candidates, and the evaluation


def _uniqueness(scores: FloatArray, best: int, rivals: NDArray[np.bool_]) -> float:
    """The best place's score over its best rival's (``rivals`` of ``scores``): inf without a
    rival scoring above 0, and 0 when the best does not."""
    rival = float(scores[rivals].max()) if rivals.any() else 0.0
    score = float(scores[best])
    return score / rival if rival > 0.0 else (np.inf if score > 0.0 else 0.0)


class LinkTests(NamedTuple):
    """What judging a whole-map link reads of the merge config (:func:`link_tests`): the pair
    tolerances of the tight overlap (INTEGRATE's, the match distance ``tight_distance``), the
    least tight fraction without and with both robots' views (``link_min_tight_fraction``,
    ``viewed_link_min_tight_fraction``), the least uniqueness (``link_min_uniqueness``), what
    a wall in free space is, and the wall in free space a link tolerates
    (``link_max_seen_through`` m, or that fraction of its value:
    ``link_max_seen_through_fraction``)."""

    tight: PairTolerance
    min_tight_fraction: tuple[float, float]
    min_uniqueness: float
    free_space: FreeSpaceLimits
    seen_through: tuple[float, float]


def link_tests(config: MergeConfig) -> LinkTests:
    """The link tests of ``config``."""
    tight = dataclasses.replace(
        config.integrate,
        segment_distance_threshold=config.pairwise.tight_distance
        / config.integrate.point_distance_tolerance,
    )
    pairwise = config.pairwise
    return LinkTests(
        pair_tolerance(tight),
        (pairwise.link_min_tight_fraction, pairwise.viewed_link_min_tight_fraction),
        pairwise.link_min_uniqueness,
        config.free_space_limits(),
        (config.link_max_seen_through, config.link_max_seen_through_fraction),
    )


def _judged_link(
    map_a: SegmentMap,
    map_b: SegmentMap,
    judge_a: SegmentMap,
    judge_b: SegmentMap,
    views_a: MapViews | None,
    views_b: MapViews | None,
    result: MatchResult,
    uniqueness: float,
    tests: LinkTests,
) -> MapMatch:
    """INTEGRATE's evaluation of the chosen place (on the longest segments ``judge_a`` and
    ``judge_b``) as a link, judged (:func:`match_maps`, step 3): the ``link_*`` thresholds,
    the tight overlap, uniqueness with both robots' views, free space with either's."""
    viewed = views_a is not None and views_b is not None
    tight = tight_fraction(judge_a, judge_b, result.T_1_2, tests.tight)
    valid = result.valid and tight >= tests.min_tight_fraction[1 if viewed else 0]
    if viewed:
        valid = valid and uniqueness >= tests.min_uniqueness
    through = 0.0
    if valid and (views_a is not None or views_b is not None):
        through = free_space_conflict(
            map_a.segments,
            views_a,
            map_b.segments,
            views_b,
            result.matrix,
            tests.free_space,
        )
        valid = through <= seen_through_allowance(result.value, *tests.seen_through)
    return MapMatch(result, tight, valid, _INTEGRATE_CALLS, through, uniqueness)


def no_match() -> MapMatch:
    return MapMatch(MatchResult(np.zeros(3), 0.0, 0.0, False, 0, 0), 0.0, False, 0)


_REFINED = 4  # distinct places refined per pair of maps: the best and its rivals
_DISTINCT_SHIFT = 2.0  # m: placements farther apart than this (or turned more) are rivals
_DISTINCT_TURN = float(np.radians(10.0))


def _distinct(row: FloatArray, other: FloatArray) -> bool:
    """Are two ``(theta, tx, ty)`` placements different answers (rivals)?"""
    turn = abs(float(se2.wrap_angle(row[0] - other[0])))
    shift = float(np.hypot(row[1] - other[1], row[2] - other[2]))
    return shift > _DISTINCT_SHIFT or turn > _DISTINCT_TURN


def _best_places(
    judge_a: SegmentMap,
    judge_b: SegmentMap,
    drawing_a: Drawing,
    drawing_b: Drawing,
    candidates: FloatArray,
    config: MergeConfig,
) -> tuple[FloatArray, FloatArray] | None:
    """The ``_REFINED`` best distinct places among the candidates by their correlation score,
    refined (Cox) and scored again: ``(K, 3)`` placements and their scores; None when every
    candidate is refused. Refining only these costs less than the correlation itself."""
    correlation, link = config.correlation(), config.link_config()
    rough = placement_scores(drawing_a, drawing_b, candidates, correlation)
    # Long walls crossing each other refuse a placement outright (Alg. 4 l. 6-7).
    rough[refused(judge_a, judge_b, candidates, *refusal(link))] = -np.inf
    keep: list[int] = []
    for k in np.argsort(-rough, kind="stable"):
        if len(keep) == _REFINED or not np.isfinite(rough[k]):
            break
        if all(_distinct(candidates[k], candidates[j]) for j in keep):
            keep.append(int(k))
    if not keep:
        return None
    refined = refine_many(
        judge_a, judge_b, candidates[keep], pair_tolerance(link), link.refine_iterations
    )
    scores = placement_scores(drawing_a, drawing_b, refined, correlation)
    scores[refused(judge_a, judge_b, refined, *refusal(link))] = -np.inf
    if not np.isfinite(scores).any():
        return None
    return refined, scores


def draw_map(segments: MapLike, views: MapViews | None, drawing: FreeDrawing) -> Drawing:
    """A map drawn for the correlation, with its free space when its views are known (one
    point per cell along each bearing marks every cell the beams cross)."""
    free = np.zeros((0, 2)) if views is None else views.free_points(*drawing)
    return Drawing.of(segments, free, drawing.cell)


def _candidates(
    map_a: SegmentMap,
    map_b: SegmentMap,
    drawing_a: Drawing,
    drawing_b: Drawing,
    config: MergeConfig,
) -> FloatArray:
    """Candidate placements ``(theta, tx, ty)`` of map b in map a."""
    rows: list[FloatArray] = []
    k, c = config.pairwise.hypothesis_segments, config.pairwise.coarse_segments
    ranking = dataclasses.replace(config.link_config(), all_pairs_below=k)
    angles = integrate(
        map_a.longest(c),
        map_b.longest(c),
        ranking,
        heuristics=("all",),
        ordered=(False, False),
        hypothesis_sets=(map_a.longest(k), map_b.longest(k)),
    )
    if angles.value > 0.0:
        rows.append(angles.T_1_2.reshape(1, 3))
    correlation = config.correlation()
    rotations = rotation_candidates(map_a, map_b, correlation.rotations)
    peaks, _ = correlation_peaks(drawing_a, drawing_b, rotations, correlation)
    rows.append(peaks[: config.pairwise.correlation_candidates])
    return np.vstack(rows)


def tight_fraction(
    segments1: MapLike, segments2: MapLike, T_1_2: FloatArray, tight: PairTolerance
) -> float:
    """Overlap of matching segments within the ``tight`` tolerances (match distance
    ``tight_distance``: :func:`link_tests`) under ``T_1_2`` (INTEGRATE's row), as a fraction
    of the shorter set's total length."""
    map1, map2 = SegmentMap.of(segments1), SegmentMap.of(segments2)
    scores = score_pairs(map1, map2, np.asarray(T_1_2)[None, :], tight)
    shorter = min(map1.total_length, map2.total_length)
    return float(scores.value.sum()) / max(shorter, 1e-9)


def link_of(robot_a: str, robot_b: str, match: MapMatch) -> Link:
    x, y, theta = se2.pose_from_matrix(match.matrix)
    result = match.result
    return Link(
        robot_a,
        robot_b,
        (x, y, theta),
        result.value,
        result.fraction,
        match.valid,
        match.tight_fraction,
        match.seen_through,
        match.uniqueness,
    )
