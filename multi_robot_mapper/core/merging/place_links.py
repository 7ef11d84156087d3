"""Links between robots: where a place of one map lies on another map, and how sure that is.

A place (:class:`~multi_robot_mapper.core.merging.places.Place`) is searched for on the whole of
another map with no guess, in two steps:

1. **search**: the map correlation (:mod:`~multi_robot_mapper.core.evidence.correlation`)
   scores every translation of the place for each rotation the wall directions allow, walls
   lying in the other robot's free space counting against; the ``link_hypotheses`` best
   distinct placements are kept. The other map is transformed once for all its places
   (:class:`Target`). With ``shape_hypotheses``, Wolter's shape matching adds placements of
   its own (:mod:`~multi_robot_mapper.core.merging.shape_placements`, with ``ShapeConfig``'s
   defaults; off by default: it raised merge success on no shared log);
2. **verification**: INTEGRATE evaluates and refines those placements on the other map's walls
   around them, with both sides' synthetic beams (:func:`places.viewpoints`), and returns its
   calibrated confidence (:mod:`core.matching.confidence`): the probability that the placement
   is right within 0.30 m / 5 deg, low when a rival placement fits about as well. The best
   placement and its best rival become :class:`LinkCandidate`\\ s, each also with its *fit*:
   the same confidence with the rival evidence left out (how well the place fits there at
   all). A corridor that fits at two places gives two candidates of good fit and low
   confidence; consistency with the pair's other links decides between them
   (:mod:`~multi_robot_mapper.core.merging.consistency`).

A candidate links the place's centre keyframe with the other map's keyframe nearest to where
the centre lands, by ``T_keyframe_centre``: relative to keyframes, a link stays valid when
either map moves its keyframes (its own loop closures).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.correlation import (
    CorrelationTarget,
    Drawing,
    ScoringRasters,
    correlation_peaks,
    rotation_candidates,
    scorer_rasters,
)
from multi_robot_mapper.core.evidence.placement import EVIDENCE_CORRELATION
from multi_robot_mapper.core.geometry import point_segment_distance
from multi_robot_mapper.core.matching import IntegrateConfig, MatchResult, integrate
from multi_robot_mapper.core.matching.beams import BeamAgreement, Viewpoint
from multi_robot_mapper.core.matching.confidence import MatchEvidence, confidence
from multi_robot_mapper.core.matching.refine import match_information
from multi_robot_mapper.core.matching.scoring import PairTolerance, pair_tolerance
from multi_robot_mapper.core.matching.shape import Shape
from multi_robot_mapper.core.matching.shape_config import ShapeConfig
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.free_space import FreeDrawing, MapViews, ViewRows
from multi_robot_mapper.core.merging.pairwise import MapSignature, draw_map, longest
from multi_robot_mapper.core.merging.places import MapUnit, Place, UnitKey, thin, viewpoints
from multi_robot_mapper.core.merging.shape_placements import shape_placements, view_shapes
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.segment_map import SegmentMap

FloatArray = NDArray[np.float64]

# Placements farther apart than this (or turned more) are different answers (rivals).
_DISTINCT_SHIFT = 1.0  # m
_DISTINCT_TURN = float(np.radians(10.0))
# The other map's walls within this much beyond place_radius of a placed centre are verified,
# the longest this many of them and of the place's (short pieces add cost, not evidence).
_CROP_MARGIN = 1.0  # m
_VERIFY_SEGMENTS = 120


@dataclasses.dataclass(frozen=True)
class LinkCandidate:
    """A place of one map found on another: keyframe ``centre`` of ``source`` lies at
    ``T_keyframe_centre`` in keyframe ``keyframe``'s frame of ``target``."""

    source: UnitKey
    centre: int
    target: UnitKey
    keyframe: int
    T_keyframe_centre: Pose  # x, y, theta
    T_target_centre: Pose  # the same placement in the target map's frame (when matched)
    confidence: float  # P(right), the rival placements included
    fit: float  # P(right) as if no rival placement existed
    value: float  # matched wall (m)
    rank: int  # 0: the best placement of the place on that map, 1: its best rival
    information: FloatArray  # (3, 3) of the keyframe-to-keyframe edge, gtsam's tangent order

    def identity(self) -> tuple[object, ...]:
        """What the candidate says (its information matrix follows from the same match): two
        updates that found the same candidates decide alike."""
        return (
            self.source,
            self.centre,
            self.target,
            self.keyframe,
            self.T_keyframe_centre,
            self.confidence,
            self.fit,
            self.value,
            self.rank,
        )


