"""INTEGRATE's parameters (Amigoni III), one typed config."""

from __future__ import annotations

import dataclasses
import math

from multi_robot_mapper.core.config import param, validate


@dataclasses.dataclass(frozen=True)
class IntegrateConfig:
    """INTEGRATE parameters (Amigoni III). Lengths in metres, angles in radians."""

    point_distance_tolerance: float = param(
        0.05,
        unit="m",
        doc="POINTDISTANCETOLERANCE: scale of the distance penalty 0.95^(d/tol) (Alg. 4 l. 16)",
        minimum=0.001,
        maximum=1.0,
    )
    segment_distance_threshold: float = param(
        5.0,
        unit="",
        doc="SEGMENTDISTANCETHRESHOLD: pairs farther than this many tolerances do not match",
        minimum=0.1,
        maximum=1000.0,
    )
    angle_difference_tolerance: float = param(
        0.05,
        unit="rad",
        doc="ANGLEDIFFERENCETOLERANCE: two landmark angles this close are equal",
        minimum=0.0001,
        maximum=0.5,
    )
    segment_length_refuse: float = param(
        0.8,
        unit="m",
        doc="SEGMENTLENGTHREFUSE: a hypothesis making two longer segments cross is refused",
        minimum=0.0,
        maximum=100.0,
    )
    crossing_margin: float = param(
        0.2,
        unit="m",
        doc="a crossing refuses only if it lies this far inside both long segments",
        minimum=0.0,
        maximum=10.0,
    )
    min_landmark_angle: float = param(
        0.35,
        unit="rad",
        doc="segment pairs closer to parallel than this have no reliable vertex",
        minimum=0.0,
        maximum=1.5,
    )
    segment_length_percentage: float = param(
        20.0,
        unit="%",
        doc="SEGMENTLENGTHPERCENTAGE: consecutive-angle segments must be this long vs the longest",
        minimum=0.0,
        maximum=100.0,
    )
    segment_division_factor: float = param(
        0.5,
        unit="",
        doc="SEGMENTDIVISIONFACTOR: random heuristic draws from segments longer than f^k x longest",
        minimum=0.01,
        maximum=1.0,
    )
    random_rounds: int = param(
        3,
        unit="",
        doc="K of Alg. 3: rounds k = 1..K drawing N_k = 20 * 2^k angles",
        minimum=0,
        maximum=12,
    )
    histogram_slots: int = param(
        18,
        unit="",
        doc="orientation histogram buckets over pi (perpendicular heuristic)",
        minimum=4,
        maximum=3600,
    )
    all_pairs_below: int = param(
        12,
        unit="segments",
        doc="use every segment pair when a set has at most this many",
        minimum=0,
        maximum=1000,
    )
    min_segment_length: float = param(
        0.1, unit="m", doc="shorter segments never form landmarks", minimum=0.0, maximum=100.0
    )
    max_match_angle: float = param(
        0.2,
        unit="rad",
        doc="segments whose directions differ more than this never match (bounds the work)",
        minimum=0.001,
        maximum=1.5,
    )
    max_hypotheses: int = param(
        20000,
        unit="",
        doc="at most this many distinct hypotheses (most voted first) are prescreened",
        minimum=1,
        maximum=1_000_000,
    )
    hypothesis_angle_cell: float = param(
        0.0087,
        unit="rad",
        doc="hypotheses in the same (angle, x, y) cell are one (the most voted cells first)",
        minimum=0.0001,
        maximum=1.0,
    )
    hypothesis_distance_cell: float = param(
        0.02,
        unit="m",
        doc="translation size of the cells that merge hypotheses",
        minimum=0.0001,
        maximum=10.0,
    )
    refine_iterations: int = param(
        6,
        unit="",
        doc="Gauss-Newton iterations of the least-squares refinement of each candidate (0: none)",
        minimum=0,
        maximum=100,
    )
    seed: int = param(
        0,
        unit="",
        doc="seed of the random-pair heuristic (deterministic runs)",
        minimum=0,
        maximum=2_147_483_647,
    )
    min_match_value: float = param(
        1.0,
        unit="m",
        doc="validity: the best transformation must overlap at least this length",
        minimum=0.0,
        maximum=1000000.0,
    )
    min_match_fraction: float = param(
        0.5,
        unit="",
        doc="validity: net value at least this fraction of the shorter set's total length",
        minimum=0.0,
        maximum=1.0,
    )
    free_space_margin: float = param(
        0.15,
        unit="m",
        doc="a point this far in front of what the other scan's beam measured is a contradiction",
        minimum=0.0,
        maximum=10.0,
    )
    confirm_margin: float = param(
        0.1,
        unit="m",
        doc="for the match confidence, a return within this of the range the other scan "
        "measured on its bearing is confirmed by it",
        minimum=0.001,
        maximum=2.0,
    )
    free_space_weight: float = param(
        1.0,
        unit="",
        doc="metres of overlap one metre of segment inside the other scan's free space cancels",
        minimum=0.0,
        maximum=100.0,
    )
    min_cross_support: float = param(
        0.5,
        unit="m",
        doc="validity: matched length across the weakest direction (one wall or a bare corridor "
        "cannot fix the offset along it)",
        minimum=0.0,
        maximum=1000.0,
    )
    refine_candidates: int = param(
        12,
        unit="",
        doc="the best this many distinct hypotheses are refined; the best net score wins",
        minimum=1,
        maximum=1000,
    )

    free_space_spread: int = param(
        1,
        unit="beams",
        doc="a point is seen through only if the beams this many either side passed it too",
        minimum=0,
        maximum=100,
    )
    free_space_min_length: float = param(
        0.3,
        unit="m",
        doc="with one view only, segments shorter than this (people) are not tested",
        minimum=0.0,
        maximum=100.0,
    )
    view_point_length: float = param(
        0.3,
        unit="m",
        doc="with both views, one return stands for at most this much surface",
        minimum=0.001,
        maximum=10.0,
    )
    confirmed_weight: float = param(
        3.0,
        unit="",
        doc="metres of score one metre of a scan that the other scan's beams end on adds when "
        "candidates are ranked (a wrong transform puts one scan where the other never looked)",
        minimum=0.0,
        maximum=100.0,
    )
    cross_support_weight: float = param(
        5.0,
        unit="",
        doc="metres of score one metre of cross support adds when candidates are ranked",
        minimum=0.0,
        maximum=100.0,
    )
    slide_candidates: int = param(
        3,
        unit="",
        doc="this many best candidates are slid along the direction their walls leave free",
        minimum=0,
        maximum=100,
    )
    slide_below_support: float = param(
        1.0,
        unit="m",
        doc="only candidates with less cross support than this are slid",
        minimum=0.0,
        maximum=1000.0,
    )
    slide_range: float = param(
        1.5, unit="m", doc="slides go this far either way", minimum=0.0, maximum=10.0
    )
    slide_step: float = param(
        0.1, unit="m", doc="slides are tried every this far", minimum=0.005, maximum=10.0
    )
    candidate_pool: int = param(
        100,
        unit="",
        doc="this many prescreened hypotheses are evaluated in full (Alg. 4) and searched for "
        "distinct candidates",
        minimum=1,
        maximum=100_000,
    )
    prescreen_segments: int = param(
        16,
        unit="segments",
        doc="with more than candidate_pool hypotheses, all are first valued on this many "
        "longest segments of each set; the candidate_pool best are evaluated in full",
        minimum=1,
        maximum=10_000,
    )
    prescreen_match_angle: float = param(
        0.1,
        unit="rad",
        doc="in the prescreen, segments whose directions differ more than this never match",
        minimum=0.001,
        maximum=1.5,
    )
    candidate_separation: float = param(
        0.4,
        unit="m",
        doc="candidates closer than this (and candidate_angle_separation) are one answer",
        minimum=0.0,
        maximum=100.0,
    )
    candidate_angle_separation: float = param(
        0.05,
        unit="rad",
        doc="candidates turned less than this (and candidate_separation) are one answer",
        minimum=0.0,
        maximum=math.pi,
    )

    def __post_init__(self) -> None:
        validate(self)

    @property
    def match_distance(self) -> float:
        """Pairs with d(s1, s2) above this contribute nothing (Alg. 4 l. 9)."""
        return self.point_distance_tolerance * self.segment_distance_threshold
