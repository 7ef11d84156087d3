"""A robot's scan stream checked against itself before any scan is mapped.

One laser on one robot sends one stream: the same beam geometry every scan, stamps that
advance at the laser's own cadence, and ranges that are never the same twice (every reading
carries noise). A scan that contradicts its own stream is refused before it reaches the
mapper, counted per reason, and the map and the mapper's state stay as they were. Rules, in
the order they are checked (each refusal names one reason: the first rule broken):

``zero_stamp``
    The stamp is zero: never set.
``future_stamp``
    More than ``max_lead`` seconds ahead of the node's clock (a node only: replay has none).
``angle_fields``
    ``angle_min``, ``angle_max``, ``angle_increment`` or the beam count differ from the
    stream's established geometry. The first scan establishes it; a laser does not change its
    geometry mid-run, but one that was really reconfigured sends the new geometry in every
    scan from then on: ``geometry_scans`` consecutive scans of one new geometry make it the
    stream's (the last of them is mapped, the earlier ones were refused; a warning says so).
``duplicate_stamp`` / ``stale_stamp``
    The stamp repeats the last mapped scan's, or lies behind it by at most ``reset_jump``.
``stamp_jump_ahead`` / ``stamp_jump_back``
    A stamp more than ``gap_periods`` of the stream's cadence (the median of its recent
    intervals) ahead of the last mapped scan's, or more than ``reset_jump`` behind it, is
    held, not mapped: one corrupt stamp must neither make every later good scan look stale
    nor start the map over. The held scans are released when ``confirm_scans`` scans in all
    continue the new time (a gap in the laser's stream: mapped in order; a clock that jumped
    back and stays there, a bag played again: the map starts over, then they are mapped), and
    refused under these names when the next scan continues the old time instead.
``copied_ranges``
    The ranges are an exact copy of one of the last ``copy_window`` mapped scans' (with at
    least :data:`COPY_MIN_RETURNS` readings: a scan of open space, all no-return, legitimately
    repeats). Not for scans that jump back beyond ``reset_jump``: a bag played again repeats
    its scans exactly, and the copies are forgotten when the map starts over.

A node that drops scans for load before they reach the guard tells it
(:meth:`ScanStreamGuard.skipped`), so that the next scan it maps is not taken for a jump.

:class:`ScanStreamGuard` is pure (no ROS): ``robot_mapper`` and the offline pipeline (``mrm
replay``) put every scan through one, so a bag replayed gives what the node gave.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections import deque
from types import MappingProxyType
from typing import Generic, TypeVar

import numpy as np

from multi_robot_mapper.core.scan import LaserScanData

T = TypeVar("T")

# A scan with fewer readings in [range_min, range_max) than this is never called a copy: open
# space (every beam no-return) looks the same scan after scan.
COPY_MIN_RETURNS = 10
# Intervals between mapped scans the cadence is measured over (their median).
_CADENCE_INTERVALS = 21
# The LaserScan fields each refusal is about (for the node's warnings).
REASON_FIELDS = MappingProxyType(
    {
        "zero_stamp": "header.stamp",
        "future_stamp": "header.stamp",
        "angle_fields": "angle_min/angle_max/angle_increment/ranges",
        "duplicate_stamp": "header.stamp",
        "stale_stamp": "header.stamp",
        "stamp_jump_ahead": "header.stamp",
        "stamp_jump_back": "header.stamp",
        "copied_ranges": "ranges",
    }
)
# Angle fields within this are the same (float32 fields carried through float64: exact in
# practice; the slack only absorbs a round trip through text).
_ANGLE_TOLERANCE = 1e-6  # rad


@dataclasses.dataclass(frozen=True)
class ScanStreamConfig:
    """The stream rules' settings, at the robot mapper node's defaults (its parameters
    ``stamp_reset_jump`` ... ``copy_window``, ros/mapper_config.py, document each)."""

    reset_jump: float = 5.0  # s
    max_lead: float = 10.0  # s
    gap_periods: float = 10.0  # intervals of the stream's cadence
    confirm_scans: int = 3
    geometry_scans: int = 10
    copy_window: int = 200  # scans


@dataclasses.dataclass(frozen=True)
class Held(Generic[T]):
    """A scan held by the stamp rules, with what the caller needs to map it later."""

    stamp: float
    item: T


@dataclasses.dataclass(frozen=True)
class StreamVerdict(Generic[T]):
    """What to do with a scan.

    ``action``: ``map`` (map ``release``, then this scan), ``hold`` (nothing now; this scan
    may be released later), ``reset`` (start the robot's map over, then map ``release`` and
    this scan) or ``refuse``. ``refused``: scans set aside by this verdict, each with its
    reason (this scan's own, or scans held earlier that the stream contradicted).
    ``notices``: what to warn about that refuses nothing (the laser's geometry changed, the
    map starts over)."""

    action: str
    refused: tuple[tuple[str, str], ...] = ()  # (reason, message) per scan set aside
    release: tuple[Held[T], ...] = ()
    notices: tuple[tuple[str, str], ...] = ()  # (kind, message): "laser_geometry", "map_reset"

    @property
    def maps(self) -> bool:
        """This scan (and ``release``) are to be mapped."""
        return self.action in ("map", "reset")


@dataclasses.dataclass(frozen=True)
class _Geometry:
    angle_min: float
    angle_max: float
    angle_increment: float
    beams: int

    @staticmethod
    def of(scan: LaserScanData) -> _Geometry:
        return _Geometry(
            float(scan.angle_min),
            float(scan.angle_max),
            float(scan.angle_increment),
            int(np.asarray(scan.ranges).size),
        )

    def same(self, other: _Geometry) -> bool:
        return self.beams == other.beams and all(
            abs(a - b) <= _ANGLE_TOLERANCE
            for a, b in (
                (self.angle_min, other.angle_min),
                (self.angle_max, other.angle_max),
                (self.angle_increment, other.angle_increment),
            )
        )

    def describe(self) -> str:
        return (
            f"angle_min {self.angle_min:.6f}, angle_max {self.angle_max:.6f}, "
            f"angle_increment {self.angle_increment:.6f} rad, {self.beams} beams"
        )


def ranges_digest(scan: LaserScanData) -> bytes | None:
    """A digest of the scan's ranges, or None when it has too few readings to be a copy."""
    r = np.asarray(scan.ranges, dtype=np.float64).ravel()
    with np.errstate(invalid="ignore"):
        returns = int(np.count_nonzero((r >= scan.range_min) & (r < scan.range_max)))
    if returns < COPY_MIN_RETURNS:
        return None
    return hashlib.blake2b(np.ascontiguousarray(r).tobytes(), digest_size=16).digest()


class ScanStreamGuard(Generic[T]):
    """One robot's scan stream: the rules of the module docstring, scan by scan.

    :meth:`check` each scan in arrival order, with ``item`` (what the caller needs to map it
    later, should it be held); act on the verdict. :meth:`finish` refuses what is still held
    when the stream ends."""

    def __init__(self, config: ScanStreamConfig) -> None:
        self.config = config
        self._geometry: _Geometry | None = None
        self._candidate: tuple[_Geometry, int] | None = None  # a new geometry, scans in a row
        self.last: float | None = None  # stamp of the last mapped scan
        self._intervals: deque[float] = deque(maxlen=_CADENCE_INTERVALS)
        self._held: list[Held[T]] = []
        self._held_back = False  # the held scans jumped back (a reset if confirmed)
        self._held_step = 0.0  # how far ahead the held scans jumped (a new cadence, maybe)
        self._digests: deque[bytes] = deque()
        self._digest_set: set[bytes] = set()
        self._held_digests: list[bytes | None] = []  # of the held scans, in order

    # --- state ------------------------------------------------------------------------------

    @property
    def held(self) -> int:
        """Scans held now (neither mapped nor refused yet)."""
        return len(self._held)

    def gap(self) -> float:
        """How far ahead of the last mapped scan a stamp may lie and be mapped at once:
        ``gap_periods`` of the stream's cadence (``reset_jump`` until it has one)."""
        if len(self._intervals) < 3:
            return self.config.reset_jump
        return self.config.gap_periods * float(np.median(np.asarray(self._intervals)))

    def reconfigure(self, config: ScanStreamConfig) -> None:
        """New settings from the next scan on (what the stream established is kept)."""
        self.config = config

    # --- the rules --------------------------------------------------------------------------

    def check(
        self, stamp: float, scan: LaserScanData, item: T, now: float | None = None
    ) -> StreamVerdict[T]:
        """The verdict on one scan. ``now``: the node's clock in seconds (None or 0: no clock
        yet, or replay)."""
        if stamp == 0.0:
            return _refuse("zero_stamp", "header.stamp is zero (never set)")
        lead = self.config.max_lead
        if now and stamp > now + lead:
            return _refuse(
                "future_stamp",
                f"header.stamp {stamp:.3f} s is {stamp - now:.3g} s ahead of this node's clock "
                f"(max_stamp_lead {lead:g} s)",
            )
        geometry = _Geometry.of(scan)
        notice = ""
        if self._geometry is None:
            self._geometry = geometry  # the first scan's
        elif not geometry.same(self._geometry):
            established = self._geometry
            changed = self._new_geometry(geometry)
            if changed is None:
                return _refuse(
                    "angle_fields",
                    f"{geometry.describe()}: this laser's scans have {established.describe()}",
                )
            notice = changed
        else:
            self._candidate = None  # a scan of the stream's geometry ends a run of another
        refusal = self._stamp_refusal(stamp)
        if refusal is not None:
            return StreamVerdict("refuse", refused=(refusal,))
        digest = ranges_digest(scan)
        # A bag played again repeats its scans exactly: a jump back is judged by its stamps
        # alone (the copies are forgotten when the map starts over).
        if digest is not None and digest in self._digest_set and not self._jumps_back(stamp):
            return _refuse(
                "copied_ranges",
                f"ranges (stamp {stamp:.3f} s) are an exact copy of one of the last "
                f"{self.config.copy_window} scans' (no laser reads the same twice)",
            )
        verdict = self._place_in_time(stamp, item, digest)
        if notice:
            notices = (("laser_geometry", notice), *verdict.notices)
            verdict = dataclasses.replace(verdict, notices=notices)
        return verdict

    def skipped(self, stamp: float) -> None:
        """A scan of this stream that will not be mapped (a node dropped it for load: it
        waited too long in the queue, or ``max_scan_rate`` left it out): when it continues the
        stream's time, that time moves on with it, so that the next scan mapped after many
        dropped ones is not taken for a jump ahead."""
        last = self.last
        if last is not None and not self._held and last < stamp <= last + self.gap():
            self._intervals.append(stamp - last)
            self.last = stamp

    def finish(self) -> tuple[tuple[str, str], ...]:
        """The stream ended: the scans still held are refused (reason, message each)."""
        return self._drop_held("the stream ended before later scans confirmed its time")

    # --- helpers ----------------------------------------------------------------------------

    def _new_geometry(self, geometry: _Geometry) -> str | None:
        """A scan of another geometry than the stream's: None (refused) until
        ``geometry_scans`` in a row have it; then the notice that it is the stream's now."""
        candidate = self._candidate
        count = candidate[1] + 1 if candidate is not None and candidate[0].same(geometry) else 1
        self._candidate = (geometry, count)
        if count < self.config.geometry_scans:
            return None
        old = self._geometry
        assert old is not None
        self._geometry, self._candidate = geometry, None
        return (
            f"the laser's geometry changed ({old.describe()} -> {geometry.describe()}): "
            f"{count} scans in a row have it, it is this stream's from now on"
        )

    def _stamp_refusal(self, stamp: float) -> tuple[str, str] | None:
        """``duplicate_stamp`` or ``stale_stamp`` (reason, message), or None."""
        last = self.last
        if last is None or (self._held and self._continues_held(stamp)):
            return None
        if self._held and stamp == self._held[-1].stamp:
            return ("duplicate_stamp", f"header.stamp {stamp:.3f} s repeats a held scan's")
        if stamp == last:
            return ("duplicate_stamp", f"header.stamp {stamp:.3f} s repeats the last scan's")
        if last - self.config.reset_jump <= stamp < last:
            return (
                "stale_stamp",
                f"header.stamp {stamp:.3f} s is {last - stamp:.3g} s older than the last scan's",
            )
        return None

    def _place_in_time(self, stamp: float, item: T, digest: bytes | None) -> StreamVerdict[T]:
        """Map a scan that continues the stream (or the scans held); hold one that jumps."""
        last = self.last
        if last is None:
            self._mapped(stamp, digest)
            return StreamVerdict("map")
        if self._held and self._continues_held(stamp):
            self._held.append(Held(stamp, item))
            self._held_digests.append(digest)
            return self._confirmed(())
        if last < stamp <= last + self.gap():
            dropped = self._drop_held("the next scan continued the stream's time")
            self._mapped(stamp, digest)
            return StreamVerdict("map", refused=dropped)
        # A jump ahead of the cadence or back beyond reset_jump: held until confirmed.
        dropped = self._drop_held("the next scan jumped elsewhere")
        self._held = [Held(stamp, item)]
        self._held_digests = [digest]
        self._held_back = stamp < last
        # A step ahead may be a new cadence (a laser slowed down, or one whose intervals vary
        # more than gap() allows): later scans as far apart continue it.
        self._held_step = 0.0 if self._held_back else stamp - last
        return self._confirmed(dropped)

    def _jumps_back(self, stamp: float) -> bool:
        """The scan starts or continues a jump back beyond ``reset_jump``."""
        last = self.last
        if last is None:
            return False
        if self._held and self._continues_held(stamp):
            return self._held_back
        return stamp < last - self.config.reset_jump

    def _continues_held(self, stamp: float) -> bool:
        newest = self._held[-1].stamp
        return newest < stamp <= newest + max(self.gap(), self._held_step)

    def _confirmed(self, dropped: tuple[tuple[str, str], ...]) -> StreamVerdict[T]:
        """Hold, or release once ``confirm_scans`` scans continue the new time."""
        if len(self._held) < self.config.confirm_scans:
            return StreamVerdict("hold", refused=dropped)
        held, digests, back = self._held, self._held_digests, self._held_back
        self._held, self._held_digests = [], []
        notices: tuple[tuple[str, str], ...] = ()
        if back:
            text = (
                f"header.stamp jumped back {(self.last or 0.0) - held[0].stamp:.3g} s (more than "
                f"stamp_reset_jump {self.config.reset_jump:g} s) and {len(held)} scans stayed "
                "there (a bag played again, a clock reset): the map starts over"
            )
            notices = (("map_reset", text),)
            self.last = None
            self._intervals.clear()
            self._digests.clear()
            self._digest_set.clear()
        for scan, digest in zip(held, digests, strict=True):
            self._mapped(scan.stamp, digest)
        return StreamVerdict(
            "reset" if back else "map", refused=dropped, release=tuple(held[:-1]), notices=notices
        )

    def _drop_held(self, why: str) -> tuple[tuple[str, str], ...]:
        if not self._held:
            return ()
        last = self.last
        kind = "stamp_jump_back" if self._held_back else "stamp_jump_ahead"
        refused = tuple(
            (
                kind,
                f"header.stamp {held.stamp:.3f} s jumped {abs(held.stamp - (last or 0.0)):.3g} s "
                f"{'back' if self._held_back else 'ahead'} of the stream's ({why})",
            )
            for held in self._held
        )
        self._held, self._held_digests = [], []
        return refused

    def _mapped(self, stamp: float, digest: bytes | None) -> None:
        if self.last is not None and stamp > self.last:
            self._intervals.append(stamp - self.last)
        self.last = stamp
        if digest is not None and digest not in self._digest_set:
            self._digests.append(digest)
            self._digest_set.add(digest)
            while len(self._digests) > self.config.copy_window:
                self._digest_set.discard(self._digests.popleft())


def _refuse(kind: str, message: str) -> StreamVerdict[T]:
    return StreamVerdict("refuse", refused=((kind, message),))
