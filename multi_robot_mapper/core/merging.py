"""Map merging: partial maps of robots that never met, in one global ``map`` frame.

Amigoni, Gasparini & Gini 2006, Sec. IV merge an *ordered* sequence of partial maps by
repeated INTEGRATE: sequentially (IV-A), as a tree (IV-B) or with the pivot method (IV-C,
Algorithm 6). :func:`merge_sequential`, :func:`merge_tree` and :func:`merge_pivot` implement
the three over an ordered list, for comparison on a known order; the pivot method uses the
cleaner variant the paper recommends (fuse ``S_1..i-1`` with ``S_i`` moved by the composed
``t_1,i``, not with ``S_i-1,i``).

Robots do not come in an order, and the order is what the paper leaves as future work.
:func:`merge` is the pivot idea without it: INTEGRATE every pair of partial maps, keep the
pairs whose best transformation passes the validity threshold (*links*), take the
maximum-value spanning tree of the links and place every robot frame by composing the links'
transforms along the tree from a reference robot (the pivots are the tree's edges). A robot
with no valid link to the reference stays unmerged (``None``): a wrong placement is worse than
none. ``merge(..., previous=result)`` re-runs cheaply as the maps grow: a pair whose two maps
barely changed keeps its earlier result, and the previous tree is kept unless a clearly
better link appears.

Segment overlap alone cannot tell two look-alike places apart (a grid of equal rooms, a ring
of equal corridors, two rectilinear buildings drawn on the same grid): a wrong link can score
as high as the true one. Free space separates them: given each robot's keyframe poses
(``viewpoints``, on the wire with every partial map), :class:`MapViews` ray casts the robot's
own map from where its laser stood, and a link is refused when the other map's walls lie in
that free space (:func:`free_space_conflict`), both for the pair alone and, when two groups of
already linked robots join in the spanning tree, against every viewpoint of the other group
(:func:`free_space_join`).

Frames: each robot's partial map is in its own map frame ``robot``; ``T_map_robot`` places it
in the global ``map`` frame, which is the reference robot's map frame. Poses are ``(x, y,
theta)`` triples (metres, radians), matrices ``T_a_b`` map frame-b coordinates into frame a.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import time
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.correlation import (
    CorrelationConfig,
    Drawing,
    correlation_peaks,
    placement_scores,
    rotation_candidates,
)
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.matching import (
    IntegrateConfig,
    MatchResult,
    integrate,
    lines_of,
    refine_many,
    refused,
    sample_segments,
    score_pairs,
)
from multi_robot_mapper.core.simulation import raycast_fans

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Pose = tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class MergeConfig:
    """Map merging. Lengths in metres, angles in radians.

    ``integrate`` holds INTEGRATE's matching tolerances; for links between maps its validity
    thresholds (``min_match_value``, ``min_match_fraction``, ``min_cross_support``) and its
    hypothesis budget (``max_hypotheses``, ``all_pairs_below``, ``refine_candidates``) are
    replaced by the ``link_*`` and hypothesis parameters below: partial maps are larger than
    scans and overlap by a smaller fraction.
    """

    reference: str = param(
        "",
        unit="",
        doc="robot whose map frame is 'map'; empty: the robot with the largest map (total "
        "segment length) among the largest group of linked robots",
    )
    link_min_value: float = param(
        15.0,
        unit="m",
        doc="validity threshold: a link's best transformation must overlap at least this "
        "length of matching segments (more than the walls of one room: a single room or "
        "corner looks alike in many places)",
        minimum=0.0,
    )
    link_min_fraction: float = param(
        0.3,
        unit="",
        doc="validity threshold on segments alone (a robot without viewpoints): overlap at "
        "least this fraction of the shorter map's total segment length",
        minimum=0.0,
        maximum=1.0,
    )
    viewed_link_min_fraction: float = param(
        0.1,
        unit="",
        doc="link_min_fraction when both robots' viewpoints are known: free space and "
        "uniqueness (link_min_uniqueness) then tell look-alike places apart, and robots that "
        "share a small part of their maps can be linked",
        minimum=0.0,
        maximum=1.0,
    )
    link_min_cross_support: float = param(
        1.5,
        unit="m",
        doc="validity threshold: matched length across the least constrained direction "
        "(parallel walls alone cannot fix the offset along them)",
        minimum=0.0,
    )
    link_min_tight_fraction: float = param(
        0.15,
        unit="",
        doc="validity threshold on segments alone: segments matched within tight_distance must "
        "overlap at least this fraction of the shorter map (the same walls coincide to "
        "centimetres, look-alike walls of other places only roughly)",
        minimum=0.0,
        maximum=1.0,
    )
    viewed_link_min_tight_fraction: float = param(
        0.05,
        unit="",
        doc="link_min_tight_fraction when both robots' viewpoints are known",
        minimum=0.0,
        maximum=1.0,
    )
    tight_distance: float = param(
        0.05,
        unit="m",
        doc="matching distance of the tight overlap (link_min_tight_fraction)",
        minimum=0.0,
        exclusive_minimum=True,
    )
    hypothesis_segments: int = param(
        12,
        unit="segments",
        doc="the angles between every pair of this many longest segments of each map "
        "propose the transformations",
        minimum=2,
    )
    coarse_segments: int = param(
        40,
        unit="segments",
        doc="hypotheses are ranked on this many longest segments of each map; the best are "
        "then refined and judged on the whole maps",
        minimum=2,
    )
    judge_segments: int = param(
        250,
        unit="segments",
        doc="the best hypotheses are refined and judged on this many longest segments of each "
        "map (short pieces add cost, not evidence)",
        minimum=2,
    )
    correlation_candidates: int = param(
        8,
        unit="",
        doc="the best placements of the map correlation (every translation, for each rotation "
        "the wall directions allow) that join INTEGRATE's own hypothesis as candidates; the "
        "best few distinct places among them are refined and judged",
        minimum=1,
    )
    correlation_cell: float = param(
        0.3,
        unit="m",
        doc="grid cell of the map correlation (its walls are blurred by one cell)",
        minimum=0.0,
        exclusive_minimum=True,
    )
    free_space_weight: float = param(
        2.0,
        unit="",
        doc="in the correlation score, a metre of wall lying in the other robot's free space "
        "counts against as this many metres of matched wall",
        minimum=0.0,
    )
    link_min_uniqueness: float = param(
        2.0,
        unit="",
        doc="validity threshold when both robots' viewpoints are known: the link's "
        "correlation score (matched wall minus wall in free space, m) must be at least this "
        "many times that of the best distinct placement (> 2 m or 10 degrees away): a place "
        "that fits twice is ambiguous (symmetric corridors, rows of equal rooms) and is "
        "refused",
        minimum=1.0,
    )
    max_hypotheses: int = param(
        150,
        unit="",
        doc="at most this many most-voted INTEGRATE hypotheses are ranked per pair of maps",
        minimum=1,
    )
    reuse_length_change: float = param(
        5.0,
        unit="%",
        doc="a pair's result is reused while each map's total segment length stays within "
        "this of the length it was computed on (and its segment count within "
        "reuse_count_change)",
        minimum=0.0,
    )
    reuse_count_change: float = param(
        10.0,
        unit="%",
        doc="a pair's result is reused while each map's segment count stays within this (or "
        "2 segments) of the count it was computed on",
        minimum=0.0,
    )
    stability_margin: float = param(
        0.25,
        unit="",
        doc="a link of the previous tree stays in the tree unless another link's value "
        "exceeds it by this fraction (placements do not flip between similar links)",
        minimum=0.0,
    )
    link_max_seen_through: float = param(
        1.0,
        unit="m",
        doc="validity threshold: a link is refused when more than this length of either map "
        "(and more than link_max_seen_through_fraction of its value) lies in free space the "
        "other robot saw from its keyframes (only when keyframe poses are given)",
        minimum=0.0,
    )
    link_max_seen_through_fraction: float = param(
        0.1,
        unit="",
        doc="see link_max_seen_through: the allowance as a fraction of the link's value (large "
        "overlaps of drifting maps tolerate a little more)",
        minimum=0.0,
    )
    free_space_margin: float = param(
        0.5,
        unit="m",
        doc="a wall of the other map is in a robot's free space when it lies at least this much "
        "nearer a viewpoint than the robot's own map along the same bearing",
        minimum=0.0,
    )
    free_space_min_length: float = param(
        1.0,
        unit="m",
        doc="only segments at least this long are tested against the other robot's free space "
        "(walls; short pieces are furniture, exhibits and people, which move or are seen from "
        "one side only)",
        minimum=0.0,
    )
    view_spacing: float = param(
        1.0,
        unit="m",
        doc="viewpoints (keyframe poses) closer than this to one already kept add no evidence",
        minimum=0.0,
    )
    max_views: int = param(
        60,
        unit="",
        doc="at most this many viewpoints per map, evenly spread over the kept ones",
        minimum=1,
    )
    view_range: float = param(
        8.0,
        unit="m",
        doc="free space reaches at most this far from a viewpoint (a wall must be seen in the "
        "robot's own map within it)",
        minimum=0.0,
        exclusive_minimum=True,
    )
    view_spread: int = param(
        6,
        unit="bearings",
        doc="free space along a bearing reaches only the nearest wall within this many "
        "bearings either side (gaps between a map's segments are not seen through)",
        minimum=0,
    )
    view_field: float = param(
        float(np.pi),
        unit="rad",
        doc="field of view claimed around each keyframe's heading (the laser's forward "
        "direction; 180 degrees is the narrowest common laser: wider ones claim less than they "
        "saw, never more)",
        minimum=0.0,
        exclusive_minimum=True,
        maximum=2.0 * np.pi,
    )
    view_beams: int = param(
        360,
        unit="",
        doc="bearings per full turn at which the robot's own map is ray cast",
        minimum=8,
    )
    fusion_tolerance: float = param(
        0.05,
        unit="m",
        doc="FUSIONTOLERANCE of the global map: a fused polyline stays this close to every "
        "segment it replaces",
        minimum=0.0,
        exclusive_minimum=True,
    )
    integrate: IntegrateConfig = dataclasses.field(default_factory=IntegrateConfig)

    def __post_init__(self) -> None:
        validate(self)

    def correlation(self) -> CorrelationConfig:
        """The map correlation's settings from this config."""
        return CorrelationConfig(
            cell=self.correlation_cell, free_space_weight=self.free_space_weight
        )

    def link_config(self, hypotheses: int | None = None, viewed: bool = False) -> IntegrateConfig:
        """``integrate`` with this config's validity thresholds (``viewed``: those for two
        robots whose viewpoints are known) and hypothesis budget."""
        return dataclasses.replace(
            self.integrate,
            min_match_value=self.link_min_value,
            min_match_fraction=self.viewed_link_min_fraction if viewed else self.link_min_fraction,
            min_cross_support=self.link_min_cross_support,
            max_hypotheses=self.max_hypotheses if hypotheses is None else hypotheses,
            all_pairs_below=self.hypothesis_segments,
            refine_candidates=min(self.integrate.refine_candidates, 3),
        )


