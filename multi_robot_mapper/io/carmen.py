"""Reader for CARMEN laser logs (``FLASER`` lines), plain or gzip-compressed.

Only the laser readings and the reference pose stored with them are read; the odometry fields
of each line are skipped on purpose (this project maps without odometry).

The log is the boundary: what leaves this module is clean. A ``FLASER`` line whose ranges,
pose or stamp hold NaN or inf, a malformed or cut line, or a line of another message type is
skipped and counted (:attr:`CarmenLog.skipped`, :attr:`CarmenLog.other_lines`), never passed
on. Beam geometry and the no-return value follow CARMEN's own reader (``readlog.c``) and the
log's ``PARAM`` lines; :meth:`CarmenLog.summary` says which were used.
"""

from __future__ import annotations

import dataclasses
import gzip
import math
import zlib
from collections import Counter
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, overload

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.scan import LaserScanData

FloatArray = NDArray[np.float64]

# The no-return marker of a laser repeats at the top of the range histogram, sometimes with a
# little noise around it (edmonton: 51.09-51.16 m around 51.15 m): readings this close below
# the marker are no return too.
NO_RETURN_TOLERANCE_M = 0.1
# The marker is looked for among the readings within this fraction of the largest one.
_TOP_BAND = 0.01
# A PARAM maximum that this share of the readings exceeds (short of the marker) is a cap the
# robot software applied, not the sensor's maximum (edmonton: robot_front_laser_max 10 m,
# a quarter of its readings between 10 and 51 m).
_PARAM_CONTRADICTED_SHARE = 0.01
_RANGE_PARAMS = ("robot_front_laser_max", "laser_front_laser_max_range")
# No FLASER line of a real laser comes near this; a longer line is refused unread.
MAX_LINE_CHARS = 1_000_000
MAX_BEAMS = 100_000
# builtin_interfaces/Time counts seconds in an int32: a stamp beyond is no stamp at all.
MAX_STAMP_S = 2.0**31
# Stamps of a run must increase for replay and for sorting by stamp. Some logs repeat or step
# back their ipc timestamps (intel: 4 times; csail stores them to 6 digits, so all 406 scans
# share 2 values); such a scan is put this much after the one before it.
MIN_STAMP_STEP_S = 1e-3
# Scan period assumed for logs whose own clock cannot order the scans.
NOMINAL_PERIOD_S = 1.0
# Where a clock that starts at or below zero is moved to (ROS time is never negative, and a
# zero stamp means "not set").
FIRST_STAMP_S = 1.0


class CarmenFormatError(ValueError):
    """The log cannot be read (or a line cannot be parsed); the message names the line."""


@dataclasses.dataclass(frozen=True)
class CarmenScan:
    """One FLASER reading: ranges, beam geometry and the log's reference laser pose."""

    ranges: FloatArray
    angle_min: float
    angle_increment: float
    reference_pose: tuple[float, float, float]  # x, y, theta of the laser in the world frame
    timestamp: float  # ipc_timestamp, seconds
    # Readings at or beyond this are "no return"; decided for the whole log by read_carmen.
    range_max: float = math.inf
    line_number: int = 0

    @property
    def angle_max(self) -> float:
        return self.angle_min + self.angle_increment * (len(self.ranges) - 1)


def beam_geometry(beam_count: int) -> tuple[float, float]:
    """``(angle_min, angle_increment)`` of a CARMEN front laser with ``beam_count`` beams.

    As CARMEN's own reader has it (``carmen_laser_guess_fov`` and
    ``carmen_laser_guess_angle_increment``, start angle -90 deg): 180 and 181 beams are 1 deg
    apart, 360 and 361 beams 0.5 deg apart, all from -90 deg; so 181 and 361 beams span 180 deg
    and 180 and 360 beams 179 and 179.5 deg (the SICK's last beam is not logged). Any other
    count spans 180 deg inclusively.
    """
    if beam_count < 2:
        raise CarmenFormatError(f"a FLASER line needs at least 2 beams, got {beam_count}")
    if beam_count in (180, 181):
        return -math.pi / 2.0, math.radians(1.0)
    if beam_count in (360, 361):
        return -math.pi / 2.0, math.radians(0.5)
    return -math.pi / 2.0, math.pi / (beam_count - 1)


