"""Wolter's shape-based matching's parameters (:mod:`core.matching.shape`), one typed config.

The paper (Wolter, Latecki, Lakämper, Sun, *Shape-Based Robot Mapping*) works in centimetres:
its grouping distance is 20 cm and its DCE stop thresholds 1.0 and 5.0 (Fig. 1, on a 1 m
grid); Cox's alignment samples every 10 cm. Here lengths are metres and angles radians. The
similarity of Eq. 2 is in rad² (the variance of two turning functions' difference, weighted by
1 + the squared difference of lengths in metres), so the skip penalty of Eq. 4 is in rad² per
metre of polyline."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import param, validate


@dataclasses.dataclass(frozen=True)
class ShapeConfig:
    """Shape-based matching (Wolter Sec. 3-5). Lengths in metres, angles in radians."""

    group_distance: float = param(
        0.20,
        unit="m",
        doc="consecutive returns farther apart than this start a new polyline (Wolter 3.1)",
        minimum=0.001,
        maximum=10.0,
    )
    dce_threshold: float = param(
        0.05,
        unit="m",
        doc="Discrete Curve Evolution removes vertices while the least relevance "
        "d(u,v) + d(v,w) - d(u,w) is below this (Wolter Eq. 1; the paper's 5.0 in cm): "
        "sensor noise goes, corners stay",
        minimum=0.0,
        maximum=10.0,
    )
    max_group: int = param(
        3,
        unit="polylines",
        doc="a polyline may correspond to up to this many consecutive polylines of the other "
        "scan (1-to-many and many-to-1, Wolter 4.2: the same wall grouped differently)",
        minimum=1,
        maximum=10,
    )
    skip_penalty: float = param(
        0.1,
        unit="rad²/m",
        doc="cost of leaving a polyline unmatched, per metre of its length (Wolter Eq. 4, P): "
        "two polylines are put in correspondence when their dissimilarity is below the "
        "penalty of skipping both",
        minimum=0.0,
        maximum=100.0,
    )
    alignment_distance: float = param(
        0.5,
        unit="m",
        doc="second pass: a correspondence whose induced alignment moves its polyline this "
        "far from the estimated alignment costs as much as skipping it (Wolter Eq. 4, D)",
        minimum=0.001,
        maximum=100.0,
    )
    alignment_angle: float = param(
        0.35,
        unit="rad",
        doc="second pass: the same, for the induced alignment's turn",
        minimum=0.001,
        maximum=3.2,
    )
    reliable_candidates: int = param(
        3,
        unit="correspondences",
        doc="the most reliable pairs of polylines on shape alone (Wolter Eq. 5) each tried as "
        "the estimate of the matching with alignment term; the one whose matching costs "
        "least is kept (1: the paper's single most reliable one)",
        minimum=1,
        maximum=50,
    )
    tangent_samples: int = param(
        32,
        unit="samples",
        doc="points per polyline at which turning functions are compared (Eq. 2-3 integrals "
        "by the midpoint rule)",
        minimum=4,
        maximum=1024,
    )
    align_spacing: float = param(
        0.10,
        unit="m",
        doc="the perceived polylines are sampled this far apart for the final point-to-"
        "polyline alignment (Wolter 5.1, after Cox)",
        minimum=0.005,
        maximum=10.0,
    )
    align_iterations: int = param(
        30,
        unit="iterations",
        doc="at most this many alignment steps (each: nearest points, then the closed-form "
        "rigid fit)",
        minimum=0,
        maximum=1000,
    )

    def __post_init__(self) -> None:
        validate(self)