# --- One pair of maps ------------------------------------------------------------------------


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
    def of(segments: FloatArray) -> MapSignature:
        array = np.ascontiguousarray(segments, dtype=np.float64)
        length = float(lines_of(array).length.sum()) if len(array) else 0.0
        return MapSignature(len(array), length, hashlib.sha1(array.tobytes()).hexdigest())

    def close_to(self, earlier: MapSignature, config: MergeConfig) -> bool:
        """Did the map change little since ``earlier``? (Then a pair result is reused.)

        Identical content, or: segment count within ``reuse_count_change`` % (at least 2
        segments) and total length within ``reuse_length_change`` % of the earlier map's. A
        growing map is re-matched once it grew by that much since the result was computed.
        """
        if self.digest == earlier.digest:
            return True
        count_slack = max(2.0, config.reuse_count_change / 100.0 * earlier.count)
        length_slack = config.reuse_length_change / 100.0 * earlier.length
        return (
            abs(self.count - earlier.count) <= count_slack
            and abs(self.length - earlier.length) <= length_slack
        )


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
    order = np.argsort(-lines_of(segments).length, kind="stable")
    return np.asarray(segments[order[:count]])


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
    map_a: FloatArray,
    map_b: FloatArray,
    config: MergeConfig,
    views_a: MapViews | None = None,
    views_b: MapViews | None = None,
    drawings: tuple[Drawing, Drawing] | None = None,
) -> MapMatch:
    """How map b lies in map a, and whether to trust it.

    1. Candidates: INTEGRATE's own hypotheses (Amigoni Alg. 2: equal angles between pairs of
       the ``hypothesis_segments`` longest segments, ranked on the ``coarse_segments`` longest)
       and the ``correlation_candidates`` best placements of the map correlation
       (:mod:`multi_robot_mapper.core.correlation`: every translation, for each rotation the
       wall directions allow; with the robots' views, walls in the other's free space count
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
    if len(map_a) == 0 or len(map_b) == 0:
        return _no_match()
    drawing_a, drawing_b = drawings or (
        draw_map(map_a, views_a, config),
        draw_map(map_b, views_b, config),
    )
    judge_a = longest(map_a, config.judge_segments)
    judge_b = longest(map_b, config.judge_segments)
    candidates = _candidates(map_a, map_b, drawing_a, drawing_b, config)
    places = _best_places(judge_a, judge_b, drawing_a, drawing_b, candidates, config)
    if places is None:
        return _no_match()
    refined, scores = places
    best = int(np.argmax(scores))
    rivals = np.array([_distinct(row, refined[best]) for row in refined], dtype=bool)
    rival = float(scores[rivals].max()) if rivals.any() else 0.0
    score = float(scores[best])
    uniqueness = score / rival if rival > 0.0 else (np.inf if score > 0.0 else 0.0)
    viewed = views_a is not None and views_b is not None
    # INTEGRATE evaluates the chosen place (Alg. 4): every start there (the refined one and
    # the candidates near it), the best refined.
    near = [row for row in candidates if not _distinct(row, refined[best])]
    same_place = np.vstack((refined[~rivals], *near))
    result = integrate(
        judge_a,
        judge_b,
        config.link_config(hypotheses=len(same_place), viewed=viewed),
        heuristics=(),
        ordered=(False, False),
        extra_hypotheses=same_place,
    )
    calls = 2  # INTEGRATE's candidates, and the evaluation
    if result.value <= 0.0:
        return MapMatch(result, 0.0, False, calls, 0.0, uniqueness)
    tight = tight_fraction(judge_a, judge_b, result.T_1_2, config)
    valid = result.valid and tight >= (
        config.viewed_link_min_tight_fraction if viewed else config.link_min_tight_fraction
    )
    if viewed:
        valid = valid and uniqueness >= config.link_min_uniqueness
    through = 0.0
    if valid and (views_a is not None or views_b is not None):
        through = free_space_conflict(map_a, views_a, map_b, views_b, result.matrix, config)
        valid = through <= seen_through_allowance(result.value, config)
    return MapMatch(result, tight, valid, calls, through, uniqueness)


def _no_match() -> MapMatch:
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
    judge_a: FloatArray,
    judge_b: FloatArray,
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
    rough[refused(judge_a, judge_b, candidates, link)] = -np.inf
    keep: list[int] = []
    for k in np.argsort(-rough, kind="stable"):
        if len(keep) == _REFINED or not np.isfinite(rough[k]):
            break
        if all(_distinct(candidates[k], candidates[j]) for j in keep):
            keep.append(int(k))
    if not keep:
        return None
    refined = refine_many(judge_a, judge_b, candidates[keep], link)
    scores = placement_scores(drawing_a, drawing_b, refined, correlation)
    scores[refused(judge_a, judge_b, refined, link)] = -np.inf
    if not np.isfinite(scores).any():
        return None
    return refined, scores


def draw_map(segments: FloatArray, views: MapViews | None, config: MergeConfig) -> Drawing:
    """A map drawn for the correlation, with its free space when its views are known (one
    point per cell along each bearing marks every cell the beams cross)."""
    cell = config.correlation_cell
    free = np.zeros((0, 2)) if views is None else views.free_points(config, cell)
    return Drawing.of(segments, free, cell)


def _candidates(
    map_a: FloatArray,
    map_b: FloatArray,
    drawing_a: Drawing,
    drawing_b: Drawing,
    config: MergeConfig,
) -> FloatArray:
    """Candidate placements ``(theta, tx, ty)`` of map b in map a."""
    rows: list[FloatArray] = []
    k, c = config.hypothesis_segments, config.coarse_segments
    ranking = dataclasses.replace(config.link_config(), all_pairs_below=k)
    angles = integrate(
        longest(map_a, c),
        longest(map_b, c),
        ranking,
        heuristics=("all",),
        ordered=(False, False),
        hypothesis_sets=(longest(map_a, k), longest(map_b, k)),
    )
    if angles.value > 0.0:
        rows.append(angles.T_1_2.reshape(1, 3))
    correlation = config.correlation()
    rotations = rotation_candidates(map_a, map_b, correlation.rotations)
    peaks, _ = correlation_peaks(drawing_a, drawing_b, rotations, correlation)
    rows.append(peaks[: config.correlation_candidates])
    return np.vstack(rows)


def tight_fraction(
    segments1: FloatArray, segments2: FloatArray, T_1_2: FloatArray, config: MergeConfig
) -> float:
    """Overlap of matching segments within ``tight_distance`` under ``T_1_2`` (INTEGRATE's
    row), as a fraction of the shorter set's total length."""
    tight = dataclasses.replace(
        config.integrate,
        segment_distance_threshold=config.tight_distance
        / config.integrate.point_distance_tolerance,
    )
    scores = score_pairs(segments1, segments2, np.asarray(T_1_2)[None, :], tight)
    shorter = min(float(lines_of(segments1).length.sum()), float(lines_of(segments2).length.sum()))
    return float(scores.value.sum()) / max(shorter, 1e-9)