@dataclasses.dataclass(frozen=True)
class Target:
    """A map prepared to be searched for places: its drawing for the correlation (transformed
    once), and its keyframe poses (the viewpoints of the verification)."""

    unit: MapUnit
    signature: MapSignature
    drawing: Drawing
    correlation: CorrelationTarget
    view_poses: FloatArray  # (V, 3) keyframe poses thinned to view_spacing
    views: MapViews | None  # the free space the robot saw (None: no keyframe poses)
    shapes: list[Shape]  # Wolter's shape all round from each view pose (shape_hypotheses)

    @staticmethod
    def of(unit: MapUnit, config: MergeConfig, rows: ViewRows | None = None) -> Target:
        """``unit`` prepared (``rows``: views cast before, :meth:`MapViews.of`)."""
        views = (
            MapViews.of(unit.segments, unit.poses, config.view_fan(), rows)
            if len(unit.poses)
            else None
        )
        drawing = draw_map(unit.segment_map, views, config.free_drawing())
        correlation = config.correlation()
        # A place (walls and free space) reaches place_radius from its centre: the grid must
        # hold it without wrapping round (its middle may lie off its centre).
        reach = 2.0 * config.place_radius
        prepared = CorrelationTarget.of(drawing, reach, correlation.cell, correlation.blur)
        poses = unit.poses[thin(unit.poses, config.view_spacing)]
        shapes = (
            view_shapes(unit.segments, poses, config.place_radius, ShapeConfig())
            if config.shape_hypotheses
            else []
        )
        signature = MapSignature.of(unit.segment_map)
        return Target(unit, signature, drawing, prepared, poses, views, shapes)

    @functools.cached_property
    def rasters(self) -> ScoringRasters:
        """The drawing's rasters at the evidence model's scale, made once per map content
        (every pair with this map weighs its placements on them; issue 50)."""
        return scorer_rasters(self.drawing, EVIDENCE_CORRELATION.cell, EVIDENCE_CORRELATION.blur)


def place_drawing(place: Place, drawing: FreeDrawing, radius: float) -> Drawing:
    """A place drawn for the correlation, with its free space (within ``radius``,
    ``place_radius``, of its centre, like its walls: the place is a disk)."""
    free = place.views.free_points(*drawing)
    free = free[np.hypot(free[:, 0], free[:, 1]) <= radius]
    return Drawing.of(place.segment_map, free, drawing.cell)


def place_config(config: MergeConfig) -> IntegrateConfig:
    """INTEGRATE's settings for verifying placements of places: its matching tolerances,
    every hypothesis given evaluated and refined, no slide along corridors (the correlation
    has tried every translation already)."""
    tried = config.link_hypotheses + config.shape_hypotheses
    return dataclasses.replace(
        config.integrate,
        max_hypotheses=max(tried, 1),
        refine_candidates=tried,
        slide_range=0.0,
    )


# Viewpoints per side of a verification, at least this far apart: the beams' evidence is
# about the place, and a few views of it say what many do (the cost grows with each).
_VERIFY_VIEWS = 6
_VERIFY_SPACING = 2.0  # m


def _verify_views(views: MapViews, view_range: float) -> list[Viewpoint]:
    """A map's views thinned for a verification (:data:`_VERIFY_VIEWS`), each seeing
    ``view_range`` m at most."""
    rows = thin(views.poses, _VERIFY_SPACING)
    if len(rows) > _VERIFY_VIEWS:
        rows = rows[np.linspace(0, len(rows) - 1, _VERIFY_VIEWS).astype(int)]
    kept = MapViews(views.poses[rows], views.ranges[rows], views.angle_min, views.angle_increment)
    return viewpoints(kept, view_range)


