"""When ``mrm replay --record`` takes a snapshot (core/snapshots.py): every period of bag time
while something new was mapped, of what was mapped before the scan that made it due, never
over a stretch with nothing new, and on schedule again after a gap."""

from __future__ import annotations

from collections.abc import Mapping

import pytest

from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.snapshots import Timeline


class Taken(Timeline):
    """The schedule alone: each snapshot's stamp, no merge."""

    stamps: list[float]

    def take(self, mappers: Mapping[str, LocalMapper], stamp: float) -> None:
        self.stamps.append(stamp)
        self.newest = None
        self.taken += 1


def played(stamps: list[float], period: float = 1.0) -> list[float]:
    timeline = Taken(sink=lambda _: None, period=period, method="pivot", config=MergeConfig())
    timeline.stamps = []
    for stamp in stamps:
        timeline.before(stamp, {})
        timeline.mapped(stamp)
    assert timeline.taken == len(timeline.stamps)
    return timeline.stamps


def test_a_snapshot_every_period_of_what_was_mapped_before_it_was_due() -> None:
    # 10 Hz from 100.0 s: the first due at 101.0, taken when the scan at 101.0 arrives, of
    # the newest mapped before it (100.9), then every second.
    stamps = [100.0 + 0.1 * k for k in range(36)]
    assert played(stamps) == pytest.approx([100.9, 101.9, 102.9])


def test_no_snapshot_over_a_gap_and_the_schedule_resumes_after_it() -> None:
    # Scans at 0-0.5 s, nothing until 7.2 s: one snapshot of the first stretch when 7.2
    # arrives, none for the empty seconds between; the next due at 8.0.
    stamps = [0.0, 0.25, 0.5, 7.2, 7.6, 8.1, 8.4, 9.0]
    assert played(stamps) == [0.5, 7.6, 8.4]
    # A NaN stamp is never due and leaves the newest stamp as it was.
    assert played([0.0, 0.5, float("nan"), 0.8, 1.2]) == [0.8]