# --- Free space: what a robot saw from its keyframes ------------------------------------------


@dataclasses.dataclass(frozen=True)
class MapViews:
    """Free space a robot saw: its own map ray cast from its viewpoints (``view_field``
    around each keyframe's heading).

    A partial map carries no scans, but its keyframe poses say where the laser stood; the
    robot's own walls seen from there bound the space its beams crossed (a door the map does
    not close leaves no wall on that bearing, and nothing is claimed there). Another robot's
    wall placed inside that space contradicts the placement: the two buildings only look alike
    (the look-alike rooms and corridors segment overlap cannot tell apart).
    """

    poses: FloatArray  # (K, 3) viewpoints (laser poses) in the robot's map frame
    ranges: FloatArray  # (K, B) the map's range at each bearing of each view (inf: no wall)
    angle_min: float  # bearing of column 0 in each viewpoint's frame (rad)
    angle_increment: float  # rad between columns

    @staticmethod
    def of(segments: FloatArray, keyframe_poses: FloatArray, config: MergeConfig) -> MapViews:
        """The views of a map from its keyframe poses, at least ``view_spacing`` apart and at
        most ``max_views`` of them, ``view_field`` wide around each heading."""
        poses = np.asarray(keyframe_poses, dtype=np.float64).reshape(-1, 3)
        kept: list[int] = []
        for index in range(len(poses)):  # greedy thinning over keyframes (a few hundred)
            if (
                not kept
                or np.min(np.hypot(*(poses[kept, :2] - poses[index, :2]).T)) >= config.view_spacing
            ):
                kept.append(index)
        if len(kept) > config.max_views:
            kept = [kept[i] for i in np.linspace(0, len(kept) - 1, config.max_views).astype(int)]
        chosen = poses[kept]
        step = 2.0 * np.pi / config.view_beams
        beams = max(2, round(config.view_field / step) + 1)
        first = -0.5 * step * (beams - 1)
        ranges = raycast_fans(segments, chosen, first, step, beams, config.view_range)
        return MapViews(chosen, ranges, first, step)

    def free_limits(self, spread: int) -> FloatArray:
        """(K, B) how far free space reaches along each bearing: the nearest wall within
        ``spread`` bearings either side (a gap between two segments is not seen through), and
        nothing (-inf) where some bearing of that window hits no wall or lies beyond the edge
        of the field of view (the field does not wrap round, even at 2 pi: its first and last
        ``spread`` bearings claim nothing)."""
        limits = np.where(np.isfinite(self.ranges), self.ranges, -np.inf)
        if spread > 0 and limits.shape[1]:
            padded = np.pad(limits, ((0, 0), (spread, spread)), constant_values=-np.inf)
            windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * spread + 1, axis=1)
            limits = windows.min(axis=2)
        return np.asarray(limits)

    def free_points(self, config: MergeConfig, spacing: float) -> FloatArray:
        """Points every ``spacing`` metres along every bearing of every view, out to
        ``free_space_margin`` before the wall that ends it (:meth:`free_limits`): where the
        robot's laser saw nothing."""
        reach = self.free_limits(config.view_spread) - config.free_space_margin
        steps = np.arange(spacing, config.view_range, spacing)
        view, bearing, step = np.nonzero(reach[:, :, None] > steps[None, None, :])
        if view.size == 0:
            return np.zeros((0, 2))
        heading = self.poses[view, 2] + self.angle_min + self.angle_increment * bearing
        distance = steps[step]
        return np.column_stack(
            (
                self.poses[view, 0] + distance * np.cos(heading),
                self.poses[view, 1] + distance * np.sin(heading),
            )
        )