def placement_hypotheses(
    place: Place, target: Target, config: MergeConfig, drawing: Drawing | None = None
) -> tuple[FloatArray, FloatArray]:
    """Where the place may lie on the target map, before verification: the correlation's
    ``link_hypotheses`` best distinct placements (none when even the best scores below
    ``link_min_overlap``), and the shape matching's (:mod:`shape_placements`; only with
    ``shape_hypotheses``). Rows (theta, x, y) of the place's centre in the target's frame."""
    unit = target.unit
    nothing = np.zeros((0, 3))
    if len(unit.segments) == 0 or len(place.segments) == 0:
        return nothing, nothing
    drawn = (
        drawing
        if drawing is not None
        else place_drawing(place, config.free_drawing(), config.place_radius)
    )
    correlation = config.correlation()
    rotations = rotation_candidates(unit.segment_map, place.segment_map, correlation.rotations)
    peaks, scores = correlation_peaks(
        target.drawing, drawn, rotations, correlation, target.correlation
    )
    if len(peaks) == 0 or scores[0] < config.link_min_overlap * place.length:
        return nothing, nothing
    correlated = peaks[_distinct(peaks, config.link_hypotheses)]
    if not config.shape_hypotheses:
        return correlated, nothing
    shaped = shape_placements(
        place.segments,
        target.view_poses,
        target.shapes,
        config.shape_hypotheses,
        config.place_radius,  # as far as the place's walls reach: the views see the same
        ShapeConfig(),
    )
    return correlated, shaped


def match_place(
    place: Place, target: Target, config: MergeConfig, drawing: Drawing | None = None
) -> list[LinkCandidate]:
    """The place searched for on the target map: its best placement and best rival as link
    candidates (none when it lies nowhere there)."""
    unit = target.unit
    correlated, shaped = placement_hypotheses(place, target, config, drawing)
    if len(correlated) == 0:
        return []
    hypotheses = np.vstack((correlated, shaped))
    # The target's walls and viewpoints around every placement tried, in the target's frame.
    crop = SegmentMap.of(
        longest(
            segments_near(unit.segments, hypotheses[:, 1:], config.place_radius + _CROP_MARGIN),
            _VERIFY_SEGMENTS,
        )
    )
    own = place.segment_map.longest(_VERIFY_SEGMENTS)
    if len(crop) == 0:
        return []
    poses = target.view_poses
    near = _close_to_any(poses[:, :2], hypotheses[:, 1:], config.place_radius)
    views = MapViews.of(crop.segments, poses[near], config.view_fan())
    settings = place_config(config)
    reach = config.view_range
    sides = (_verify_views(views, reach) or None, _verify_views(place.views, reach) or None)
    best = integrate(
        crop,
        own,
        settings,
        heuristics=(),
        ordered=(False, False),
        extra_hypotheses=hypotheses,
        views=sides,
    )
    if best.value <= 0.0 or best.evidence is None:
        return []
    noise = LinkNoise(
        pair_tolerance(config.integrate), config.graph.link_sigma, config.graph.link_angle_sigma
    )
    found = [_candidate(place, own, unit, crop, best, 0, noise)]
    rival = _best_rival(crop, own, hypotheses, best.T_1_2, best.evidence, sides, settings)
    if rival is not None:
        found.append(_candidate(place, own, unit, crop, rival, 1, noise))
    return found


def _best_rival(
    crop: SegmentMap,
    own: SegmentMap,
    hypotheses: FloatArray,
    best_T: FloatArray,
    best: MatchEvidence,
    sides: tuple[list[Viewpoint] | None, list[Viewpoint] | None],
    settings: IntegrateConfig,
) -> MatchResult | None:
    """The best rival of the best placement ``best_T`` (its evidence ``best``) of the
    place's segments ``own`` on the target's ``crop``, with its confidence against the best
    placement; None when every hypothesis lies at the best placement or the rival's
    verification finds nothing else."""
    # The best rival: the same verification without the hypotheses at the best placement;
    # its confidence is then judged with the best placement as *its* rival (a tie leaves both
    # unsure, a clear winner leaves the rival none).
    others = np.array([_differs(row, best_T) for row in hypotheses], dtype=bool)
    if not others.any():
        return None
    rival = integrate(
        crop,
        own,
        settings,
        heuristics=(),
        ordered=(False, False),
        extra_hypotheses=hypotheses[others],
        views=sides,
    )
    if not (rival.value > 0.0 and rival.evidence is not None and _differs(rival.T_1_2, best_T)):
        return None
    # Its evidence with the best placement as its rival: the beams on each were judged by
    # the two verifications already (the same maps, views and settings: match_evidence's
    # judgements of rival.T_1_2 and of best_T, bit for bit; judging them again was a fifth
    # of a place match, issue 50).
    found = rival.evidence
    evidence = MatchEvidence(
        found.second_in_first,
        found.first_in_second,
        found.score,
        best.score,
        found.support,
        found.fraction,
        best.second_in_first + best.first_in_second,
    )
    return dataclasses.replace(rival, confidence=confidence(evidence.features()))


