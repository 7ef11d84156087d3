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
import functools
import math

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
    """The scan cannot be used at all. ``kind`` is a stable key for counters and throttled
    warnings, ``field`` the LaserScan field at fault."""

    def __init__(self, kind: str, message: str, field: str = "") -> None:
        super().__init__(message)
        self.kind = kind
        self.message = message
        self.field = field

    def __reduce__(self) -> tuple[type[ScanError], tuple[str, str, str]]:
        # Raised in a worker process, it crosses back pickled (bench pools, the back end's
        # process): the default reduction would call __init__ with the message alone.
        return (ScanError, (self.kind, self.message, self.field))


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
    # Beams without a usable return, by kind: "nan", "+inf" (no return, REP-117), "-inf" (too
    # close), "below_range_min", "beyond_range_max" (at or beyond it). Empty when all are valid.
    dropped: tuple[tuple[str, int], ...] = ()

    @property
    def invalid_count(self) -> int:
        """Beams without a usable return (NaN, inf, out of [range_min, range_max))."""
        return self.beam_count - len(self.points)


def scan_points(scan: LaserScanData, max_beams: int = 100_000) -> ScanPoints:
    """Convert LaserScan fields to valid points, checking every field a driver can get wrong."""
    angle_min, angle_increment = scan.angle_min, scan.angle_increment
    range_min, range_max = scan.range_min, scan.range_max
    r = np.asarray(scan.ranges, dtype=np.float64).ravel()
    n = r.size
    _check_beam_count(n, max_beams)
    _check_scalar_fields(scan)
    _check_beam_angles(scan, n)
    notices = _intensities_notices(scan.intensities, n)

    # The range limits are finite (checked above), so NaN and +-inf fail one of the two
    # comparisons: no separate finiteness test is needed.
    with np.errstate(invalid="ignore"):
        valid = (r >= range_min) & (r < range_max)
    index = valid.nonzero()[0]
    dropped: tuple[tuple[str, int], ...] = ()
    if index.size < n:
        dropped = _dropped_by_kind(r, range_min, range_max)
        notices += _non_finite_notices(dropped, n)
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
    cos, sin = _beam_directions(float(angle_min), float(angle_increment), n)
    if index.size == n and angle_increment > 0.0:
        rv = r  # every beam valid, already counter-clockwise: no gathers
    else:
        rv, cos, sin = r[index], cos[index], sin[index]
    points = np.empty((index.size, 2))
    np.multiply(rv, cos, out=points[:, 0])
    np.multiply(rv, sin, out=points[:, 1])
    return ScanPoints(
        points=points,
        beam_index=index.astype(np.int64, copy=False),
        beam_count=n,
        notices=tuple(notices),
        dropped=dropped,
    )


def _check_beam_count(n: int, max_beams: int) -> None:
    """ScanError unless the scan has between one and ``max_beams`` beams."""
    if n == 0:
        raise ScanError("no_beams", "scan has no beams (ranges is empty)", "ranges")
    if n > max_beams:
        raise ScanError(
            "too_many_beams",
            f"scan has {n} beams, more than max_beams={max_beams}; refusing it as corrupt",
            "ranges",
        )


def _check_scalar_fields(scan: LaserScanData) -> None:
    """ScanError unless every angle and range field is finite and the range limits leave room
    for a valid reading."""
    range_min, range_max = scan.range_min, scan.range_max
    # The scalar checks use math, not numpy: numpy costs about a microsecond per scalar call.
    for name, value in (
        ("angle_min", scan.angle_min),
        ("angle_max", scan.angle_max),
        ("angle_increment", scan.angle_increment),
        ("range_min", range_min),
        ("range_max", range_max),
    ):
        if not math.isfinite(value):
            raise ScanError(
                "non_finite_field", f"scan field {name} is {value}, not a finite number", name
            )
    if range_min < 0.0:
        raise ScanError(
            "range_limits",
            f"range_min is negative ({range_min:g} m): no laser measures that",
            "range_min",
        )
    if range_max <= range_min:
        raise ScanError(
            "range_limits",
            f"range_max ({range_max:g} m) <= range_min ({range_min:g} m): no reading can be valid",
            "range_max",
        )


