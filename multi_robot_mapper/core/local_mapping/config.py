"""Local mapping's parameters, one typed config."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.matching import IntegrateConfig
from multi_robot_mapper.core.matching.shape_config import ShapeConfig


@dataclasses.dataclass(frozen=True)
class LocalMapperConfig:
    """Local mapping (front end, keyframe graph, loop closing). Lengths in metres, angles in
    radians. The three confidence thresholds are probabilities that a match is right (within
    0.30 m / 5 deg), chosen from the precision/recall curve of the fitted confidence (README,
    "Match confidence")."""

    keyframe_distance: float = param(
        0.5,
        unit="m",
        doc="a scan this far from the last keyframe becomes a keyframe",
        minimum=0.0,
        maximum=100.0,
        tune="smaller for a denser keyframe graph (small rooms; more CPU), larger for a sparser "
        "one (open halls, fast robots)",
    )
    keyframe_angle: float = param(
        0.35,
        unit="rad",
        doc="a scan turned this much from the last keyframe becomes a keyframe",
        minimum=0.0,
        maximum=3.2,
        tune="with keyframe_distance: smaller for a robot that turns on the spot",
    )
    revisit_keyframes: bool = param(
        True,
        unit="",
        doc="a scan within keyframe_distance and keyframe_angle of ANY earlier keyframe of its "
        "piece adds no keyframe and is placed on that one instead (the map already holds that "
        "view): a robot driving over known ground keeps its map and its partial_map message "
        "the same size, so both grow with the area covered, not with time; false: only the "
        "last keyframe counts",
    )
    integrate_confidence: float = param(
        0.8,
        unit="",
        doc="a scan is integrated when its match is right with at least this probability; "
        "otherwise the robot is lost and maps on in a new piece of map",
        minimum=0.0,
        maximum=1.0,
        tune="lower places more scans but risks bends; higher starts more pieces",
    )
    loop_confidence: float = param(
        0.9,
        unit="",
        doc="a loop closure (or a join of two pieces of map) is tried when its windows' match "
        "is right with at least this probability (then the consistency checks, then the "
        "evidence model: join_probability)",
        minimum=0.0,
        maximum=1.0,
        tune="the same trade for loop closures and joins of pieces",
    )
    join_probability: float = param(
        0.99,
        unit="",
        doc="a loop closure or a join of two pieces of map is made only when the evidence "
        "model's probability that it is right reaches this: the walls it moves, each counted "
        "once, against their best rival placement where the robot can have been "
        "(core/evidence: models fitted on the back end's own decisions, closure_model.json "
        "and piece_join_model.json; the same threshold as the merger's join_probability)",
        minimum=0.5,
        maximum=0.999999,
        tune="lower closes more loops and joins more pieces, at more risk of a wrong one",
    )
    recent_keyframes: int = param(
        3,
        unit="keyframes",
        doc="a scan the last scan cannot place is matched against this many keyframes before "
        "it (nearest first) before the robot counts as lost",
        minimum=0,
        maximum=50,
    )
    lost_confirm_scans: int = param(
        2,
        unit="scans",
        doc="a scan no confident match places is held, not mapped: when the next scan is "
        "placed from the map it was an outlier (a scan of another place, junk ranges), set "
        "aside; the robot counts as lost (a new piece starts from the held scan) only when "
        "this many scans in a row are not placed and each is placed from the one before it. "
        "1: the first such scan starts a new piece",
        minimum=1,
        maximum=100,
    )
    plausible_speed: float = param(
        3.0,
        unit="m/s",
        doc="the front end never places a scan in the robot's own piece farther from the "
        "last placed scan than the robot drives at this speed (or at its own 95th percentile "
        "speed, if faster) in the time between their stamps, plus 0.3 m: a scan of another "
        "place that matches the last scan metres away (a corridor seen from elsewhere in "
        "it) is not where the robot is. Set it above the robot's top speed",
        minimum=0.01,
        maximum=1000.0,
        tune="a robot faster than 3 m/s",
    )
    local_edges: int = param(
        3,
        unit="keyframes",
        doc="a new keyframe is also matched to this many earlier keyframes of its neighbourhood "
        "(its own window excepted): more edges, a stiffer graph, less drift",
        minimum=0,
        maximum=50,
    )
    loop_window: int = param(
        10,
        unit="keyframes",
        doc="keyframes fewer than this many keyframes apart are neighbours, matched by the "
        "front end; only older ones are loop-closure candidates",
        minimum=1,
        maximum=10000,
    )
    loop_radius: float = param(
        2.0,
        unit="m",
        doc="loop-closure candidates lie within this of the new keyframe's estimate, plus "
        "loop_radius_growth per metre driven since the last closure",
        minimum=0.0,
        maximum=1000.0,
        tune="larger for a robot that drifts more (long loops through bare corridors): closures "
        "found further off, at more CPU per keyframe",
    )
    loop_radius_growth: float = param(
        0.1,
        unit="m/m",
        doc="how fast the loop-closure search region grows with the path since the last "
        "closure (the drift the front end may have accumulated)",
        minimum=0.0,
        maximum=10.0,
    )
    loop_candidates: int = param(
        3,
        unit="keyframes",
        doc="at most this many loop-closure candidates (nearest first) are matched per new "
        "keyframe; also the keyframes of every other piece matched for a join",
        minimum=0,
        maximum=100,
    )
    wall_sigma: float = param(
        0.05,
        unit="m",
        doc="each metre of matched wall counts as one measurement of its line with this "
        "standard deviation: the information of a match's edge",
        minimum=1e-4,
        maximum=10.0,
    )
    edge_sigma_floor: float = param(
        0.02,
        unit="m",
        doc="no edge is trusted to better than this (and edge_angle_floor): errors of "
        "successive scan matches are not independent",
        minimum=1e-4,
        maximum=10.0,
    )
    edge_angle_floor: float = param(
        0.005,
        unit="rad",
        doc="see edge_sigma_floor, for the rotation",
        minimum=1e-5,
        maximum=1.0,
    )
    fusion_tolerance: float = param(
        0.02,
        unit="m",
        doc="FUSIONTOLERANCE: a fused polyline stays this close to every segment it replaces",
        minimum=1e-4,
        maximum=1.0,
    )
    fusion_radius: float = param(
        12.0,
        unit="m",
        doc="a new keyframe is fused with the map segments within this of its pose (and of "
        "its own segments)",
        minimum=0.1,
        maximum=1000.0,
    )
    velocity_window: float = param(
        0.0,
        unit="s",
        doc="the constant-velocity prediction is the robot's motion over its placed scans of "
        "this many seconds (at least the last one; 0: the last placed motion alone). Not "
        "averaged: over 0.5 s on the dense aces bag, 6 pieces instead of 9 but 5 tracking "
        "breaks instead of 1 (docs/decisions.md, tracking in corridors)",
        minimum=0.0,
        maximum=10.0,
    )
    local_map_keyframes: int = param(
        1,
        unit="keyframes",
        doc="a scan is tracked against the last keyframe fused with the keyframes before it "
        "in its piece, this many in all (1: the last keyframe alone). 1: with 3, the dense "
        "aces bag kept 6 393 scans posed instead of 3 862 with no tracking break, the dense "
        "intel bag 10 156 instead of 13 556 (docs/decisions.md, tracking in corridors)",
        minimum=1,
        maximum=10,
    )
    motion_prior: bool = param(
        False,
        unit="",
        doc="tracking weighs the constant-velocity prediction along the direction a match "
        "cannot observe (the weakest of its point-to-line Hessian), as a motion prior worth "
        "the robot's own measured prediction error (core/matching/prior.py). Off: on the "
        "dense aces and intel bags it let the velocity's error carry scans along corridors "
        "(10 and 14 tracking breaks instead of 1; docs/decisions.md, tracking in corridors)",
    )
    integrate: IntegrateConfig = dataclasses.field(default_factory=IntegrateConfig)
    # Wolter's shape matching: a second source of hypotheses for a search that is not
    # confident (README, "Local mapping").
    shape: ShapeConfig = dataclasses.field(default_factory=ShapeConfig)

    def __post_init__(self) -> None:
        validate(self)
