"""A simulated drive with hostile scans interleaved (issue 46, item 5), shared by
``test_hostile_scans.py`` and ``bench/hostile_scans.py``.

Half of the hostile scans are real scans of the drive with hostile fields (:data:`REAL_KINDS`),
half are junk stamped between two good scans (:data:`JUNK_KINDS`):

- ``angle_fields``: a scan from where the robot is, its fan turned by 0.1-1 rad, its increment
  scaled by 0.8-0.95 or 1.05-1.2, every other beam, or the first 70 % of its beams (each with
  fields consistent with its beam count, so that the scan itself is valid);
- ``copied_ranges``: the ranges of one of the last 30 good scans, exactly;
- ``repeated_stamp``: a scan from a random place of the route, stamped as the last good scan;
- ``backwards_stamp``: a scan from where the robot is, stamped 0.05-3 s or 10-10 000 s before
  the last good scan;
- ``future_stamp``: a scan from where the robot is, stamped 1-30 s or 1 000-1 000 000 s after
  the last good scan;
- ``other_world``: a scan of the rooms or corridors world from a random place of its route;
- ``random_ranges``: every range uniform in [range_min, range_max);
- ``no_return``: every beam +inf (no return);
- ``elsewhere``: a scan of the office from a random place of its route at least 5 m from the
  robot (a place of the same building, not where the robot is).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from multi_robot_mapper.core.pipeline import TimedLaserScan
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import (
    LaserModel,
    SimulatedRobot,
    drive_path,
    plan_paths,
    simulate_robots,
    simulate_scan,
)
from multi_robot_mapper.core.worlds import ROUTES, WORLDS

# The simulator's Hokuyo UTM-30LX geometry (1081 beams over 270 deg, 1 cm noise, 0.5 %
# dropouts), published at 10 Hz; the robot drives the office route at 1.5 m/s: 300 scans are
# one lap (45.7 m), whose loop the back end closes.
LASER = LaserModel(rate=10.0)
SPEED = 1.5  # m/s
REAL_KINDS = ("angle_fields", "copied_ranges", "repeated_stamp", "backwards_stamp", "future_stamp")
JUNK_KINDS = ("other_world", "random_ranges", "no_return", "elsewhere")
FIRST_HOSTILE = 5  # hostile scans come after this many good ones: the stream is established


@dataclasses.dataclass(frozen=True)
class HostileStream:
    """A robot's scans in arrival order and, for each, its hostile kind ("" when good)."""

    scans: list[TimedLaserScan]
    kinds: list[str]

    def good(self) -> list[TimedLaserScan]:
        return [s for s, kind in zip(self.scans, self.kinds, strict=True) if not kind]


def office_drive(scans: int, seed: int) -> SimulatedRobot:
    """``scans`` scans of one robot driving the office route (seeded)."""
    duration = scans / LASER.rate
    return simulate_robots("office", 1, LASER, seed=seed, duration=duration, speed=SPEED)[0]


def _replace(scan: LaserScanData, **fields: object) -> LaserScanData:
    return dataclasses.replace(scan, **fields)  # type: ignore[arg-type]


def with_other_angles(scan: LaserScanData, variant: int, rng: np.random.Generator) -> LaserScanData:
    """``scan`` with angle fields the laser never sends (see the module docstring)."""
    n, step = len(scan.ranges), scan.angle_increment
    if variant % 4 == 0:
        turn = float(rng.choice((-1.0, 1.0)) * rng.uniform(0.1, 1.0))
        return _replace(scan, angle_min=scan.angle_min + turn, angle_max=scan.angle_max + turn)
    if variant % 4 == 1:
        scale = float(rng.uniform(0.8, 0.95) if rng.random() < 0.5 else rng.uniform(1.05, 1.2))
        return _replace(
            scan, angle_increment=step * scale, angle_max=scan.angle_min + step * scale * (n - 1)
        )
    kept = scan.ranges[::2] if variant % 4 == 2 else scan.ranges[: int(0.7 * n)]
    step = 2 * step if variant % 4 == 2 else step
    return _replace(
        scan, ranges=kept, angle_increment=step, angle_max=scan.angle_min + step * (len(kept) - 1)
    )


