"""Simulator speed in generated buildings: scans/s with ray casting culled to the walls in
range (what ``mrm simulate --world generated`` does) against casting every scan at every
segment, on one core, beside today's built-in office world.

Each case drives one robot along a planned route (0.8 m/s) for ``--scans`` scans. Columns:
"scans": noisy scans/s as the simulator makes them (culled exact ranges, glass, people,
noise and dropouts); "exact": the culled exact ranges alone, at every ``scans // 100``-th
pose; "all": the same poses cast against every wall, furniture leg, person and pane at once
(no culling). Also the time to generate each building and to plan 3 robots' routes, and
the cost of a sparse drive (a scan kept every 0.5 m or 15 deg).

    .venv/bin/python -m bench.sim_speed [--scans 400] [--repeat 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from functools import partial  # noqa: E402

import numpy as np  # noqa: E402

from multi_robot_mapper.core.building_runs import (  # noqa: E402
    BuildingScanner,
    SparseSpacing,
    drive_routes,
    plan_routes,
    scan_drives,
)
from multi_robot_mapper.core.buildings import Building, generate_building  # noqa: E402
from multi_robot_mapper.core.simulation import (  # noqa: E402
    LASERS,
    LaserModel,
    people_at,
    raycast_fan,
    simulate_robots,
)

# (label, generate_building arguments)
CASES: list[tuple[str, dict[str, object]]] = [
    ("room_row 25 m", {"seed": 1, "kind": "room_row", "size": 25.0}),
    ("mixed 25 m, glass", {"seed": 2, "kind": "mixed", "size": 25.0, "glass": True}),
    ("room_row 200 m, glass", {"seed": 1, "kind": "room_row", "size": 200.0, "glass": True}),
    (
        "mirror_wings 200 m, glass",
        {"seed": 3, "kind": "mirror_wings", "size": 200.0, "glass": True},
    ),
    ("pillar_hall 200 m", {"seed": 5, "kind": "pillar_hall", "size": 200.0}),
    (
        "pillar_hall 200 m, furniture 0.02/m^2, 20 people",
        {"seed": 5, "kind": "pillar_hall", "size": 200.0, "clutter": 0.02, "people": 20},
    ),
    (
        "mixed 200 m, glass, furniture 0.05/m^2, 20 people",
        {"seed": 4, "kind": "mixed", "size": 200.0, "glass": True, "clutter": 0.05, "people": 20},
    ),
]


def median_time(work: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def exact_rates(
    building: Building, poses: np.ndarray, laser: LaserModel, repeat: int
) -> tuple[float, float]:
    """Scans/s of exact ranges (no noise) at ``poses``: culled (BuildingScanner), and cast
    against every wall, furniture leg, person and pane at once."""
    fan = (laser.angle_min, laser.angle_increment, laser.beams, laser.range_max)
    scanner = BuildingScanner.of(building, laser)
    stamps = np.arange(len(poses)) / laser.rate

    def culled() -> None:
        for pose, seconds in zip(poses.tolist(), stamps.tolist(), strict=True):
            scanner.ranges(tuple(pose), seconds)

    def everything() -> None:
        for pose, seconds in zip(poses.tolist(), stamps.tolist(), strict=True):
            people = people_at(building.clutter.walkers, seconds)
            solid = np.vstack([building.walls, building.clutter.static, *people])
            ranges = raycast_fan(solid, tuple(pose), *fan)
            if len(building.glass):
                glass = raycast_fan(building.glass, tuple(pose), *fan)
                ranges = np.where(ranges <= glass, ranges, np.inf)

    return len(poses) / median_time(culled, repeat), len(poses) / median_time(everything, 1)


def sparse_run(
    building: Building, paths: list[np.ndarray], laser: LaserModel, duration: float
) -> int:
    """Drive the paths keeping a pose every 0.5 m or 15 deg, scan those: how many kept."""
    drives = drive_routes(paths, 0.8, laser.rate, duration, SparseSpacing())
    return sum(len(run.scans) for run in scan_drives(building, drives, laser))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=400, help="scans per case (default 400)")
    parser.add_argument("--repeat", type=int, default=3, help="timed passes (default 3)")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    print("simulator speed, one core (scans/s, median of passes)")
    for name, laser in LASERS.items():
        duration = args.scans / laser.rate
        built_in = median_time(
            lambda laser=laser, d=duration: simulate_robots("office", 1, laser, duration=d),
            args.repeat,
        )
        print(
            f"\n{name}: {laser.beams} beams, {laser.range_max:g} m, {laser.rate:g} Hz; "
            f"built-in office world (today, 62 walls): {args.scans / built_in:.0f} scans/s"
        )
        print(
            f"  {'building':50s} {'segments':>8s} {'scans':>6s} {'exact':>6s} {'all':>6s}"
            f" {'generate':>8s} {'routes':>7s}"
        )
        for label, kwargs in CASES:
            generate_s = median_time(lambda kw=kwargs: generate_building(**kw), args.repeat)
            building = generate_building(**kwargs)  # type: ignore[arg-type]
            length = 0.8 * duration
            route_s = median_time(
                lambda b=building, n=length: plan_routes(b, 3, n, 0.25, seed=0), args.repeat
            )
            drives = drive_routes(plan_routes(building, 1, length, 0.0), 0.8, laser.rate, duration)
            full = median_time(partial(scan_drives, building, drives, laser), args.repeat)
            few = drives[0].T_world_laser[:: max(1, args.scans // 100)]
            culled, everything = exact_rates(building, few, laser, args.repeat)
            segments = len(building.walls) + len(building.glass) + len(building.clutter.static)
            print(
                f"  {label:50s} {segments:8d} {len(drives[0].stamps) / full:6.0f} "
                f"{culled:6.0f} {everything:6.0f} {generate_s * 1e3:6.0f}ms {route_s * 1e3:5.0f}ms"
            )
        label, kwargs = CASES[3]
        building = generate_building(**kwargs)  # type: ignore[arg-type]
        long_drive = 600.0  # s
        paths = plan_routes(building, 1, 0.8 * long_drive, 0.0)
        dense = drive_routes(paths, 0.8, laser.rate, long_drive)

        sparse_s = median_time(partial(sparse_run, building, paths, laser, long_drive), args.repeat)
        kept = sparse_run(building, paths, laser, long_drive)
        print(
            f"  sparse drive of {long_drive:g} s in {label}: {kept} of {len(dense[0].stamps)} "
            f"poses kept (a scan every 0.5 m or 15 deg), {sparse_s:.2f} s to drive and scan"
        )


if __name__ == "__main__":
    main()
