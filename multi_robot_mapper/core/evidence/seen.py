"""Free space from real scans: where a robot's laser saw nothing, as points for a
:class:`~.correlation.Drawing` (the evidence model counts another map's walls there against a
placement).

A beam that returned at range r saw nothing for r metres. As the merger's synthetic views
(:class:`~core.merging.free_space.MapViews`), on beams about a degree apart, free space along a
beam reaches only as far as the nearest return of the beams within ``SEEN_SPREAD`` either side
(a gap between two walls, a wall's end seen at a grazing angle, is not seen through), up to
``margin`` before it and at most ``reach``; a beam with no return within that window claims
nothing (glass, an open door beyond the range: nothing is known there).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.scan import LaserScanData

FloatArray = NDArray[np.float64]

# As the merger's views (MergeConfig view_range, free_space_margin, view_beams over a turn).
SEEN_REACH = 8.0  # m
SEEN_MARGIN = 0.5  # m
SEEN_BEAM_STEP = float(np.radians(1.0))  # rad between the beams used
SEEN_SPREAD = 6  # beams either side (MergeConfig view_spread)


def scan_free_points(
    scans: Sequence[LaserScanData],
    poses: FloatArray,
    spacing: float,
    reach: float = SEEN_REACH,
    margin: float = SEEN_MARGIN,
) -> FloatArray:
    """(P, 2) points, in the frame of ``poses`` (the laser poses of ``scans``), where the scans'
    beams crossed free space (module doc); beams about a degree apart."""
    out: list[FloatArray] = []
    steps = np.arange(spacing, reach, spacing)
    for scan, pose in zip(scans, np.asarray(poses, dtype=np.float64).reshape(-1, 3), strict=True):
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        if len(ranges) == 0 or scan.angle_increment == 0.0:
            continue
        every = max(1, round(SEEN_BEAM_STEP / abs(scan.angle_increment)))
        beams = np.arange(0, len(ranges), every)
        r = ranges[beams]
        valid = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
        limits = np.where(valid, r, -np.inf)
        padded = np.pad(limits, SEEN_SPREAD, constant_values=-np.inf)
        window = np.lib.stride_tricks.sliding_window_view(padded, 2 * SEEN_SPREAD + 1)
        free = np.minimum(window.min(axis=1) - margin, reach)
        beam, step = np.nonzero(free[:, None] > steps[None, :])
        if beam.size == 0:
            continue
        bearing = pose[2] + scan.angle_min + scan.angle_increment * beams[beam]
        distance = steps[step]
        out.append(
            np.column_stack(
                (pose[0] + distance * np.cos(bearing), pose[1] + distance * np.sin(bearing))
            )
        )
    return np.vstack(out) if out else np.zeros((0, 2))
