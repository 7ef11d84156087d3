"""Throttled warnings: one per kind per period, repeats counted."""

from __future__ import annotations

from multi_robot_mapper.ros.throttle import ThrottledWarnings


def test_each_kind_has_its_own_period_and_repeats_are_reported() -> None:
    now = [0.0]
    logged: list[str] = []
    warnings = ThrottledWarnings(logged.append, period=10.0, clock=lambda: now[0])
    assert warnings.warn("nan", "a")
    assert not warnings.warn("nan", "b")
    assert warnings.warn("inf", "c")
    now[0] = 10.5
    assert warnings.warn("nan", "d")
    assert logged == ["a", "c", "d (1 more since the last such warning)"]
    assert warnings.counts == {"nan": 3, "inf": 1}
