"""The stream guard (core/scan_stream.py, issue 46 item 5) rule by rule: angle fields that differ
from the laser's, stamps that repeat, run backwards or jump ahead, ranges copied from an earlier
scan; each refused scan counted per reason, the stream's state untouched, a laser really
reconfigured or a clock that really jumped followed. The whole path with hostile scans:
test/cross/test_hostile_scans.py."""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.scan_stream import ScanStreamGuard
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.core.worlds import WORLDS
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig

RULES = RobotMapperConfig().stream_config()  # the shipped rules
PERIOD = 0.1  # s: a 10 Hz laser


def laser_scans(count: int, seed: int = 0) -> list[LaserScanData]:
    """``count`` noisy scans of one place (every one's ranges its own)."""
    rng = np.random.default_rng(seed)
    walls = WORLDS["office"]()
    return [simulate_scan(walls, (5.0, 3.6, 0.0), LaserModel(beams=361), rng) for _ in range(count)]


class Stream:
    """A guard and a 10 Hz laser's scans: what each one did."""

    def __init__(self, config: object = RULES) -> None:
        self.guard: ScanStreamGuard[int] = ScanStreamGuard(config)  # type: ignore[arg-type]
        self.scans = laser_scans(60)
        self.used = 0
        self.mapped: list[int] = []  # items mapped, in order
        self.refused: list[str] = []  # reasons, in order
        self.resets = 0

    def send(self, stamp: float, scan: LaserScanData | None = None) -> str:
        """Check the next scan (or ``scan``) stamped ``stamp``; the verdict's action."""
        item = self.used
        self.used += 1
        verdict = self.guard.check(stamp, scan if scan is not None else self.scans[item], item)
        self.refused += [kind for kind, _ in verdict.refused]
        if verdict.maps:
            self.resets += verdict.action == "reset"
            self.mapped += [held.item for held in verdict.release] + [item]
        return verdict.action

    def good(self, first: float, count: int) -> None:
        for k in range(count):
            assert self.send(first + k * PERIOD) == "map"


def test_angle_fields_that_differ_from_the_lasers_are_refused() -> None:
    s = Stream()
    s.good(10.0, 5)
    base = laser_scans(1, seed=9)[0]
    turned = dataclasses.replace(
        base, angle_min=base.angle_min + 0.3, angle_max=base.angle_max + 0.3
    )
    coarser = dataclasses.replace(
        base,
        ranges=base.ranges[::2],
        angle_increment=2 * base.angle_increment,
        angle_max=base.angle_min + 2 * base.angle_increment * 180,
    )
    assert s.send(10.45, turned) == "refuse"
    assert s.send(10.46, coarser) == "refuse"
    assert s.refused == ["angle_fields", "angle_fields"]
    s.good(10.5, 3)  # the laser's own scans go on, mapped
    assert s.mapped == [0, 1, 2, 3, 4, 7, 8, 9]


def test_a_laser_reconfigured_for_good_becomes_the_streams_geometry() -> None:
    # geometry_change_scans in a row of one new geometry: the laser was reconfigured. The
    # earlier ones were refused; from the last on, the new geometry is the stream's.
    s = Stream()
    s.good(10.0, 3)
    new = RULES.geometry_scans
    notices = []
    for k in range(new + 2):
        base = s.scans[s.used]
        fewer = dataclasses.replace(
            base,
            ranges=base.ranges[:300],
            angle_max=base.angle_min + base.angle_increment * 299,
        )
        verdict = s.guard.check(10.3 + k * PERIOD, fewer, s.used)
        notices += [kind for kind, _ in verdict.notices]
        s.refused += [kind for kind, _ in verdict.refused]
        s.mapped += [s.used] if verdict.maps else []
        s.used += 1
    assert s.refused == ["angle_fields"] * (new - 1)
    assert notices == ["laser_geometry"]
    assert s.mapped == [0, 1, 2, 2 + new, 3 + new, 4 + new]
    # The old geometry is now the odd one out.
    assert s.send(10.3 + (new + 2) * PERIOD) == "refuse" and s.refused[-1] == "angle_fields"


def test_a_stamp_that_repeats_is_refused() -> None:
    s = Stream()
    s.good(10.0, 3)
    assert s.send(10.2) == "refuse" and s.refused == ["duplicate_stamp"]
    s.good(10.3, 2)
    assert s.mapped == [0, 1, 2, 4, 5]