def seen_through_length(views: MapViews, segments: FloatArray, config: MergeConfig) -> float:
    """Length of the walls among ``segments`` (in the views' map frame; those at least
    ``free_space_min_length`` long) lying in the free space of ``views``: nearer some
    viewpoint than the map's own wall on that bearing by ``free_space_margin``."""
    spacing = 0.2  # m between the points tested along each wall
    walls = segments[lines_of(segments).length >= config.free_space_min_length]
    if len(walls) == 0 or len(views.poses) == 0:
        return 0.0
    points, owner = sample_segments(walls, spacing)
    # Each point stands for its wall's length over its points (a wall's two ends both count).
    weight = (lines_of(walls).length / np.bincount(owner, minlength=len(walls)))[owner]
    limits = views.free_limits(config.view_spread)
    # Every point in every viewpoint's frame at once: (K, P) bearings and distances.
    dx = points[None, :, 0] - views.poses[:, 0, None]
    dy = points[None, :, 1] - views.poses[:, 1, None]
    bearing = se2.wrap_angle(np.arctan2(dy, dx) - views.poses[:, 2, None])
    distance = np.hypot(dx, dy)
    column = np.rint((bearing - views.angle_min) / views.angle_increment).astype(np.int64)
    inside = (column >= 0) & (column < limits.shape[1])
    reach = np.take_along_axis(limits, np.where(inside, column, 0), axis=1)
    seen = inside & (distance < reach - config.free_space_margin)
    return float(weight[seen.any(axis=0)].sum())