def parse_flaser(line: str, line_number: int = 0) -> CarmenScan:
    """Parse one ``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ts host logger_ts``.

    Raises :class:`CarmenFormatError` for a malformed line and for NaN or inf in the ranges,
    the pose or the stamp (message starting with ``non-finite``).
    """
    fields = line.split()
    try:
        n = int(fields[1])
        if not 0 <= n <= MAX_BEAMS:
            raise ValueError(f"beam count {n} outside [0, {MAX_BEAMS}]")
        ranges = np.array(fields[2 : 2 + n], dtype=np.float64)
        x, y, theta = (float(v) for v in fields[2 + n : 5 + n])
        timestamp = float(fields[8 + n])
        if math.isfinite(timestamp) and abs(timestamp) > MAX_STAMP_S:
            raise ValueError(f"timestamp {timestamp:g} s outside +-{MAX_STAMP_S:g} s")
    except (IndexError, ValueError) as exc:
        raise CarmenFormatError(f"line {line_number}: malformed FLASER line ({exc})") from exc
    if ranges.size != n:
        raise CarmenFormatError(
            f"line {line_number}: FLASER announces {n} ranges, has {ranges.size}"
        )
    if not (np.isfinite(ranges).all() and math.isfinite(x + y + theta + timestamp)):
        raise CarmenFormatError(f"line {line_number}: non-finite value (NaN or inf)")
    try:
        angle_min, increment = beam_geometry(n)
    except CarmenFormatError as exc:
        raise CarmenFormatError(f"line {line_number}: {exc}") from exc
    return CarmenScan(
        ranges=ranges,
        angle_min=angle_min,
        angle_increment=increment,
        reference_pose=(x, y, theta),
        timestamp=timestamp,
        line_number=line_number,
    )


@dataclasses.dataclass(frozen=True)
class NoReturn:
    """How a log's no-return readings are recognised: readings ``>= range_max``."""

    range_max: float
    source: str  # "PARAM <name>", "range histogram", "--range-max" or "none found"
    marker: float | None = None  # the reading the laser gives for no return, when seen
    marker_count: int = 0
    note: str = ""

    def describe(self) -> str:
        seen = (
            f"; the log marks no return with {self.marker:g} m ({self.marker_count} readings)"
            if self.marker is not None
            else ""
        )
        note = f"; {self.note}" if self.note else ""
        return f"no return: readings >= {self.range_max:g} m ({self.source}){seen}{note}"


_HISTOGRAM = "value repeating at the top of the range histogram"


def find_no_return(
    readings: FloatArray, scan_of_reading: NDArray[np.int64], params: dict[str, str]
) -> NoReturn:
    """The no-return threshold of a log: from a ``PARAM`` with the laser's maximum when the
    readings agree with it, else from the value repeating at the top of the range histogram
    (a marker seen in at least two scans), else none (every reading is a return).

    A sensor marks "no return" with its maximum, which depends on the sensor and its mode
    (about 81.9 m, 50-51 m, 32.767 m); a fixed cut would turn some of them into walls.
    """
    if readings.size == 0:
        return NoReturn(range_max=1.0, source="none found: no reading")
    marker, marker_count = _repeating_top(readings, scan_of_reading)
    histogram_max = None if marker is None else marker - NO_RETURN_TOLERANCE_M
    name, value = _param_maximum(params)
    if name is not None:
        if histogram_max is None:
            return NoReturn(
                range_max=value, source=f"PARAM {name}", marker=marker, marker_count=marker_count
            )
        beyond = int(np.count_nonzero((readings >= value) & (readings < histogram_max)))
        if value <= histogram_max and beyond <= _PARAM_CONTRADICTED_SHARE * readings.size:
            return NoReturn(
                range_max=value, source=f"PARAM {name}", marker=marker, marker_count=marker_count
            )
        why = (
            "it lies above the no-return value"
            if value > histogram_max
            else f"{100.0 * beyond / readings.size:.1f} % of the readings lie between it and "
            "the no-return value"
        )
        note = f"PARAM {name} {value:g} m not used: {why}"
        return NoReturn(
            range_max=histogram_max,
            source=_HISTOGRAM,
            note=note,
            marker=marker,
            marker_count=marker_count,
        )
    if histogram_max is not None:
        return NoReturn(
            range_max=histogram_max, source=_HISTOGRAM, marker=marker, marker_count=marker_count
        )
    return NoReturn(
        range_max=float(readings.max()) + NO_RETURN_TOLERANCE_M,
        source="none found: no PARAM and no value repeating at the top of the ranges",
    )


