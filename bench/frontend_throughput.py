"""Front-end throughput (scan -> validated points -> segments) on one core, in scans/s.

Targets (issue 2): >= 2000 scans/s at 180 beams, >= 500 scans/s at 1081 beams.
180-beam scans are the real intel log when ../shared/data is present (else simulated SICK
scans); 1081-beam scans are simulated Hokuyo UTM-30LX scans of the built-in office world.

    .venv/bin/python -m bench.frontend_throughput [--repeat 5]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import carmen_log, simulated_scans  # noqa: E402
from multi_robot_mapper.core.extraction import extract_scan  # noqa: E402
from multi_robot_mapper.core.extraction_config import ExtractionConfig  # noqa: E402
from multi_robot_mapper.core.scan import LaserScanData  # noqa: E402
from multi_robot_mapper.core.simulation import LaserModel  # noqa: E402
from multi_robot_mapper.io.carmen import carmen_scan_data, read_carmen  # noqa: E402

INTEL = carmen_log("intel")


def throughput(scans: list[LaserScanData], repeat: int) -> tuple[float, float]:
    """Best and median scans/s over ``repeat`` passes."""
    config = ExtractionConfig()
    rates = []
    for _ in range(repeat):
        start = time.perf_counter()
        for scan in scans:
            extract_scan(scan, config)
        rates.append(len(scans) / (time.perf_counter() - start))
    return max(rates), statistics.median(rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    if INTEL.is_file():
        scans180 = [carmen_scan_data(s) for s in read_carmen(INTEL)]
        source180 = f"real: intel.log.gz, {len(scans180)} scans"
    else:
        sick = LaserModel(beams=180, field_of_view=np.radians(179.0), range_max=80.0, rate=5.0)
        scans180 = simulated_scans(sick, 900)
        source180 = "simulated SICK (../shared/data absent)"
    scans1081 = simulated_scans(LaserModel(), 500)
    print("front-end throughput, one core (scans/s; best / median of passes)")
    for beams, scans, source, target in (
        (180, scans180, source180, 2000),
        (1081, scans1081, "simulated Hokuyo UTM-30LX, office world, 500 scans", 500),
    ):
        best, median = throughput(scans, args.repeat)
        verdict = "meets" if median >= target else "MISSES"
        print(
            f"  {beams:5d} beams: {best:7.0f} best, {median:7.0f} median  "
            f"(target >= {target}: {verdict})  [{source}]"
        )


if __name__ == "__main__":
    main()
