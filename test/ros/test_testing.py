"""Running nodes in-process without launch files (ros/testing.py): the DDS domain a test takes,
a context of its own shut down on exit, and spinning bounded by a condition and a timeout."""

from __future__ import annotations

import os

import pytest

from multi_robot_mapper.ros.testing import default_domain_id, isolated_context, spin_until


def test_the_domain_is_the_environments_or_one_of_the_processs_own(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    assert default_domain_id() == 7
    for unusable in ("", "seven", "-3"):
        monkeypatch.setenv("ROS_DOMAIN_ID", unusable)
        assert default_domain_id() == 1 + os.getpid() % 100
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert 1 <= default_domain_id() <= 100


class Executor:
    """Counts its spins and the longest it was asked to wait."""

    def __init__(self) -> None:
        self.spins = 0
        self.longest = 0.0

    def spin_once(self, timeout_sec: float) -> None:
        self.spins += 1
        self.longest = max(self.longest, timeout_sec)


def test_spinning_stops_when_the_condition_holds_or_the_time_is_up() -> None:
    executor = Executor()
    assert spin_until(executor, lambda: executor.spins == 3, timeout=10.0)  # type: ignore[arg-type]
    assert executor.spins == 3  # the condition is checked before each spin
    assert spin_until(executor, lambda: True, timeout=0.0)  # type: ignore[arg-type]
    assert executor.spins == 3
    never = Executor()
    assert not spin_until(never, lambda: False, timeout=0.05, step=0.01)  # type: ignore[arg-type]
    assert never.spins >= 1 and never.longest <= 0.01


def test_an_isolated_context_is_initialised_inside_and_shut_down_after() -> None:
    with isolated_context() as context:
        assert context.ok()
        assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"]
    assert not context.ok()