def _repeating_top(
    readings: FloatArray, scan_of_reading: NDArray[np.int64]
) -> tuple[float | None, int]:
    """The most frequent reading near the largest one, if it repeats in two scans or more."""
    top = readings >= float(readings.max()) * (1.0 - _TOP_BAND)
    values, counts = np.unique(readings[top], return_counts=True)
    best = int(np.argmax(counts))
    if counts[best] < 3:
        return None, 0
    scans = np.unique(scan_of_reading[top][readings[top] == values[best]])
    return (float(values[best]), int(counts[best])) if scans.size >= 2 else (None, 0)


def _param_maximum(params: dict[str, str]) -> tuple[str | None, float]:
    """The first PARAM giving the front laser's maximum range as a positive number."""
    for name in _RANGE_PARAMS:
        try:
            value = float(params.get(name, "nan"))
        except ValueError:
            continue
        if math.isfinite(value) and value > 0.0:
            return name, value
    return None, math.nan


@dataclasses.dataclass(frozen=True)
class CarmenLog(Sequence[CarmenScan]):
    """The usable FLASER scans of a log (a sequence, in file order) and what was left out."""

    path: Path
    scans: tuple[CarmenScan, ...]
    no_return: NoReturn
    params: dict[str, str]
    skipped: dict[str, int]  # reason -> FLASER lines skipped
    skipped_lines: tuple[int, ...]  # the first few skipped line numbers
    other_lines: dict[str, int]  # message type -> lines not used
    truncated: bool = False  # the gzip stream ended early

    @overload
    def __getitem__(self, index: int) -> CarmenScan: ...
    @overload
    def __getitem__(self, index: slice) -> Sequence[CarmenScan]: ...
    def __getitem__(self, index: int | slice) -> CarmenScan | Sequence[CarmenScan]:
        return self.scans[index]

    def __len__(self) -> int:
        return len(self.scans)

    def __iter__(self) -> Iterator[CarmenScan]:
        return iter(self.scans)

    def skipped_summary(self) -> list[str]:
        """What of the log was not read: skipped FLASER lines, a truncated end."""
        lines = []
        if self.skipped:
            where = ", ".join(str(n) for n in self.skipped_lines)
            more = ", ..." if sum(self.skipped.values()) > len(self.skipped_lines) else ""
            kinds = ", ".join(f"{count} {reason}" for reason, count in self.skipped.items())
            lines.append(f"FLASER lines skipped: {kinds} (lines {where}{more})")
        if self.truncated:
            lines.append("the compressed file ends early (truncated): read up to that point")
        return lines

    def summary(self) -> list[str]:
        """Lines for the import summary: beam geometry, no-return value, what was skipped."""
        lines = []
        for count in sorted({s.ranges.size for s in self.scans}):
            angle_min, step = beam_geometry(count)
            span = math.degrees(step * (count - 1))
            lines.append(
                f"beams: {count} from {math.degrees(angle_min):g} deg every "
                f"{math.degrees(step):.4g} deg ({span:.4g} deg; CARMEN's FLASER geometry)"
            )
        lines.append(self.no_return.describe())
        lines.extend(self.skipped_summary())
        if self.other_lines:
            common = Counter(self.other_lines).most_common()
            shown = ", ".join(f"{kind} {count}" for kind, count in common[:6])
            more = f" and {len(common) - 6} other kinds" if len(common) > 6 else ""
            lines.append(f"other lines not used: {shown}{more}")
        return lines


