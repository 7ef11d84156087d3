"""One message per kind of problem per period, so a bad sensor cannot flood the log."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


class ThrottledWarnings:
    """Logs ``message`` for ``kind`` at most once per ``period`` seconds (steady clock).

    rclpy's own ``throttle_duration_sec`` throttles per call site, which would let one kind of
    bad scan hide another; here each kind has its own clock. Suppressed repeats are counted and
    reported with the next message of that kind. ``log`` is any callable taking the message,
    typically a node logger's ``info``, ``warning`` or ``error``: several instances of any
    severities may log through this module (see :func:`_emit`).
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
        _emit(self.log, f"{message}{suffix}")
        self._last[kind] = now
        return True

    def once(self, kind: str, message: str) -> bool:
        """Log the first message of ``kind`` only (later ones are counted); True when logged."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if kind in self._last:
            return False
        _emit(self.log, message)
        self._last[kind] = float("inf")  # never again: warn() of this kind stays quiet too
        return True


def _emit(log: Callable[[str], object], message: str) -> None:
    """Call ``log(message)``; for an rclpy logger method, from one line per severity.

    rclpy remembers the severity of each call site (file, function, line) of a logger and
    raises ``ValueError`` when one site logs at a second severity. Two instances of this class
    that log ``info`` and ``warning`` through the same logger would share a call site here, and
    the second call would raise inside whatever callback it was reporting on.
    """
    logger: Any = getattr(log, "__self__", None)
    name = getattr(log, "__name__", "")
    if logger is None or not hasattr(logger, "get_child"):
        log(message)
    elif name == "debug":
        logger.debug(message)
    elif name == "info":
        logger.info(message)
    elif name in ("warning", "warn"):
        logger.warning(message)
    elif name == "error":
        logger.error(message)
    elif name == "fatal":
        logger.fatal(message)
    else:
        log(message)
