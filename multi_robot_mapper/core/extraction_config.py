"""Settings of the front end (pipeline stage 1, :mod:`core.extraction`): clusters, polylines and
the scans it refuses. Lengths in metres, angles in radians."""

from __future__ import annotations

import dataclasses
import math

from multi_robot_mapper.core.config import param, validate


@dataclasses.dataclass(frozen=True)
class ExtractionConfig:
    """Scan-to-segment front end. Lengths in metres."""

    cluster_distance: float = param(
        0.20,
        unit="m",
        doc="tau: consecutive points farther apart start a new cluster (Amigoni III-D, Wolter 3.1)",
        minimum=0.01,
        maximum=10.0,
        tune="a sparse laser (1 degree beams on walls 10 m away land 0.17 m apart): raise it so "
        "walls stay whole; lower it to keep near objects apart",
    )
    split_tolerance: float = param(
        0.025,
        unit="m",
        doc="kappa: recursive split stops when every point is this close to its segment",
        minimum=0.001,
        maximum=1.0,
        tune="a noisier laser (range noise above 1-2 cm): raise it, or walls come out as zigzags "
        "of short segments",
    )
    min_cluster_points: int = param(
        2,
        unit="points",
        doc="clusters with fewer points are dropped (a lone return cannot make a segment)",
        minimum=2,
        maximum=1000,
    )
    simplifier: str = param(
        "split",
        unit="",
        doc="polyline simplifier: recursive split (tolerance kappa) or Discrete Curve Evolution",
        choices=("split", "dce"),
        tune="to try Discrete Curve Evolution (Wolter's simplifier) instead of the recursive "
        "split: 'dce'",
    )
    dce_threshold: float = param(
        0.005,
        unit="m",
        doc="DCE removes vertices while the least relevance K(u,v,w) (Wolter eq. 1) is below this",
        minimum=0.0001,
        maximum=1.0,
        tune="with simplifier 'dce' only: raise it for a noisier laser",
    )
    max_beams: int = param(
        100_000,
        unit="beams",
        doc="scans with more beams are refused as corrupt",
        minimum=1,
        maximum=1_000_000,
    )
    min_field_of_view: float = param(
        0.5,
        unit="rad",
        doc="scans whose beams span less (|angle_increment| x (beams - 1)) are refused: no "
        "laser makes them (an increment of 1e-4 rad puts 1081 beams within 6 degrees, every "
        "point nearly on one line), and no match can constrain a pose with them; 0.5 rad lets "
        "depth cameras through (about 1 rad)",
        minimum=0.0,
        maximum=2.0 * math.pi,
        tune="a sensor narrower than 0.5 rad (a depth camera's fake scan is about 1 rad) is "
        "refused: lower it to map with one",
    )

    def __post_init__(self) -> None:
        validate(self)
