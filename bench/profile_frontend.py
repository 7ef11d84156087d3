"""Where the front end spends its time, on one core: microseconds per scan for each stage.

    .venv/bin/python -m bench.profile_frontend [--beams 180|1081] [--repeat 5] [--cprofile]

Each stage of ``extract_segments`` is timed on its own inputs, in the order the front end
calls them (best of ``--repeat`` passes over all scans). Scans are those of
``bench/frontend_throughput.py``: the real intel log at 180 beams (simulated SICK scans when
../shared/data is absent), simulated Hokuyo UTM-30LX scans at 1081 beams. ``--cprofile`` adds
the cProfile top 25 of the whole front end (numpy ufunc calls do not show there: they are
counted in the Python function that makes them).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import cProfile  # noqa: E402
import pstats  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import carmen_log, simulated_scans  # noqa: E402
from multi_robot_mapper.core import extraction as ex  # noqa: E402
from multi_robot_mapper.core.scan import LaserScanData, scan_points  # noqa: E402
from multi_robot_mapper.core.simulation import LaserModel  # noqa: E402
from multi_robot_mapper.io.carmen import carmen_scan_data, read_carmen  # noqa: E402


def load(beams: int) -> list[LaserScanData]:
    if beams == 180 and carmen_log("intel").is_file():
        return [carmen_scan_data(s) for s in read_carmen(carmen_log("intel"))]
    if beams == 180:
        sick = LaserModel(beams=180, field_of_view=np.radians(179.0), range_max=80.0, rate=5.0)
        return simulated_scans(sick, 900)
    return simulated_scans(LaserModel(), 500)


class StageTimer:
    """Accumulates the time of each named call."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)

    def __call__(self, name: str, fn: Callable[..., Any], *args: Any) -> Any:
        start = time.perf_counter()
        result = fn(*args)
        self.seconds[name] += time.perf_counter() - start
        return result


def centred_moments(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The centring and cumulative moments of ``extract_segments``."""
    origin = np.add.reduce(points, axis=0) / len(points)
    x = points[:, 0] - origin[0]
    y = points[:, 1] - origin[1]
    return x, y, ex._cumulative_moments(x, y)


def one_pass(scans: list[LaserScanData], config: ex.ExtractionConfig) -> dict[str, float]:
    """Seconds spent in each stage over all scans (the split simplifier)."""
    timed = StageTimer()
    tol = config.split_tolerance
    for scan in scans:
        points = timed("scan_points", scan_points, scan, config.max_beams).points
        if len(points) == 0:
            continue
        first, last = timed("cluster_bounds", ex.cluster_bounds, points, config.cluster_distance)
        big = (last - first + 1) >= config.min_cluster_points
        if not big.any():
            continue
        first, last = first[big], last[big]
        x, y, moments = timed("moments", centred_moments, points)
        vertex = timed("split_vertices", ex.split_vertices, x, y, moments, first, last, tol)
        seg_first, seg_last = timed("pieces", ex._pieces, vertex, first, last)
        seg_first, seg_last = timed(
            "merge_collinear", ex.merge_collinear, x, y, moments, seg_first, seg_last, tol
        )
        seg_first, seg_last = timed(
            "drop_corner_slivers", ex.drop_corner_slivers, seg_first, seg_last
        )
        timed("refit_segments", ex.refit_segments, x, y, moments, first, seg_first, seg_last, tol)
    return timed.seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--beams", type=int, default=180, choices=(180, 1081))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--cprofile", action="store_true", help="also print the cProfile top 25")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    scans = load(args.beams)
    config = ex.ExtractionConfig()
    best: dict[str, float] = {}
    for _ in range(args.repeat):
        for name, seconds in one_pass(scans, config).items():
            best[name] = min(best.get(name, np.inf), seconds * 1e6 / len(scans))
    print(f"{args.beams} beams, {len(scans)} scans: microseconds per scan (best of {args.repeat})")
    for name, micros in best.items():
        print(f"  {name:22s} {micros:7.1f}")
    print(f"  {'sum':22s} {sum(best.values()):7.1f}")
    if args.cprofile:
        profiler = cProfile.Profile()
        profiler.enable()
        for scan in scans:
            ex.extract_scan(scan, config)
        profiler.disable()
        pstats.Stats(profiler).sort_stats("tottime").print_stats(25)


if __name__ == "__main__":
    main()
