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
    )
    split_tolerance: float = param(
        0.025,
        unit="m",
        doc="kappa: recursive split stops when every point is this close to its segment",
        minimum=0.001,
        maximum=1.0,
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
    )
    dce_threshold: float = param(
        0.005,
        unit="m",
        doc="DCE removes vertices while the least relevance K(u,v,w) (Wolter eq. 1) is below this",
        minimum=0.0001,
        maximum=1.0,
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
    )

    def __post_init__(self) -> None:
        validate(self)