_SHOWN_SKIPPED_LINES = 5


def _lines(stream: IO[str]) -> Iterator[tuple[str, bool]]:
    """Lines of at most MAX_LINE_CHARS, each with whether it ended with a newline; the rest of
    an over-long line is consumed and dropped."""
    while True:
        line = stream.readline(MAX_LINE_CHARS)
        if not line:
            return
        complete = line.endswith("\n")
        if not complete and len(line) >= MAX_LINE_CHARS:
            while True:  # drop the rest of the over-long line
                rest = stream.readline(MAX_LINE_CHARS)
                if not rest or rest.endswith("\n"):
                    break
            yield "", True
            continue
        yield line, complete


@dataclasses.dataclass
class _LogLines:
    """What :func:`read_carmen` gathers from a log, line by line."""

    scans: list[CarmenScan] = dataclasses.field(default_factory=list)
    params: dict[str, str] = dataclasses.field(default_factory=dict)
    skipped: Counter[str] = dataclasses.field(default_factory=Counter)  # reason -> lines
    skipped_lines: list[int] = dataclasses.field(default_factory=list)  # the first few
    other: Counter[str] = dataclasses.field(default_factory=Counter)  # kind -> lines

    def take(self, line: str, number: int, complete: bool) -> None:
        """One line (``""``: an over-long one, dropped) numbered ``number``; ``complete``: it
        ended with a newline (a FLASER line without one was cut, not malformed)."""
        kind = line.split(maxsplit=1)[0] if line.strip() else ""
        if kind == "FLASER":
            self._take_flaser(line, number, complete)
        elif kind == "PARAM":
            words = line.split()
            if len(words) >= 3:
                self.params[words[1]] = words[2]
            self.other[kind] += 1
        elif not line:
            self.skipped["over-long"] += 1
        elif kind.startswith("#"):
            self.other["comment"] += 1
        elif kind:
            self.other[kind if kind.isalnum() and len(kind) <= 20 else "unrecognised"] += 1

    def _take_flaser(self, line: str, number: int, complete: bool) -> None:
        try:
            self.scans.append(parse_flaser(line, number))
            return
        except CarmenFormatError as exc:
            reason = (
                "with NaN/inf"
                if "non-finite" in str(exc)
                else "cut (last line)"
                if not complete
                else "malformed"
            )
        self.skipped[reason] += 1
        if len(self.skipped_lines) < _SHOWN_SKIPPED_LINES:
            self.skipped_lines.append(number)


def _log_no_return(
    scans: Sequence[CarmenScan], params: dict[str, str], range_max: float | None
) -> NoReturn:
    """The no-return threshold: ``range_max`` when given, else the one the log shows."""
    if range_max is not None:
        return NoReturn(range_max=range_max, source="--range-max")
    ranges = [s.ranges for s in scans]
    readings = np.concatenate(ranges) if ranges else np.zeros(0)
    owner = (
        np.repeat(np.arange(len(scans)), [r.size for r in ranges])
        if ranges
        else np.zeros(0, np.int64)
    )
    return find_no_return(readings, owner, params)


def read_carmen(path: str | Path, range_max: float | None = None) -> CarmenLog:
    """Every usable FLASER scan of a CARMEN log (``.gz`` is decompressed on the fly).

    ``range_max`` overrides the no-return threshold found in the log (:func:`find_no_return`).
    Raises :class:`CarmenFormatError` (or ``OSError``) only when the file cannot be read at all.
    """
    path = Path(path)
    log = _LogLines()
    truncated = False
    number = 0
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt", encoding="ascii", errors="replace") as stream:
            for number, (line, complete) in enumerate(_lines(stream), start=1):
                log.take(line, number, complete)
    except EOFError:
        truncated = True  # a gzip stream cut short: keep the lines read so far
    except (gzip.BadGzipFile, zlib.error) as exc:
        raise CarmenFormatError(
            f"{path}: corrupt compressed data after line {number} ({exc})"
        ) from exc
    no_return = _log_no_return(log.scans, log.params, range_max)
    return CarmenLog(
        path=path,
        scans=tuple(dataclasses.replace(s, range_max=no_return.range_max) for s in log.scans),
        no_return=no_return,
        params=log.params,
        skipped=dict(log.skipped),
        skipped_lines=tuple(log.skipped_lines),
        other_lines=dict(log.other),
        truncated=truncated,
    )


