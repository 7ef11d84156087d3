"""Pair test in the manner of Amigoni's Table 2: consecutive scans matched by INTEGRATE alone.

For every consecutive scan pair of the CARMEN logs, INTEGRATE (no initial guess, no
prediction) estimates the relative pose; a pair succeeds within 0.30 m and 5 deg of the
reference (strict: 0.10 m and 2 deg). Prints the success rates and the median time per pair.

    .venv/bin/python bench/pair_test.py [--logs intel aces] [--limit 200]
        [--heuristics consecutive random histogram all endpoints] [--no-views]

Target (issue 4): >= 97 % on every log with one parameter set, median < 20 ms per pair.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.config import config_from_flat, parse_override  # noqa: E402
from multi_robot_mapper.core.extraction import ExtractionConfig, extract_scan  # noqa: E402
from multi_robot_mapper.core.matching import HEURISTICS, IntegrateConfig, integrate  # noqa: E402
from multi_robot_mapper.io.carmen import carmen_scan_data, read_carmen  # noqa: E402

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "carmen"


def run_log(
    name: str, limit: int, heuristics: tuple[str, ...], views: bool, config: IntegrateConfig
) -> None:
    path = DATA / f"{name}.log.gz"
    if not path.is_file():
        print(f"{name}: skipped, {path} not found")
        return
    scans = list(read_carmen(path))
    data = [carmen_scan_data(s) for s in scans]
    segments = [extract_scan(d, ExtractionConfig())[0].segments for d in data]
    pairs = np.arange(len(scans) - 1)
    if limit and limit < len(pairs):
        pairs = pairs[np.linspace(0, len(pairs) - 1, limit).astype(int)]
    ok = strict = valid = valid_and_ok = 0
    times = []
    for k in pairs:
        T_world_1 = se2.matrix_from_pose(*scans[k].reference_pose)
        T_world_2 = se2.matrix_from_pose(*scans[k + 1].reference_pose)
        T_1_2 = se2.invert(T_world_1) @ T_world_2
        start = time.perf_counter()
        result = integrate(
            segments[k],
            segments[k + 1],
            config,
            heuristics=heuristics,
            views=(data[k], data[k + 1]) if views else (None, None),
        )
        times.append(time.perf_counter() - start)
        dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
        error, turn = np.hypot(dx, dy), abs(dtheta)
        correct = bool(error < 0.30 and turn < np.radians(5))
        ok += correct
        strict += bool(error < 0.10 and turn < np.radians(2))
        valid += result.valid
        valid_and_ok += result.valid and correct
    n = len(pairs)
    # How far the validity flag can be trusted: correct among valid, valid among correct.
    precision = valid_and_ok / valid if valid else float("nan")
    recall = valid_and_ok / ok if ok else float("nan")
    print(
        f"{name:6s} pairs {n:4d}  success {ok / n:.3f}  strict {strict / n:.3f}  "
        f"valid {valid / n:.3f} (correct among valid {precision:.3f}, "
        f"valid among correct {recall:.3f})  median {np.median(times) * 1e3:.1f} ms  "
        f"p90 {np.percentile(times, 90) * 1e3:.1f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=["intel", "aces", "fhw", "csail"])
    parser.add_argument("--limit", type=int, default=0, help="at most this many pairs per log")
    parser.add_argument("--heuristics", nargs="+", default=list(HEURISTICS), choices=HEURISTICS)
    parser.add_argument("--no-views", action="store_true", help="no free-space check")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override an IntegrateConfig field, e.g. --set refine_candidates=8",
    )
    args = parser.parse_args()
    config = config_from_flat(IntegrateConfig, dict(parse_override(o) for o in args.overrides))
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    print(
        f"INTEGRATE pair test: heuristics {' '.join(args.heuristics)}, "
        f"views {not args.no_views}, overrides {args.overrides or 'none'}"
    )
    for name in args.logs:
        run_log(name, args.limit, tuple(args.heuristics), not args.no_views, config)


if __name__ == "__main__":
    main()
