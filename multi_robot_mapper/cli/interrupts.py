"""Ctrl-C that is never lost: a SIGINT handler that remembers the interrupt it raised.

Python's own handler raises :class:`KeyboardInterrupt` wherever the main thread is. While a
command's libraries load, that can be inside a C extension's module initialisation, and some
of them do not let it through: measured here, an interrupt inside numpy.random's Cython
initialisation (reached through scipy's ``from numpy import *``) vanished and the replay ran
to its end with exit code 0; one inside gtsam's pybind11 initialisation came out as
``ImportError: initialization failed`` (its cause the KeyboardInterrupt) with a traceback. The
latch raises as Python's handler does and also remembers, so the command line can raise the
interrupt again once the libraries are loaded, and read an error an interrupt caused as the
interrupt. Only the standard library is imported here (see cli/main.py).
"""

from __future__ import annotations

import signal
from types import FrameType


class InterruptLatch:
    """A SIGINT handler: raises KeyboardInterrupt and remembers that it did."""

    def __init__(self) -> None:
        self.received = False

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        self.received = True
        raise KeyboardInterrupt


def interrupt_received() -> bool:
    """Whether the SIGINT handler in place is a latch that has raised (the interrupt may have
    been swallowed on its way up)."""
    handler = signal.getsignal(signal.SIGINT)
    return isinstance(handler, InterruptLatch) and handler.received


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt again if the latch in place received one: called where a
    swallowed interrupt would otherwise be lost (after the libraries load, at each progress
    report)."""
    if interrupt_received():
        raise KeyboardInterrupt


def caused_by_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` came from a KeyboardInterrupt (its chain of causes and contexts holds
    one), as gtsam's ``ImportError: initialization failed`` does."""
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        if isinstance(link, KeyboardInterrupt):
            return True
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return False