def increasing(stamps: FloatArray, step: float = MIN_STAMP_STEP_S) -> FloatArray:
    """``stamps`` made strictly increasing: each at least ``step`` after the one before."""
    # stamp_i = max over j <= i of (t_j + (i - j) step): a running maximum after removing the
    # ramp, added back (vectorised form of t_i = max(t_i, t_{i-1} + step)).
    ramp = step * np.arange(len(stamps), dtype=np.float64)
    return np.asarray(np.maximum.accumulate(stamps - ramp) + ramp)


def monotonic_stamps(logged: FloatArray, name: str) -> tuple[FloatArray, list[str]]:
    """Strictly increasing, positive stamps for scans in file order, and notes saying what was
    changed: a clock too coarse to order the scans gives one scan per ``NOMINAL_PERIOD_S``; a
    clock that runs backwards (more steps back than forward) is read backwards, keeping its
    spacing; single steps that do not increase are moved ``MIN_STAMP_STEP_S`` after the scan
    before; a clock at or below zero is shifted to start at ``FIRST_STAMP_S``."""
    logged = np.asarray(logged, dtype=np.float64)
    count = len(logged)
    notes: list[str] = []
    steps = np.diff(logged)
    repeats = int(np.count_nonzero(steps == 0.0))
    backward = int(np.count_nonzero(steps < 0.0))
    forward = int(np.count_nonzero(steps > 0.0))
    if repeats > count // 2:
        # The log's clock is too coarse to order its scans (csail's are written with six
        # significant digits): number them at a nominal period instead of inventing times.
        stamps = logged[0] + NOMINAL_PERIOD_S * np.arange(count, dtype=np.float64)
        notes.append(
            f"{repeats} of {count} timestamps of {name} repeat (too coarse a clock); "
            f"stamps set one scan per {NOMINAL_PERIOD_S:g} s from the first"
        )
    else:
        clock = logged
        if backward > forward:
            clock = 2.0 * logged[0] - logged  # read backwards from the first stamp
            notes.append(
                f"{backward} of {count - 1} steps between the timestamps of {name} go "
                "backwards: scans imported in file order, the clock read backwards from the "
                "first stamp (spacing kept)"
            )
        stamps = increasing(clock)
        adjusted = int(np.count_nonzero(stamps != clock))
        if adjusted:
            notes.append(
                f"{adjusted} of {count} timestamps of {name} do not increase; moved to "
                f"{MIN_STAMP_STEP_S * 1e3:g} ms after the scan before"
            )
    if count and stamps[0] <= 0.0:
        shift = FIRST_STAMP_S - float(stamps[0])
        stamps = stamps + shift
        notes.append(
            f"the timestamps of {name} start at {logged[0]:g} s (ROS time is positive): "
            f"all moved by {shift:+g} s"
        )
    return stamps, notes


def carmen_scan_data(scan: CarmenScan) -> LaserScanData:
    """The LaserScan geometry of a CARMEN reading (no-return readings lie at or beyond
    ``range_max``, as :func:`read_carmen` decided it for the log)."""
    if not math.isfinite(scan.range_max):
        raise ValueError("the scan's range_max is not decided: read it with read_carmen()")
    return LaserScanData(
        ranges=scan.ranges,
        angle_min=scan.angle_min,
        angle_max=scan.angle_max,
        angle_increment=scan.angle_increment,
        range_min=0.0,
        range_max=scan.range_max,
    )
