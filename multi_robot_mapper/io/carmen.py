"""Reader for CARMEN laser logs (``FLASER`` lines), plain or gzip-compressed.

Only the laser readings and the reference pose stored with them are read; the odometry fields
of each line are skipped on purpose (this project maps without odometry).
"""

from __future__ import annotations

import dataclasses
import gzip
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.scan import LaserScanData

FloatArray = NDArray[np.float64]

# Readings at or beyond this are treated as "no return" (the Radish logs mark no return with
# their sensor's maximum, about 80 m, or 50 m on some sets); it is the scans' range_max.
NO_RETURN_RANGE_M = 50.0
FIELD_OF_VIEW_RAD = math.pi


class CarmenFormatError(ValueError):
    """A line of the log cannot be parsed; the message names the line number."""


@dataclasses.dataclass(frozen=True)
class CarmenScan:
    """One FLASER reading: ranges, beam geometry and the log's reference laser pose."""

    ranges: FloatArray
    angle_min: float
    angle_increment: float
    reference_pose: tuple[float, float, float]  # x, y, theta of the laser in the world frame
    timestamp: float  # ipc_timestamp, seconds

    @property
    def angle_max(self) -> float:
        return self.angle_min + self.angle_increment * (len(self.ranges) - 1)


def beam_geometry(beam_count: int) -> tuple[float, float]:
    """``(angle_min, angle_increment)`` of a CARMEN front laser with ``beam_count`` beams.

    180 beams are -90 deg + i * 1 deg; 181 and 361 beams (and any other count) span the 180 deg
    field of view inclusively: -90 deg + i * 180 deg / (n - 1).
    """
    if beam_count == 180:
        return -math.pi / 2.0, math.radians(1.0)
    if beam_count < 2:
        raise CarmenFormatError(f"a FLASER line needs at least 2 beams, got {beam_count}")
    return -math.pi / 2.0, FIELD_OF_VIEW_RAD / (beam_count - 1)


def parse_flaser(line: str, line_number: int = 0) -> CarmenScan:
    """Parse one ``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ts host logger_ts``."""
    fields = line.split()
    try:
        n = int(fields[1])
        ranges = np.array(fields[2 : 2 + n], dtype=np.float64)
        x, y, theta = (float(v) for v in fields[2 + n : 5 + n])
        timestamp = float(fields[8 + n])
    except (IndexError, ValueError) as exc:
        raise CarmenFormatError(f"line {line_number}: malformed FLASER line ({exc})") from exc
    if ranges.size != n:
        raise CarmenFormatError(
            f"line {line_number}: FLASER announces {n} ranges, has {ranges.size}"
        )
    angle_min, increment = beam_geometry(n)
    return CarmenScan(
        ranges=ranges,
        angle_min=angle_min,
        angle_increment=increment,
        reference_pose=(x, y, theta),
        timestamp=timestamp,
    )


def read_carmen(path: str | Path) -> Iterator[CarmenScan]:
    """Yield every FLASER scan of a CARMEN log (``.gz`` is decompressed on the fly)."""
    path = Path(path)
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", encoding="ascii", errors="replace") as stream:
        for number, line in enumerate(stream, start=1):
            if line.startswith("FLASER "):
                yield parse_flaser(line, number)


def carmen_scan_data(scan: CarmenScan) -> LaserScanData:
    """The LaserScan geometry of a CARMEN reading (no-return readings fall at range_max)."""
    return LaserScanData(
        ranges=scan.ranges,
        angle_min=scan.angle_min,
        angle_max=scan.angle_max,
        angle_increment=scan.angle_increment,
        range_min=0.0,
        range_max=NO_RETURN_RANGE_M,
    )