def _check_beam_angles(scan: LaserScanData, n: int) -> None:
    """ScanError unless the angle fields describe the ``n`` beams of ``ranges``: a nonzero
    increment of the sign of angle_max - angle_min, no more than a full turn, and as many
    beams as ranges (within a beam either way)."""
    angle_min, angle_max, angle_increment = scan.angle_min, scan.angle_max, scan.angle_increment
    if n > 1 and angle_increment == 0.0:
        raise ScanError(
            "zero_increment", f"angle_increment is 0 for a scan of {n} beams", "angle_increment"
        )
    span = angle_max - angle_min
    if n > 1 and span != 0.0 and (span > 0.0) != (angle_increment > 0.0):
        raise ScanError(
            "angle_order",
            f"angle_max ({angle_max:.4f} rad) - angle_min ({angle_min:.4f} rad) = {span:.4f} rad "
            f"has the opposite sign of angle_increment ({angle_increment:.6f} rad)",
            "angle_max",
        )
    sweep = abs(angle_increment) * (n - 1)
    if sweep > _FULL_TURN + abs(angle_increment):
        raise ScanError(
            "beam_span",
            f"ranges has {n} beams: at angle_increment {angle_increment:.6f} rad they sweep "
            f"{math.degrees(sweep):.0f} deg, more than a full turn "
            f"(angle_min..angle_max describe {abs(span) / abs(angle_increment) + 1:.0f} beams)",
            "ranges",
        )
    if n > 1:
        # Drivers disagree on whether angle_max is the last beam's angle or one increment
        # beyond it: a beam of slack either way. More is a scan whose fields contradict it.
        expected = abs(span) / abs(angle_increment) + 1.0
        if abs(expected - n) > 1.5:
            raise ScanError(
                "beam_count",
                f"ranges has {n} beams but angle_min/angle_max/angle_increment describe "
                f"{expected:.0f}: the fields contradict each other",
                "ranges",
            )


def _intensities_notices(intensities: FloatArray | None, n: int) -> list[ScanNotice]:
    """A notice when the intensities are given but not one per beam (they are ignored)."""
    if intensities is not None:
        n_int = np.asarray(intensities).size
        if n_int not in (0, n):
            return [
                ScanNotice(
                    "intensities_length",
                    f"intensities has {n_int} entries but ranges has {n}; intensities ignored",
                )
            ]
    return []


def _non_finite_notices(dropped: tuple[tuple[str, int], ...], n: int) -> list[ScanNotice]:
    """A notice when some of the ``n`` ranges are NaN or infinite (``dropped``, by kind)."""
    counts = dict(dropped)
    n_nan, n_inf = counts.get("nan", 0), counts.get("+inf", 0) + counts.get("-inf", 0)
    if n_nan or n_inf:
        return [
            ScanNotice(
                "non_finite_ranges",
                f"{n_nan} NaN and {n_inf} inf of {n} ranges: treated as no return",
            )
        ]
    return []


def _dropped_by_kind(
    r: FloatArray, range_min: float, range_max: float
) -> tuple[tuple[str, int], ...]:
    """How many beams are NaN, +inf, -inf, below range_min, at or beyond range_max."""
    nan = np.isnan(r)
    pos_inf = r == np.inf
    neg_inf = r == -np.inf
    finite = ~(nan | pos_inf | neg_inf)
    counts = (
        ("nan", int(np.count_nonzero(nan))),
        ("+inf", int(np.count_nonzero(pos_inf))),
        ("-inf", int(np.count_nonzero(neg_inf))),
        ("below_range_min", int(np.count_nonzero(finite & (r < range_min)))),
        ("beyond_range_max", int(np.count_nonzero(finite & (r >= range_max)))),
    )
    return tuple((kind, count) for kind, count in counts if count)


# A laser never changes its beam geometry, so the cosine and sine of every beam angle are
# computed once per (angle_min, angle_increment, beam count) and reused: the trigonometry is
# the dearest part of the conversion. A few geometries (one per laser) are kept.
@functools.lru_cache(maxsize=16)
def _beam_directions(
    angle_min: float, angle_increment: float, n: int
) -> tuple[FloatArray, FloatArray]:
    """Cosine and sine of beam i's angle ``angle_min + i * angle_increment`` (read-only,
    memoised: a pure function of the geometry)."""
    angles = angle_min + angle_increment * np.arange(n, dtype=np.float64)
    cos, sin = np.cos(angles), np.sin(angles)
    cos.flags.writeable = False
    sin.flags.writeable = False
    return cos, sin