class _Maker:
    """Makes the hostile scans of one stream (one seeded generator for all of them)."""

    def __init__(self, run: SimulatedRobot, seed: int) -> None:
        self.run = run
        self.rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(46,)))
        self.office = WORLDS["office"]()
        self.office_poses = drive_path(plan_paths(ROUTES["office"], 1, 1e3)[0], 1.0, 2.0, 60.0)
        self.others = [
            (WORLDS[name](), drive_path(plan_paths(ROUTES[name], 1, 1e3)[0], 1.0, 1.0, 80.0))
            for name in ("rooms", "corridors")
        ]

    def scan(self, kind: str, i: int, stamp: float, variant: int) -> TimedLaserScan:
        """A hostile scan of ``kind`` after good scan ``i``, stamped ``stamp`` unless its kind
        is a hostile stamp."""
        rng, run = self.rng, self.run
        last = float(run.stamps[i])
        here = tuple(float(v) for v in run.T_world_laser[i])
        fresh = simulate_scan(self.office, here, LASER, rng)  # where the robot is, now
        if kind == "angle_fields":
            return TimedLaserScan(stamp, with_other_angles(fresh, variant, rng))
        if kind == "copied_ranges":
            source = run.scans[i - int(rng.integers(0, min(30, i) + 1))]
            return TimedLaserScan(stamp, _replace(fresh, ranges=source.ranges.copy()))
        if kind == "repeated_stamp":
            place = self.office_poses[int(rng.integers(len(self.office_poses)))]
            return TimedLaserScan(last, simulate_scan(self.office, tuple(place), LASER, rng))
        if kind == "backwards_stamp":
            back = rng.uniform(0.05, 3.0) if variant % 2 else rng.uniform(10.0, 1e4)
            return TimedLaserScan(last - float(back), fresh)
        if kind == "future_stamp":
            ahead = rng.uniform(1.0, 30.0) if variant % 2 else rng.uniform(1e3, 1e6)
            return TimedLaserScan(last + float(ahead), fresh)
        if kind == "other_world":
            walls, places = self.others[variant % 2]
            place = places[int(rng.integers(len(places)))]
            return TimedLaserScan(stamp, simulate_scan(walls, tuple(place), LASER, rng))
        if kind == "random_ranges":
            ranges = rng.uniform(LASER.range_min, LASER.range_max, LASER.beams)
            return TimedLaserScan(stamp, _replace(fresh, ranges=ranges))
        if kind == "no_return":
            return TimedLaserScan(stamp, _replace(fresh, ranges=np.full(LASER.beams, np.inf)))
        if kind == "elsewhere":
            poses = self.office_poses
            far = poses[np.hypot(poses[:, 0] - here[0], poses[:, 1] - here[1]) >= 5.0]
            place = far[int(rng.integers(len(far)))]
            return TimedLaserScan(stamp, simulate_scan(self.office, tuple(place), LASER, rng))
        raise ValueError(f"unknown hostile kind {kind!r}")


def hostile_stream(run: SimulatedRobot, hostile: int, seed: int) -> HostileStream:
    """``run``'s scans with ``hostile`` hostile scans interleaved at random places after its
    first :data:`FIRST_HOSTILE` scans (and before its last): half of :data:`REAL_KINDS`, half of
    :data:`JUNK_KINDS`, each kind about equally often."""
    maker = _Maker(run, seed)
    kinds = [REAL_KINDS[k % len(REAL_KINDS)] for k in range(hostile // 2)]
    kinds += [JUNK_KINDS[k % len(JUNK_KINDS)] for k in range(hostile - hostile // 2)]
    maker.rng.shuffle(kinds)
    count = len(run.stamps)
    after = np.sort(maker.rng.integers(FIRST_HOSTILE - 1, count - 1, size=len(kinds)))
    period = 1.0 / LASER.rate
    scans: list[TimedLaserScan] = []
    labels: list[str] = []
    made = 0
    for i in range(count):
        scans.append(TimedLaserScan(float(run.stamps[i]), run.scans[i]))
        labels.append("")
        here = int(np.count_nonzero(after == i))
        for n in range(here):
            stamp = float(run.stamps[i]) + period * (n + 1) / (here + 1)  # between good scans
            kind = kinds[made]
            scans.append(maker.scan(kind, i, stamp, made))
            labels.append(kind)
            made += 1
    return HostileStream(scans, labels)
