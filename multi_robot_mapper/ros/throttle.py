"""One warning per kind of problem per period, so a bad sensor cannot flood the log."""

from __future__ import annotations

import time
from collections.abc import Callable


class ThrottledWarnings:
    """Logs ``message`` for ``kind`` at most once per ``period`` seconds (steady clock).

    rclpy's own ``throttle_duration_sec`` throttles per call site, which would let one kind of
    bad scan hide another; here each kind has its own clock. Suppressed repeats are counted and
    reported with the next message of that kind.
    """

    def __init__(
        self,
        log: Callable[[str], object],
        period: float,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.log = log
        self.period = period
        self._clock = clock
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self.counts: dict[str, int] = {}

    def warn(self, kind: str, message: str) -> bool:
        """Log unless the same kind was logged less than ``period`` ago; True when logged."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        now = self._clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.period:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return False
        repeats = self._suppressed.pop(kind, 0)
        suffix = f" ({repeats} more since the last such warning)" if repeats else ""
        self.log(f"{message}{suffix}")
        self._last[kind] = now
        return True