ViewSource = Callable[[str], "MapViews | None"]


def _no_views(robot: str) -> MapViews | None:
    return None


def view_source(
    maps: Mapping[str, FloatArray], viewpoints: Mapping[str, FloatArray], config: MergeConfig
) -> ViewSource:
    """Each robot's :class:`MapViews` (None without viewpoints or without a map: no free
    space known), cast on first use: a re-run whose pairs are all reused casts none."""
    cache: dict[str, MapViews | None] = {}

    def views(robot: str) -> MapViews | None:
        if robot not in cache:
            poses = np.asarray(viewpoints.get(robot, np.zeros((0, 3))), dtype=np.float64)
            known = len(poses.reshape(-1, 3)) > 0 and len(maps[robot]) > 0
            cache[robot] = MapViews.of(maps[robot], poses, config) if known else None
        return cache[robot]

    return views


def seen_through_allowance(value: float, config: MergeConfig) -> float:
    """How much wall in the other robot's free space a link of ``value`` m tolerates:
    ``link_max_seen_through``, or that fraction of the value when larger (drifting maps)."""
    return max(config.link_max_seen_through, config.link_max_seen_through_fraction * value)


def free_space_conflict(
    map_a: FloatArray,
    views_a: MapViews | None,
    map_b: FloatArray,
    views_b: MapViews | None,
    T_a_b: FloatArray,
    config: MergeConfig,
) -> float:
    """The larger of: map b (moved by ``T_a_b``) in a's free space, map a in b's (metres)."""
    through = 0.0
    if views_a is not None:
        through = seen_through_length(views_a, se2.transform_segments(T_a_b, map_b), config)
    if views_b is not None:
        back = se2.transform_segments(se2.invert(T_a_b), map_a)
        through = max(through, seen_through_length(views_b, back, config))
    return through


def _link(robot_a: str, robot_b: str, match: MapMatch) -> Link:
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


def _fuse(
    segments1: FloatArray,
    owner1: IntArray,
    segments2: FloatArray,
    owner2: IntArray,
    config: MergeConfig,
) -> tuple[FloatArray, IntArray]:
    """S1 fused with S2 (already in S1's frame), Amigoni Alg. 5 (core.fusion)."""
    if len(segments1) == 0 or len(segments2) == 0:
        return (
            np.vstack((segments1.reshape(-1, 4), segments2.reshape(-1, 4))),
            np.concatenate((owner1, owner2)).astype(np.int64),
        )
    return fuse(segments1, owner1, segments2, owner2, config.integrate, config.fusion_tolerance)


