"""Wolter's shape-based matching on the pair test, alone and as a second source for INTEGRATE.

Two kinds of scan pairs per CARMEN log, each judged against the reference relative pose
(success within 0.30 m and 5 deg, strict within 0.10 m and 2 deg):

- **consecutive** pairs, as in ``bench/pair_test.py`` (issue 14: "its own pair test");
- **revisit** pairs: two scans at least ``--gap`` scans apart whose reference poses lie within
  1.5 m and 30 deg of each other, what a loop closure or a link between robots must match.

For each pair it runs (one core, no guess, no prediction):

- ``shape``: :func:`core.matching.shape.match_scans` alone;
- ``integrate``: INTEGRATE alone (every heuristic, views), as the pair test runs it;
- ``integrate+shape``: INTEGRATE with every aligned candidate of the shape matching as more
  hypotheses (the way a second pre-alignment source enters the project's matcher: its own
  scoring chooses), and the share of pairs right and at the local mapper's
  ``integrate_confidence``.

    .venv/bin/python -m bench.shape_pair_test [--logs intel aces fhw csail] [--limit 200]
        [--gap 50] [--set NAME=VALUE ...] [--json out.json]

``--set`` overrides a ShapeConfig field. Prints one markdown table.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import ExtractedLog, extracted_log, pair_indices  # noqa: E402
from multi_robot_mapper.cli.common import add_set_option  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.config import config_from_flat, parse_override  # noqa: E402
from multi_robot_mapper.core.local_mapping import LocalMapperConfig  # noqa: E402
from multi_robot_mapper.core.matching import HEURISTICS, IntegrateConfig, integrate  # noqa: E402
from multi_robot_mapper.core.matching.shape import match_shapes, shape_of_scan  # noqa: E402
from multi_robot_mapper.core.matching.shape_config import ShapeConfig  # noqa: E402

# The local mapper's threshold for integrating a scan.
INTEGRATE_CONFIDENCE = LocalMapperConfig().integrate_confidence

LOGS = ("intel", "aces", "fhw", "csail", "freiburg-079", "edmonton")


def revisit_pairs(log: ExtractedLog, gap: int, limit: int, seed: int = 0) -> np.ndarray:
    """(first, second) pairs of scans at least ``gap`` apart whose reference poses are within
    1.5 m and 30 deg: ``limit`` of them drawn at random (all when fewer)."""
    poses = np.asarray(log.poses, dtype=np.float64)
    dx = poses[:, None, 0] - poses[None, :, 0]
    dy = poses[:, None, 1] - poses[None, :, 1]
    turn = np.abs(se2.wrap_angle(poses[:, None, 2] - poses[None, :, 2]))
    index = np.arange(len(poses))
    near = (np.hypot(dx, dy) < 1.5) & (turn < np.radians(30.0))
    near &= index[None, :] - index[:, None] >= gap
    pairs = np.argwhere(near)
    if limit and len(pairs) > limit:
        pairs = pairs[np.sort(np.random.default_rng(seed).choice(len(pairs), limit, replace=False))]
    return pairs


def judge(log: ExtractedLog, first: int, second: int, T_1_2: np.ndarray) -> tuple[bool, bool]:
    truth = se2.invert(se2.matrix_from_pose(*log.poses[first])) @ se2.matrix_from_pose(
        *log.poses[second]
    )
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(truth) @ T_1_2)
    error, turn = float(np.hypot(dx, dy)), abs(dtheta)
    return error < 0.30 and turn < np.radians(5), error < 0.10 and turn < np.radians(2)


def run(log: ExtractedLog, pairs: np.ndarray, shape_config: ShapeConfig) -> dict[str, float]:
    config = IntegrateConfig()
    shapes = {}
    counts = dict.fromkeys(
        ("shape", "shape_strict", "integrate", "integrate+shape", "confident", "confident+shape"), 0
    )
    times: dict[str, list[float]] = {"shape": [], "shape_extract": [], "integrate": []}
    stages: dict[str, list[float]] = {}
    for k, j in pairs:
        k, j = int(k), int(j)
        started = time.perf_counter()
        for index in (k, j):
            if index not in shapes:
                shapes[index] = shape_of_scan(log.views[index], shape_config)
        times["shape_extract"].append(time.perf_counter() - started)
        started = time.perf_counter()
        found = match_shapes(shapes[k], shapes[j], shape_config)
        times["shape"].append(time.perf_counter() - started)
        for stage, seconds in found.seconds.items():
            stages.setdefault(stage, []).append(seconds)
        right, strict = judge(log, k, j, found.matrix)
        counts["shape"] += right
        counts["shape_strict"] += strict
        views = (log.views[k], log.views[j])
        started = time.perf_counter()
        alone = integrate(log.segments[k], log.segments[j], config, HEURISTICS, views=views)
        times["integrate"].append(time.perf_counter() - started)
        # every aligned candidate as an INTEGRATE hypothesis (theta, tx, ty): INTEGRATE's
        # own scoring chooses among them and its other hypotheses
        hypotheses = np.array([[t, x, y] for x, y, t in found.alternatives]).reshape(-1, 3)
        helped = integrate(
            log.segments[k],
            log.segments[j],
            config,
            HEURISTICS,
            extra_hypotheses=hypotheses if len(hypotheses) else None,
            views=views,
        )
        for name, result in (("", alone), ("+shape", helped)):
            right, _ = judge(log, k, j, result.matrix)
            counts["integrate" + name] += right
            counts["confident" + name] += right and result.confidence >= INTEGRATE_CONFIDENCE
    n = max(len(pairs), 1)
    row: dict[str, float] = {"pairs": float(len(pairs))}
    row.update({name: value / n for name, value in counts.items()})
    row.update({f"{name}_median_ms": float(np.median(t)) * 1e3 for name, t in times.items() if t})
    row["shape_p90_ms"] = float(np.percentile(times["shape"], 90)) * 1e3 if times["shape"] else 0
    row.update({f"stage_{s}_median_ms": float(np.median(t)) * 1e3 for s, t in stages.items()})
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=list(LOGS))
    parser.add_argument("--limit", type=int, default=200, help="pairs per log and kind (0: all)")
    parser.add_argument("--gap", type=int, default=50, help="scans between a revisit pair's two")
    parser.add_argument("--json", metavar="PATH", help="write the rows as JSON")
    add_set_option(parser, "override a ShapeConfig field, e.g. --set dce_threshold=0.03")
    args = parser.parse_args()
    shape_config = config_from_flat(ShapeConfig, dict(parse_override(o) for o in args.overrides))
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    rows = []
    print(
        "| log | pairs | kind | shape: success / strict | shape median / p90 ms | INTEGRATE "
        "success | INTEGRATE + shape success | confident (>= integrate_confidence) and right: "
        "INTEGRATE / + shape | INTEGRATE median ms |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in args.logs:
        log = extracted_log(name)
        if log is None:
            continue
        consecutive = pair_indices(log, args.limit)
        kinds = {
            "consecutive": np.column_stack((consecutive, consecutive + 1)),
            "revisit": revisit_pairs(log, args.gap, args.limit),
        }
        for kind, pairs in kinds.items():
            row = run(log, pairs, shape_config)
            row_out = {"log": name, "kind": kind, **row}
            rows.append(row_out)
            print(
                f"| {name} | {int(row['pairs'])} | {kind} | {row['shape']:.3f} / "
                f"{row['shape_strict']:.3f} | {row.get('shape_median_ms', 0):.1f} / "
                f"{row['shape_p90_ms']:.1f} | {row['integrate']:.3f} | "
                f"{row['integrate+shape']:.3f} | {row['confident']:.3f} / "
                f"{row['confident+shape']:.3f} | {row.get('integrate_median_ms', 0):.1f} |",
                flush=True,
            )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