def _fit(evidence: MatchEvidence) -> float:
    """The confidence of a placement as if it had no rival: how well it fits at all."""
    alone = dataclasses.replace(evidence, rival_score=0.0, rival=BeamAgreement.nothing())
    return confidence(alone.features())


def _candidate(
    place: Place,
    own: SegmentMap,
    unit: MapUnit,
    crop: SegmentMap,
    match: MatchResult,
    rank: int,
    noise: LinkNoise,
) -> LinkCandidate:
    """The link of a verified placement of the place in the target map: to the target keyframe
    nearest the placed centre, with the information of the match (``noise``: what it is
    read with)."""
    T_row = match.T_1_2
    T_target_centre = se2.matrix_from_pose(float(T_row[1]), float(T_row[2]), float(T_row[0]))
    spot = T_target_centre[:2, 2]
    row = int(np.argmin(np.hypot(*(unit.poses[:, :2] - spot).T)))
    T_target_keyframe = se2.matrix_from_pose(*unit.poses[row])
    T_keyframe_centre = se2.invert(T_target_keyframe) @ T_target_centre
    x, y, theta = se2.pose_from_matrix(T_keyframe_centre)
    information = match_information(
        se2.transform_segments(se2.invert(T_target_keyframe), crop.segments),
        own,
        np.array([theta, x, y]),
        noise.tolerance,
        noise.sigma,
        (noise.sigma, noise.angle_sigma),
        (10.0, 1.0),
    )
    return LinkCandidate(
        source=place.unit,
        centre=place.centre,
        target=unit.key,
        keyframe=int(unit.index[row]),
        T_keyframe_centre=(x, y, theta),
        T_target_centre=se2.pose_from_matrix(T_target_centre),
        confidence=float(match.confidence),
        fit=_fit(match.evidence) if match.evidence is not None else 0.0,
        value=float(match.value),
        rank=rank,
        information=information,
    )


class LinkNoise(NamedTuple):
    """What a link's information is read with: INTEGRATE's pair tolerances and the joint
    graph's link sigmas (m, rad: ``merge.graph.link_sigma``, ``link_angle_sigma``)."""

    tolerance: PairTolerance
    sigma: float
    angle_sigma: float


def _differs(row: FloatArray, other: FloatArray) -> bool:
    """Are two (theta, tx, ty) placements different answers?"""
    turn = abs(float(se2.wrap_angle(row[0] - other[0])))
    return bool(float(np.hypot(row[1] - other[1], row[2] - other[2])) > _DISTINCT_SHIFT) or (
        turn > _DISTINCT_TURN
    )


def _distinct(peaks: FloatArray, count: int) -> list[int]:
    """Indices of the best ``count`` mutually distinct placements (peaks sorted best first)."""
    kept: list[int] = []
    for k in range(len(peaks)):
        if len(kept) == count:
            break
        if all(_differs(peaks[k], peaks[j]) for j in kept):
            kept.append(k)
    return kept


def _close_to_any(points: FloatArray, centres: FloatArray, radius: float) -> NDArray[np.bool_]:
    """Which points lie within ``radius`` of any centre."""
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    gap = np.hypot(
        points[:, None, 0] - centres[None, :, 0], points[:, None, 1] - centres[None, :, 1]
    )
    return np.asarray((gap <= radius).any(axis=1))


def segments_near(segments: FloatArray, centres: FloatArray, radius: float) -> FloatArray:
    """Segments passing within ``radius`` of any centre."""
    if len(segments) == 0:
        return segments.reshape(0, 4)
    distance = point_segment_distance(
        centres[None, :, 0],
        centres[None, :, 1],
        segments[:, None, 0],
        segments[:, None, 1],
        segments[:, None, 2],
        segments[:, None, 3],
    )
    return np.asarray(segments[(distance <= radius).any(axis=1)])