def _as_map(segments: FloatArray) -> FloatArray:
    array = np.asarray(segments, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 4:
        if array.size == 0:
            return np.zeros((0, 4))
        raise ValueError(f"a partial map must be an (N, 4) segment array, got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("a partial map holds NaN or infinite coordinates")
    return array


# --- Unknown order: pairwise links, maximum-value spanning tree ------------------------------


@dataclasses.dataclass
class MergeResult:
    """Every robot frame in ``map`` (or unmerged), the links used and the global map."""

    robots: list[str]  # sorted; segment_robot indexes this list
    placements: dict[str, Pose | None]  # T_map_robot as (x, y, theta); None = unmerged
    reference: str | None  # the robot whose map frame is `map` (None: no robots)
    links: list[Link]  # the spanning tree's edges, the transforms composed
    pairs: dict[tuple[str, str], PairRecord]  # every pair's result (a < b), reusable
    segments: FloatArray  # (M, 4) fused global map in `map`
    segment_robot: IntArray  # (M,) index into robots of each segment's owner
    timings: dict[str, float]  # seconds: pairs_s, tree_s, fusion_s, total_s
    # pairs_computed, pairs_reused, integrate_calls, links_valid, cycle_conflicts
    stats: dict[str, int]

    @property
    def unmerged(self) -> list[str]:
        """Robots with no valid chain of links to the reference."""
        return [r for r in self.robots if self.placements[r] is None]

    def matrix(self, robot: str) -> FloatArray | None:
        """T_map_robot as a 3x3 matrix, or None when the robot is unmerged."""
        pose = self.placements.get(robot)
        return None if pose is None else se2.matrix_from_pose(*pose)


def pair_links(
    maps: Mapping[str, FloatArray],
    config: MergeConfig,
    previous: Mapping[tuple[str, str], PairRecord] | None = None,
    views: ViewSource | None = None,
) -> tuple[dict[tuple[str, str], PairRecord], int]:
    """INTEGRATE every pair (a, b) with a < b, reusing earlier results where maps barely
    changed (:meth:`MapSignature.close_to`), each judged on free space where ``views`` has
    the robots' views. Returns the records and the INTEGRATE calls."""
    view = views or _no_views
    robots = sorted(maps)
    signatures = {r: MapSignature.of(maps[r]) for r in robots}
    records: dict[tuple[str, str], PairRecord] = {}
    calls = 0
    drawings: dict[str, Drawing] = {}

    def drawing(robot: str) -> Drawing:  # once per robot, on first use
        if robot not in drawings:
            drawings[robot] = draw_map(maps[robot], view(robot), config)
        return drawings[robot]

    for i, a in enumerate(robots):
        for b in robots[i + 1 :]:
            old = None if previous is None else previous.get((a, b))
            if (
                old is not None
                and signatures[a].close_to(old.signature_a, config)
                and signatures[b].close_to(old.signature_b, config)
            ):
                records[(a, b)] = dataclasses.replace(old, reused=True)
                continue
            if len(maps[a]) and len(maps[b]):
                drawn = (drawing(a), drawing(b))
                match = match_maps(maps[a], maps[b], config, view(a), view(b), drawn)
            else:
                match = _no_match()
            calls += match.integrate_calls
            records[(a, b)] = PairRecord(_link(a, b, match), signatures[a], signatures[b], False)
    return records, calls


JoinCheck = Callable[[Link, Mapping[str, FloatArray], Mapping[str, FloatArray], FloatArray], bool]


def spanning_tree(
    robots: Sequence[str],
    links: Sequence[Link],
    previous_edges: set[tuple[str, str]] | None = None,
    margin: float = 0.0,
    joins: JoinCheck | None = None,
) -> list[Link]:
    """Maximum-value spanning forest of the valid links (Kruskal).

    Edges of the previous tree count as ``(1 + margin)`` times their value, so a new link
    replaces one only when clearly better. Ties break on the robot names: the result does not
    depend on the order the robots or links come in. ``joins(link, group_a, group_b,
    T_ga_gb)``, when given, may refuse a link that would join two groups of robots (each
    ``robot -> T_group_robot``; ``T_ga_gb`` places group b in group a): the next link is
    tried instead.
    """
    kept = previous_edges or set()

    def weight(link: Link) -> float:
        key = (link.robot_a, link.robot_b)
        return link.value * (1.0 + margin) if key in kept else link.value

    order = sorted(
        (lk for lk in links if lk.valid), key=lambda lk: (-weight(lk), lk.robot_a, lk.robot_b)
    )
    parent = {r: r for r in robots}
    groups: dict[str, dict[str, FloatArray]] = {r: {r: np.eye(3)} for r in robots}

    def root(r: str) -> str:
        while parent[r] != r:
            parent[r] = parent[parent[r]]
            r = parent[r]
        return r

    tree: list[Link] = []
    for link in order:
        ra, rb = root(link.robot_a), root(link.robot_b)
        if ra == rb:
            continue
        group_a, group_b = groups[ra], groups[rb]
        T_ga_gb = group_a[link.robot_a] @ link.matrix @ se2.invert(group_b[link.robot_b])
        if joins is not None and not joins(link, group_a, group_b, T_ga_gb):
            continue
        if ra < rb:  # the smaller name stays the root; the other group moves into its frame
            group_a.update({r: T_ga_gb @ T for r, T in group_b.items()})
            parent[rb] = ra
            del groups[rb]
        else:
            T_gb_ga = se2.invert(T_ga_gb)
            group_b.update({r: T_gb_ga @ T for r, T in group_a.items()})
            parent[ra] = rb
            del groups[ra]
        tree.append(link)
    return tree


def free_space_join(
    maps: Mapping[str, FloatArray], views: ViewSource, config: MergeConfig
) -> JoinCheck:
    """A :func:`spanning_tree` join check: two groups of robots join only if no robot's walls
    lie in the free space any robot of the other group saw (beyond the link's allowance,
    ``link_max_seen_through`` or that fraction of its value).

    A pair's own link was judged on the two maps alone; a group has more viewpoints. A
    look-alike place can fit one robot's map and still cross rooms a third robot saw empty.
    """

    def joins(
        link: Link,
        group_a: Mapping[str, FloatArray],
        group_b: Mapping[str, FloatArray],
        T_ga_gb: FloatArray,
    ) -> bool:
        if len(group_a) == 1 and len(group_b) == 1:
            return True  # exactly the pair match_maps judged
        allowed = seen_through_allowance(link.value, config)
        for x, T_ga_x in group_a.items():
            for y, T_gb_y in group_b.items():
                view_x, view_y = views(x), views(y)
                if view_x is None and view_y is None:
                    continue
                T_x_y = se2.invert(T_ga_x) @ T_ga_gb @ T_gb_y
                through = free_space_conflict(maps[x], view_x, maps[y], view_y, T_x_y, config)
                if through > allowed:
                    return False
        return True

    return joins


def _components(robots: Sequence[str], tree: Sequence[Link]) -> list[list[str]]:
    adjacency: dict[str, list[str]] = {r: [] for r in robots}
    for link in tree:
        adjacency[link.robot_a].append(link.robot_b)
        adjacency[link.robot_b].append(link.robot_a)
    seen: set[str] = set()
    groups: list[list[str]] = []
    for start in robots:
        if start in seen:
            continue
        group, stack = [], [start]
        seen.add(start)
        while stack:
            r = stack.pop()
            group.append(r)
            for n in adjacency[r]:
                if n not in seen:
                    seen.add(n)
                    stack.append(n)
        groups.append(sorted(group))
    return groups


def choose_reference(
    robots: Sequence[str],
    tree: Sequence[Link],
    lengths: Mapping[str, float],
    previous: str | None = None,
) -> str:
    """The largest map (total segment length) in the largest linked group of robots.

    ``previous`` (the last run's reference) is kept while it is in a group as large as any,
    so the ``map`` frame does not jump between runs.
    """
    groups = _components(robots, tree)
    size = max(len(g) for g in groups)
    if (
        previous is not None
        and previous in robots
        and len(next(g for g in groups if previous in g)) == size
    ):
        return previous
    best = min(
        (g for g in groups if len(g) == size), key=lambda g: (-sum(lengths[r] for r in g), g[0])
    )
    return min(best, key=lambda r: (-lengths[r], r))


def place(reference: str, robots: Sequence[str], tree: Sequence[Link]) -> dict[str, FloatArray]:
    """T_map_robot of every robot linked to ``reference`` (the frame `map`), composed along
    the tree (breadth first, so the order of placing is also the order of fusing)."""
    adjacency: dict[str, list[tuple[str, FloatArray]]] = {r: [] for r in robots}
    for link in tree:
        T_a_b = link.matrix
        adjacency[link.robot_a].append((link.robot_b, T_a_b))
        adjacency[link.robot_b].append((link.robot_a, se2.invert(T_a_b)))
    placed: dict[str, FloatArray] = {reference: np.eye(3)}
    queue = [reference]
    while queue:
        a = queue.pop(0)
        for b, T_a_b in sorted(adjacency[a], key=lambda item: item[0]):
            if b not in placed:
                placed[b] = placed[a] @ T_a_b
                queue.append(b)
    return placed


def cycle_conflicts(
    placed: Mapping[str, FloatArray],
    links: Sequence[Link],
    distance: float = 0.3,
    angle: float = np.radians(3.0),
) -> list[Link]:
    """Valid links between placed robots that disagree with the placements (by more than
    ``distance`` or ``angle``): a cycle of links that does not close. Some link on that cycle
    is wrong (self-similar buildings match at wrong offsets); reported, not resolved."""
    out = []
    for link in links:
        if not (link.valid and link.robot_a in placed and link.robot_b in placed):
            continue
        T_a_b = se2.invert(placed[link.robot_a]) @ placed[link.robot_b]
        dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_a_b) @ link.matrix)
        if np.hypot(dx, dy) > distance or abs(dtheta) > angle:
            out.append(link)
    return out


