"""What every command shares (cli/common.py): help without reStructuredText that says each
default, one wording for a missing input, and every number checked against its range before
any work, in one line."""

from __future__ import annotations

import argparse

import pytest

from multi_robot_mapper.cli.common import (
    CLI_LIMITS,
    CliError,
    HelpFormatter,
    check_limits,
    missing_input,
    plain_text,
)


def test_plain_text_drops_literals_and_roles() -> None:
    text = "Reads ``/scan`` with :func:`~multi_robot_mapper.io.bags.read_recordings` (``--x``)."
    assert plain_text(text) == "Reads /scan with multi_robot_mapper.io.bags.read_recordings (--x)."
    assert plain_text("a ``two\nline`` literal, :class:`Pose`") == "a two\nline literal, Pose"


def test_help_says_each_default_once_and_nothing_for_flags_or_required() -> None:
    parser = argparse.ArgumentParser(prog="mrm x", formatter_class=HelpFormatter)
    parser.add_argument("--rate", type=float, default=40.0, help="scans per second")
    parser.add_argument("--seed", type=int, default=0, help="the seed (default 0)")
    parser.add_argument("--out", required=True, help="the folder")
    parser.add_argument("--quiet", action="store_true", help="print nothing")
    parser.add_argument("--topic", help="the ``/scan`` topic")
    text = " ".join(parser.format_help().split())
    assert "scans per second (default: 40.0)" in text
    assert "the seed (default 0)" in text and "(default: 0)" not in text
    assert "the folder" in text and "the folder (default" not in text
    assert "print nothing" in text and "print nothing (default" not in text
    assert "the /scan topic" in text and "None" not in text


def test_a_number_outside_its_range_is_one_line_naming_the_option_and_the_range() -> None:
    with pytest.raises(CliError) as refused:
        check_limits(argparse.Namespace(rate=0.0, robots=3), "robots", "rate")
    assert str(refused.value) == "--rate must be in [0.1, 1000] Hz, got 0"
    with pytest.raises(CliError, match=r"^--record-period must be in \[0\.1, 3600\] s, got inf$"):
        check_limits(argparse.Namespace(record_period=float("inf")), "record_period")
    with pytest.raises(CliError, match=r"^--seed must be in \[0, 4\.29497e\+09\], got -1$"):
        check_limits(argparse.Namespace(seed=-1), "seed")  # no unit to say
    # The ends of a range and an option left unset pass.
    low, high, _ = CLI_LIMITS["robots"]
    check_limits(argparse.Namespace(robots=low, speed=None), "robots", "speed")
    check_limits(argparse.Namespace(robots=high, noise=0.0), "robots", "noise")


def test_a_missing_input_is_no_such_kind_then_the_path() -> None:
    error = missing_input("/data/intel.bag", "bag")
    assert isinstance(error, CliError) and str(error) == "no such bag: /data/intel.bag"
