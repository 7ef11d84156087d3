"""Ctrl-C is never lost: an interrupt a library swallows while loading, or turns into another
error, still ends the command with one line and exit code 130 (cli/interrupts.py)."""

from __future__ import annotations

import os
import signal
import time

import pytest

from multi_robot_mapper.cli import main as cli_main
from multi_robot_mapper.cli.interrupts import (
    InterruptLatch,
    caused_by_interrupt,
    raise_if_interrupted,
)


def _swallowing_parser_builder(real):
    """A build_parser that meets SIGINT while 'loading' and swallows the KeyboardInterrupt, as
    numpy.random's Cython initialisation did under scipy's ``from numpy import *``."""

    def build():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)  # the handler raises at once; never slept through
        except KeyboardInterrupt:
            pass  # swallowed
        return real()

    return build


def test_an_interrupt_swallowed_while_loading_still_ends_the_command(monkeypatch, capsys) -> None:
    monkeypatch.setattr(cli_main, "build_parser", _swallowing_parser_builder(cli_main.build_parser))
    before = signal.getsignal(signal.SIGINT)
    code = cli_main.main(["simulate", "--robots", "1", "--out", "/nonexistent/never-written"])
    assert code == 130
    err = capsys.readouterr().err
    assert err.strip().splitlines() == ["mrm simulate: interrupted; nothing half-written was left"]
    assert signal.getsignal(signal.SIGINT) is before  # the caller's handler is back


def test_an_error_an_interrupt_caused_is_read_as_the_interrupt(monkeypatch, capsys) -> None:
    def build():  # gtsam's pybind11 initialisation: ImportError from the KeyboardInterrupt
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    monkeypatch.setattr(cli_main, "build_parser", build)
    assert cli_main.main(["replay", "bag"]) == 130
    assert "Traceback" not in capsys.readouterr().err


def test_an_error_not_caused_by_an_interrupt_is_still_raised(monkeypatch) -> None:
    def build():
        raise ImportError("no module named nothing")

    monkeypatch.setattr(cli_main, "build_parser", build)
    with pytest.raises(ImportError, match="nothing"):
        cli_main.main(["replay", "bag"])


def test_the_latch_raises_and_remembers() -> None:
    latch = InterruptLatch()
    previous = signal.signal(signal.SIGINT, latch)
    try:
        raise_if_interrupted()  # nothing received yet
        with pytest.raises(KeyboardInterrupt):
            latch(signal.SIGINT, None)
        assert latch.received
        with pytest.raises(KeyboardInterrupt):
            raise_if_interrupted()
    finally:
        signal.signal(signal.SIGINT, previous)
    raise_if_interrupted()  # another handler in place: nothing to raise


def test_a_chain_is_followed_through_causes_and_contexts() -> None:
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise ValueError("while handling")  # noqa: B904 - the implicit context is the point
    except ValueError as exc:
        assert caused_by_interrupt(exc)
    assert not caused_by_interrupt(RuntimeError("plain"))