def merge(
    maps: Mapping[str, FloatArray],
    config: MergeConfig | None = None,
    previous: MergeResult | None = None,
    reference: str | None = None,
    viewpoints: Mapping[str, FloatArray] | None = None,
) -> MergeResult:
    """Merge partial maps whose relative poses are unknown, in no particular order.

    ``maps``: robot name -> (N, 4) segments in that robot's own map frame. ``viewpoints``:
    robot name -> (K, 3) keyframe poses in the same frame, where the robot's laser stood; a
    link putting either map in the free space the other robot saw is refused (a robot without
    viewpoints is judged on segments alone). ``reference`` (or
    ``config.reference``) names the robot whose frame becomes ``map``; by default the previous
    run's reference is kept, else the largest map of the largest linked group is taken.
    ``previous`` (the last result) supplies pair results to reuse and the tree to keep.
    """
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    clean = {str(r): _as_map(s) for r, s in maps.items()}
    robots = sorted(clean)
    chosen = reference if reference is not None else (config.reference or None)
    if chosen is not None and chosen not in clean:
        raise ValueError(f"reference robot {chosen!r} has no map; robots: {', '.join(robots)}")
    if not robots:
        empty = np.zeros((0, 4))
        return MergeResult([], {}, None, [], {}, empty, np.zeros(0, dtype=np.int64), {}, {})
    views = view_source(clean, viewpoints or {}, config)
    records, calls = pair_links(clean, config, None if previous is None else previous.pairs, views)
    pairs_done = time.perf_counter()
    lengths = {r: MapSignature.of(clean[r]).length for r in robots}
    kept = set() if previous is None else {(lk.robot_a, lk.robot_b) for lk in previous.links}
    all_links = [record.link for record in records.values()]
    joins = free_space_join(clean, views, config) if viewpoints else None
    tree = spanning_tree(robots, all_links, kept, config.stability_margin, joins)
    if chosen is None:
        chosen = choose_reference(
            robots, tree, lengths, None if previous is None else previous.reference
        )
    placed = place(chosen, robots, tree)
    used = [lk for lk in tree if lk.robot_a in placed and lk.robot_b in placed]
    tree_done = time.perf_counter()
    # Global map: fuse each placed map, in the order robots were placed (reference first).
    segments = np.zeros((0, 4))
    owner = np.zeros(0, dtype=np.int64)
    for robot, T_map_robot in placed.items():
        moved = se2.transform_segments(T_map_robot, clean[robot])
        index = np.full(len(moved), robots.index(robot), dtype=np.int64)
        segments, owner = _fuse(segments, owner, moved, index, config)
    finished = time.perf_counter()
    placements: dict[str, Pose | None] = {
        r: (se2.pose_from_matrix(placed[r]) if r in placed else None) for r in robots
    }
    return MergeResult(
        robots=robots,
        placements=placements,
        reference=chosen,
        links=used,
        pairs=records,
        segments=segments,
        segment_robot=owner,
        timings={
            "pairs_s": pairs_done - started,
            "tree_s": tree_done - pairs_done,
            "fusion_s": finished - tree_done,
            "total_s": finished - started,
        },
        stats={
            "pairs_computed": sum(not r.reused for r in records.values()),
            "pairs_reused": sum(r.reused for r in records.values()),
            "integrate_calls": calls,
            "links_valid": sum(lk.valid for lk in all_links),
            "cycle_conflicts": len(cycle_conflicts(placed, all_links)),
        },
    )


