"""Local mapping's parameters, one typed config."""

from __future__ import annotations

import dataclasses
import math

from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.matching import IntegrateConfig


@dataclasses.dataclass(frozen=True)
class LocalMapperConfig:
    """Local mapping. Lengths in metres, angles in radians."""

    keyframe_distance: float = param(
        0.5,
        unit="m",
        doc="a scan this far from the last keyframe becomes a keyframe",
        minimum=0.0,
        maximum=100.0,
    )
    keyframe_angle: float = param(
        0.35,
        unit="rad",
        doc="a scan turned this much from the last keyframe becomes a keyframe",
        minimum=0.0,
        maximum=math.pi,
    )
    submap_radius: float = param(
        12.0,
        unit="m",
        doc="partial-map segments within this distance of the last pose are matched",
        minimum=0.5,
        maximum=1000.0,
    )
    fusion_tolerance: float = param(
        0.02,
        unit="m",
        doc="FUSIONTOLERANCE: a fused polyline stays this close to every segment it replaces",
        minimum=0.001,
        maximum=1.0,
    )
    min_match_fraction: float = param(
        0.15,
        unit="",
        doc="a scan is integrated when its match with the last scan overlaps at least "
        "integrate.min_match_value and its net value (overlap minus length seen through the "
        "other scan's free space) is at least this fraction of the shorter scan's length. Far "
        "below integrate.min_match_fraction (which judges unrelated maps): on the sparse logs "
        "right scan matches go down to 0.1, and an unrelated simulated room reaches 0.10",
        minimum=-1.0,
        maximum=1.0,
    )
    min_cross_support: float = param(
        0.0,
        unit="m",
        doc="matched length across the weakest direction a scan match needs. Most wrong scan "
        "matches on the logs have < 0.1 m, but so do many corridor scans, and every scan set "
        "aside makes the next match harder (bench/scan_gate.py); with a value > 0 a scan set "
        "aside for this alone is bridged when the next scan matches it validly",
        minimum=0.0,
        maximum=100.0,
    )
    map_refine_limit: float = param(
        0.1,
        unit="m or rad",
        doc="refinement on the partial map may move a scan at most this far (metres, and "
        "radians) from where its match with the last scan put it",
        minimum=0.0,
        maximum=10.0,
    )
    tracking_fraction: float = param(
        0.7,
        unit="",
        doc="a refined prediction explaining this fraction of the scan is accepted without a "
        "global search",
        minimum=0.0,
        maximum=1.0,
    )
    submap_reach: float = param(
        1.5,
        unit="m",
        doc="a scan set aside by its match with the last scan is matched against the partial "
        "map around the last pose, and placed there only within this distance of the last "
        "scan: wrong map matches on the logs jump >= 2 m (right ones <= 1.3 m; the sparse "
        "logs step <= 1.8 m, a fast laser a few cm); 0 turns map matching off",
        minimum=0.0,
        maximum=100.0,
    )
    submap_turn: float = param(
        1.2,
        unit="rad",
        doc="a scan placed by its match against the partial map (see submap_reach) is turned "
        "at most this much from the last scan: wrong map matches on the logs turn >= 1.5 rad, "
        "mostly half round in a symmetric corridor; right ones <= 0.9 rad",
        minimum=0.0,
        maximum=math.pi,
    )
    integrate: IntegrateConfig = dataclasses.field(default_factory=IntegrateConfig)

    def __post_init__(self) -> None:
        validate(self)