def test_stamps_that_run_backwards_are_refused_and_never_start_the_map_over() -> None:
    s = Stream()
    s.good(100.0, 5)
    assert s.send(99.5) == "refuse"  # a step back: stale
    assert s.send(40.0) == "hold"  # far back: a bag played again, or a corrupt stamp?
    assert s.send(100.5) == "map"  # the stream goes on: it was a corrupt stamp
    s.good(100.6, 3)
    assert s.refused == ["stale_stamp", "stamp_jump_back"] and s.resets == 0
    assert s.mapped == [0, 1, 2, 3, 4, 7, 8, 9, 10]


def test_a_clock_that_jumped_back_and_stays_there_starts_the_map_over() -> None:
    # A bag played in a loop: once stamp_confirm_scans scans stay at the new time, the map
    # starts over and they are all mapped, in order.
    s = Stream()
    s.good(100.0, 5)
    actions = [s.send(40.0 + k * PERIOD) for k in range(RULES.confirm_scans)]
    assert actions == ["hold"] * (RULES.confirm_scans - 1) + ["reset"]
    assert s.resets == 1 and s.refused == []
    assert s.mapped == list(range(5 + RULES.confirm_scans))
    s.good(40.0 + RULES.confirm_scans * PERIOD, 2)


def test_a_stamp_far_ahead_is_refused_and_later_scans_are_not_made_stale() -> None:
    s = Stream()
    s.good(100.0, 5)
    assert s.send(100.45 + 3600.0) == "hold"
    s.good(100.5, 5)  # every later good scan is mapped, none stale
    assert s.refused == ["stamp_jump_ahead"]
    assert s.mapped == [0, 1, 2, 3, 4, 6, 7, 8, 9, 10]


def test_a_gap_in_the_stream_loses_no_scan() -> None:
    # The laser stalls for 3 s (30 periods): the scan after the gap is held until the next
    # ones confirm the new time, then all are mapped in order.
    s = Stream()
    s.good(100.0, 5)
    actions = [s.send(103.4 + k * PERIOD) for k in range(RULES.confirm_scans + 1)]
    assert actions == ["hold"] * (RULES.confirm_scans - 1) + ["map", "map"]
    assert s.refused == [] and s.mapped == list(range(5 + RULES.confirm_scans + 1))


def test_scans_a_node_dropped_for_load_keep_the_streams_time() -> None:
    # A node too busy for 40 scans (4 s) drops them before the guard, telling it: the next
    # scan it maps is no jump ahead.
    s = Stream()
    s.good(100.0, 5)
    for k in range(40):
        s.guard.skipped(100.5 + k * PERIOD)
    assert s.send(104.5) == "map" and s.refused == []


def test_ranges_copied_from_an_earlier_scan_are_refused() -> None:
    s = Stream()
    s.good(10.0, 5)
    copy = dataclasses.replace(s.scans[1], ranges=s.scans[1].ranges.copy())
    assert s.send(10.45, copy) == "refuse" and s.refused == ["copied_ranges"]
    s.good(10.5, 2)
    assert s.mapped == [0, 1, 2, 3, 4, 6, 7]
    # Open space, every beam without a return, looks the same scan after scan: no copy.
    empty = dataclasses.replace(s.scans[0], ranges=np.full(361, np.inf))
    assert s.send(10.7, empty) == "map" and s.send(10.8, empty) == "map"


@settings(max_examples=60, deadline=None)
@given(
    periods=st.lists(st.floats(0.031, 0.3), min_size=8, max_size=40),
    hostile_at=st.integers(3, 7),
    offset=st.one_of(st.floats(-1e6, -6.0), st.floats(-4.9, 0.0), st.floats(5.0, 1e6)),
)
def test_one_hostile_stamp_in_a_jittery_stream_costs_no_good_scan(
    periods: list[float], hostile_at: int, offset: float
) -> None:
    # A stream whose intervals vary up to nearly 10-fold (stamp_gap_periods 10: a step beyond
    # ten median intervals is held until later scans confirm it, and refused if the stream
    # ends first), with one scan stamped anywhere from 1e6 s back to 1e6 s ahead of the scan
    # before it: every good scan is mapped, in order, and the
    # hostile one is refused.
    s = Stream()
    stamps = 100.0 + np.cumsum([0.0, *periods])
    for k, t in enumerate(stamps):
        s.send(float(t))
        if k == hostile_at:
            s.send(float(t) + offset)
    s.refused += [kind for kind, _ in s.guard.finish()]
    good = [k if k <= hostile_at else k + 1 for k in range(len(stamps))]
    assert s.mapped == good
    assert len(s.refused) == 1 and s.resets == 0