# --- Known order: the paper's three methods (Sec. IV) ----------------------------------------


@dataclasses.dataclass
class OrderedMerge:
    """The result of merging an ordered list of maps; ``map`` is the first map's frame."""

    method: str
    placements: list[Pose | None]  # T_map_i (x, y, theta) per map; None = never integrated
    links: list[Link]  # every INTEGRATE call (robots named by their index)
    segments: FloatArray  # (M, 4) final map S_1..n
    segment_robot: IntArray  # (M,) index of the map each segment came from
    integrations: int  # pairs of maps INTEGRATE was run on (the paper's count)
    elapsed_s: float


def _ordered_result(
    method: str,
    count: int,
    placed: Mapping[int, FloatArray],
    links: list[Link],
    segments: FloatArray,
    owner: IntArray,
    started: float,
) -> OrderedMerge:
    placements: list[Pose | None] = [
        se2.pose_from_matrix(placed[i]) if i in placed else None for i in range(count)
    ]
    return OrderedMerge(
        method, placements, links, segments, owner, len(links), time.perf_counter() - started
    )


def merge_sequential(maps: Sequence[FloatArray], config: MergeConfig | None = None) -> OrderedMerge:
    """Sequential method (IV-A): S_1,2 = INTEGRATE(S_1, S_2), S_1,2,3 = INTEGRATE(S_1,2, S_3)...

    A map whose integration is not valid is left out (``None``) and the next one tried.
    """
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    clean = [_as_map(m) for m in maps]
    if not clean:
        return OrderedMerge("sequential", [], [], np.zeros((0, 4)), np.zeros(0, np.int64), 0, 0.0)
    segments = clean[0]
    owner = np.zeros(len(segments), dtype=np.int64)
    placed: dict[int, FloatArray] = {0: np.eye(3)}
    links: list[Link] = []
    for i in range(1, len(clean)):
        result = match_maps(segments, clean[i], config)
        links.append(_link("0", str(i), result))
        if not result.valid:
            continue
        placed[i] = result.matrix
        moved = se2.transform_segments(placed[i], clean[i])
        segments, owner = _fuse(
            segments, owner, moved, np.full(len(moved), i, dtype=np.int64), config
        )
    return _ordered_result("sequential", len(clean), placed, links, segments, owner, started)


@dataclasses.dataclass
class _Node:
    """A partial map of the tree method: segments in its first member's frame."""

    segments: FloatArray
    owner: IntArray
    members: dict[int, FloatArray]  # map index -> T_node_map
    first: int


def merge_tree(maps: Sequence[FloatArray], config: MergeConfig | None = None) -> OrderedMerge:
    """Tree method (IV-B): each map integrated with the next, level after level, until one.

    Level 0 is the maps; level l+1 integrates every node of level l with the next one
    (n(n-1)/2 INTEGRATE calls). A failed integration keeps the left node as it is, so a map
    missing from one node can still arrive through the next.
    """
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    clean = [_as_map(m) for m in maps]
    if not clean:
        return OrderedMerge("tree", [], [], np.zeros((0, 4)), np.zeros(0, np.int64), 0, 0.0)
    nodes = [
        _Node(m, np.full(len(m), i, dtype=np.int64), {i: np.eye(3)}, i) for i, m in enumerate(clean)
    ]
    links: list[Link] = []
    while len(nodes) > 1:
        level: list[_Node] = []
        for left, right in itertools.pairwise(nodes):
            result = match_maps(left.segments, right.segments, config)
            links.append(_link(str(left.first), str(right.first), result))
            if not result.valid:
                level.append(left)
                continue
            T_left_right = result.matrix
            members = dict(left.members)
            for index, T_right_map in right.members.items():
                members.setdefault(index, T_left_right @ T_right_map)
            moved = se2.transform_segments(T_left_right, right.segments)
            segments, owner = _fuse(left.segments, left.owner, moved, right.owner, config)
            level.append(_Node(segments, owner, members, left.first))
        nodes = level
    root = nodes[0]
    return _ordered_result(
        "tree", len(clean), root.members, links, root.segments, root.owner, started
    )


def merge_pivot(maps: Sequence[FloatArray], config: MergeConfig | None = None) -> OrderedMerge:
    """Pivot method (IV-C, Algorithm 6), the cleaner variant.

    t_i-1,i = INTEGRATE(S_i-1, S_i) (two partial maps of similar size), t_1,i = t_1,i-1 t_i-1,i,
    and S_1..i = fusion of S_1..i-1 with S_i moved by t_1,i (S_i, not S_i-1,i: each map's
    segments are fused once). When S_i-1 was left out, the last map placed is the pivot.
    """
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    clean = [_as_map(m) for m in maps]
    if not clean:
        return OrderedMerge("pivot", [], [], np.zeros((0, 4)), np.zeros(0, np.int64), 0, 0.0)
    segments = clean[0]
    owner = np.zeros(len(segments), dtype=np.int64)
    placed: dict[int, FloatArray] = {0: np.eye(3)}
    links: list[Link] = []
    pivot = 0
    for i in range(1, len(clean)):
        result = match_maps(clean[pivot], clean[i], config)
        links.append(_link(str(pivot), str(i), result))
        if not result.valid:
            continue
        placed[i] = placed[pivot] @ result.matrix  # t_1,i = t_1,pivot t_pivot,i
        moved = se2.transform_segments(placed[i], clean[i])
        segments, owner = _fuse(
            segments, owner, moved, np.full(len(moved), i, dtype=np.int64), config
        )
        pivot = i
    return _ordered_result("pivot", len(clean), placed, links, segments, owner, started)
