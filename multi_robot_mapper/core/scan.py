"""Pipeline stage 0: a laser scan's beams to valid Cartesian points in the laser frame.

Input is the content of a ``sensor_msgs/LaserScan`` as plain values, so this module never needs
ROS. Beam i points at ``angle_min + i * angle_increment`` (REP-117, laser_geometry); a reading is
valid when finite and ``range_min <= r < range_max``. Points are returned counter-clockwise
(ascending angle) whatever the sign of ``angle_increment``, so later stages see one order.

Problems that make a scan unusable raise :class:`ScanError`; problems that can be handled are
reported as :class:`ScanNotice` so a node can warn (throttled) and go on.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# One beam of slack on the field of view: drivers disagree on whether angle_max is the last
# beam's angle or one increment beyond it.
_FULL_TURN = 2.0 * np.pi


@dataclasses.dataclass(frozen=True)
class ScanNotice:
    """A handled anomaly. ``kind`` is a stable key for throttling; ``message`` names the problem."""

    kind: str
    message: str


class ScanError(ValueError):
    """The scan cannot be used at all. ``kind`` is a stable key for throttling warnings."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind
        self.message = message


@dataclasses.dataclass(frozen=True)
class LaserScanData:
    """The fields of a ``sensor_msgs/LaserScan`` that geometry needs, as plain values."""

    ranges: FloatArray
    angle_min: float
    angle_max: float
    angle_increment: float
    range_min: float
    range_max: float
    intensities: FloatArray | None = None


@dataclasses.dataclass(frozen=True)
class ScanPoints:
    """Valid returns of one scan, counter-clockwise, in the laser frame."""

    points: FloatArray  # (M, 2) metres
    beam_index: IntArray  # (M,) index of each point's beam in the original ``ranges``
    beam_count: int
    notices: tuple[ScanNotice, ...]

    @property
    def invalid_count(self) -> int:
        """Beams without a usable return (NaN, inf, out of [range_min, range_max))."""
        return self.beam_count - len(self.points)


def scan_points(scan: LaserScanData, max_beams: int = 100_000) -> ScanPoints:
    """Convert LaserScan fields to valid points, checking every field a driver can get wrong."""
    angle_min, angle_max, angle_increment = scan.angle_min, scan.angle_max, scan.angle_increment
    range_min, range_max, intensities = scan.range_min, scan.range_max, scan.intensities
    r = np.asarray(scan.ranges, dtype=np.float64).ravel()
    n = r.size
    notices: list[ScanNotice] = []
    if n == 0:
        raise ScanError("no_beams", "scan has no beams (ranges is empty)")
    if n > max_beams:
        raise ScanError(
            "too_many_beams",
            f"scan has {n} beams, more than max_beams={max_beams}; refusing it as corrupt",
        )
    for name, value in (
        ("angle_min", angle_min),
        ("angle_max", angle_max),
        ("angle_increment", angle_increment),
        ("range_min", range_min),
        ("range_max", range_max),
    ):
        if not np.isfinite(value):
            raise ScanError(
                "non_finite_field", f"scan field {name} is {value}, not a finite number"
            )
    if range_max <= range_min:
        raise ScanError(
            "range_limits",
            f"range_max ({range_max:g} m) <= range_min ({range_min:g} m): no reading can be valid",
        )
    if n > 1 and angle_increment == 0.0:
        raise ScanError("zero_increment", f"angle_increment is 0 for a scan of {n} beams")
    span = angle_max - angle_min
    if n > 1 and span != 0.0 and np.sign(span) != np.sign(angle_increment):
        raise ScanError(
            "angle_order",
            f"angle_max ({angle_max:.4f} rad) - angle_min ({angle_min:.4f} rad) = {span:.4f} rad "
            f"has the opposite sign of angle_increment ({angle_increment:.6f} rad)",
        )
    sweep = abs(angle_increment) * (n - 1)
    if sweep > _FULL_TURN + abs(angle_increment):
        raise ScanError(
            "beam_count",
            f"ranges has {n} beams: at angle_increment {angle_increment:.6f} rad they sweep "
            f"{np.degrees(sweep):.0f} deg, more than a full turn "
            f"(angle_min..angle_max describe {abs(span) / abs(angle_increment) + 1:.0f} beams)",
        )
    if n > 1:
        expected = abs(span) / abs(angle_increment) + 1.0
        if abs(expected - n) > 1.5:
            notices.append(
                ScanNotice(
                    "beam_count",
                    f"ranges has {n} beams but angle_min/angle_max/angle_increment describe "
                    f"{expected:.0f}; beam angles taken as angle_min + i * angle_increment",
                )
            )
    if intensities is not None:
        n_int = np.asarray(intensities).size
        if n_int not in (0, n):
            notices.append(
                ScanNotice(
                    "intensities_length",
                    f"intensities has {n_int} entries but ranges has {n}; intensities ignored",
                )
            )
    n_nan = int(np.count_nonzero(np.isnan(r)))
    n_inf = int(np.count_nonzero(np.isinf(r)))
    if n_nan or n_inf:
        notices.append(
            ScanNotice(
                "non_finite_ranges",
                f"{n_nan} NaN and {n_inf} inf of {n} ranges: treated as no return",
            )
        )

    angles = angle_min + angle_increment * np.arange(n, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(r) & (r >= max(range_min, 0.0)) & (r < range_max)
    index = np.flatnonzero(valid)
    if angle_increment < 0.0:
        index = index[::-1]
        notices.append(
            ScanNotice(
                "negative_increment",
                "angle_increment is negative (clockwise scan); points re-ordered counter-clockwise",
            )
        )
    if index.size == 0:
        notices.append(
            ScanNotice(
                "no_valid_ranges",
                f"none of the {n} ranges is a finite reading in "
                f"[range_min={range_min:g}, range_max={range_max:g}) m",
            )
        )
    rv = r[index]
    av = angles[index]
    points = np.column_stack((rv * np.cos(av), rv * np.sin(av)))
    return ScanPoints(
        points=points, beam_index=index.astype(np.int64), beam_count=n, notices=tuple(notices)
    )
