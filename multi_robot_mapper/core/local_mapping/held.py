"""Scans the front end could not place from the map, held until the next scans say what they
were.

A scan that no confident match places from the map (:mod:`.mapper`, step 3) is either an
outlier, a scan that contradicts the robot's own stream (junk ranges, another building, a place
of the building where the robot is not), or the first sign that the robot is lost. One scan
cannot tell which; the next ones can:

- when a later scan is placed from the map, the held scans were outliers: they are set aside
  (:data:`OUTLIER`), and the map and the mapper's state never saw them;
- when ``lost_confirm_scans`` held scans in a row follow each other (:func:`follow_match`: a
  confident match, where the robot can have driven in the time between them), or
  ``lost_confirm_scans + 2`` are held, the robot is lost: the held scans are mapped in order
  exactly as they were before scans were held (the first starts a new piece).

Two outliers in a row rarely follow each other: junk matches junk at random, metres apart,
where no robot drives in the time between two scans.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.local_mapping.attempts import in_context, reach_in
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.joins import LostFrom
from multi_robot_mapper.core.matching import MatchResult, integrate
from multi_robot_mapper.core.matching.integrate import pose_of_match
from multi_robot_mapper.core.scan import LaserScanData

FloatArray = NDArray[np.float64]

# Why a held scan was set aside (LocalMapper.set_aside_reasons).
OUTLIER = "outlier: placed neither from the map nor by the next scan"


@dataclasses.dataclass(frozen=True)
class HeldScan:
    """A scan held: not placed from the map, or following the held scan before it."""

    stamp: float
    segments: FloatArray
    view: LaserScanData
    # not placed from the map: the guess of where it is, should it start a new piece
    lost_from: LostFrom | None = None
    follow: MatchResult | None = None  # following: its placement from the held scan before


def follow_match(
    config: LocalMapperConfig, previous: HeldScan, scan: HeldScan, top_speed: float | None
) -> MatchResult | None:
    """The placement of ``scan`` from the held scan ``previous`` when a search finds it as
    confidently as an integration needs, where the robot can have driven in the time between
    them (at ``plausible_speed``, or ``top_speed`` when faster: its 95th percentile, m/s,
    None when not known yet); else None."""
    result = integrate(
        previous.segments, scan.segments, config.integrate, views=(previous.view, scan.view)
    )
    if in_context(result.confidence, "search") < config.integrate_confidence:
        return None
    x, y, _ = pose_of_match(result.T_1_2)
    elapsed = max(scan.stamp - previous.stamp, 0.0)
    speed = max(top_speed or 0.0, config.plausible_speed)
    if np.hypot(x, y) > reach_in(speed, elapsed):
        return None
    return result
