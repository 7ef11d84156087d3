"""Fit and check the front end's confidence in context (issues 11 and 17).

The match confidence (``bench/fit_confidence.py``) is fitted on a mixture of scan pairs, so
its base rate is the mixture's. The local mapper's front end asks narrower questions, each
with a base rate of its own: the last keyframe from the prediction (``track``), the last scan
with no guess (``search``), an older keyframe of the robot's piece (``recent``), a keyframe of
another piece (``other``). This bench measures what a confidence means in each, on the front
end's own matches, and fits one (slope, intercept) per context on the log-odds (Platt
scaling: :func:`~multi_robot_mapper.core.local_mapping.attempts.in_context`). Two steps:

    .venv/bin/python -m bench.fit_placement collect [--logs intel aces ...] [--robots 2 4]
        [--jobs 2] [--out bench_output/placement]
    .venv/bin/python -m bench.fit_placement fit [--write] [--out bench_output/placement]

``collect`` cuts each shared log into K robots as ``mrm import-carmen --robots K`` does and
maps each robot with the local mapper (back end in line, as a replay). Every match the front
end tries (``LocalMapper.last_attempts``) is judged against the reference: the reference
scan's and the new scan's reference poses against the match (right within 0.30 m / 5 deg).
It stores, per log and K, each attempt's context, its match confidence and whether it is
right in ``OUT/<log>_<K>.npz``. The matches are those the front end made with the
calibration installed when collecting (its decisions choose which references are tried).

``fit`` fits each context (log loss, with a weak pull towards no change so that a context
with few matches stays near the match confidence) on all logs but one and checks it on the
one left out, in turn: log loss before and after, and, at the front end's threshold
(``integrate_confidence``), how many of the matches it would integrate are right. It prints
Markdown tables for the README. ``--write`` writes the fit on every log into
``multi_robot_mapper/core/local_mapping/context_model.json`` (data the package loads, with how
and on what it was fitted).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import datetime  # noqa: E402
import itertools  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import minimize  # noqa: E402

from bench.harness import FIT_LOGS, OUTPUT, REPO, carmen_log, present_logs  # noqa: E402
from multi_robot_mapper.cli.import_carmen import split_runs  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.extraction import extract_scan  # noqa: E402
from multi_robot_mapper.core.extraction_config import ExtractionConfig  # noqa: E402
from multi_robot_mapper.core.local_mapping import LocalMapper, LocalMapperConfig  # noqa: E402
from multi_robot_mapper.core.local_mapping.attempts import (  # noqa: E402
    CONTEXT_MODEL_FILE,
    CONTEXTS,
    ContextCalibration,
    context_model_json,
    pose_of_match,
)
from multi_robot_mapper.core.matching.confidence import is_right  # noqa: E402
from multi_robot_mapper.io.carmen import (  # noqa: E402
    carmen_scan_data,
    monotonic_stamps,
    read_carmen,
)

# The calibration, data the package loads (core/local_mapping/attempts.installed_context_model).
MODEL_FILE = REPO / "multi_robot_mapper" / "core" / "local_mapping" / CONTEXT_MODEL_FILE
# The pull of each context's fit towards (slope 1, intercept 0): as many matches' worth of
# log loss as this, so that a context with a few dozen matches is not fitted to them alone.
PRIOR_WEIGHT = 1.0


def collect_case(name: str, robots: int, out_dir: Path) -> str:
    """Map ``name`` cut into ``robots`` robots; store every front-end attempt, judged."""
    path = carmen_log(name)
    scans = read_carmen(path)
    stamps, _ = monotonic_stamps(np.array([s.timestamp for s in scans]), path.name)
    config = LocalMapperConfig()
    extraction = ExtractionConfig()
    contexts, raw, placed_with, right = [], [], [], []
    started = time.perf_counter()
    for start, stop in split_runs(len(scans), robots, 0):
        mapper = LocalMapper(config)
        truth = {float(stamps[i]): np.asarray(scans[i].reference_pose) for i in range(start, stop)}
        for i in range(start, stop):
            data = carmen_scan_data(scans[i])
            segments, _ = extract_scan(data, extraction)
            mapper.add_scan(float(stamps[i]), segments, data)
            for attempt in mapper.last_attempts:
                reference = truth[attempt.reference_stamp]
                T_truth = se2.invert(se2.matrix_from_pose(*reference)) @ se2.matrix_from_pose(
                    *truth[float(stamps[i])]
                )
                T_match = se2.matrix_from_pose(*pose_of_match(attempt.result.T_1_2))
                contexts.append(CONTEXTS.index(attempt.context))
                raw.append(attempt.result.confidence)
                placed_with.append(attempt.confidence)
                right.append(is_right(T_match, T_truth))
    np.savez(
        out_dir / f"{name}_{robots}.npz",
        context=np.array(contexts, dtype=np.int64),
        confidence=np.array(raw, dtype=np.float64),
        in_context=np.array(placed_with, dtype=np.float64),
        right=np.array(right, dtype=bool),
    )
    return f"{name} {robots} robots: {len(raw)} attempts in {time.perf_counter() - started:.0f} s"


def logit(p: np.ndarray) -> np.ndarray:
    p = np.clip(p, 1e-9, 1.0 - 1e-9)
    return np.log(p / (1.0 - p))


def calibrated(p: np.ndarray, slope: float, intercept: float) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.clip(slope * logit(p) + intercept, -50.0, 50.0)))


def log_loss(p: np.ndarray, right: np.ndarray) -> float:
    p = np.clip(p, 1e-9, 1.0 - 1e-9)
    return float(-np.mean(np.where(right, np.log(p), np.log(1.0 - p)))) if len(p) else 0.0


def fit_context(p: np.ndarray, right: np.ndarray) -> tuple[float, float]:
    """(slope, intercept) minimising the log loss, pulled towards (1, 0) by PRIOR_WEIGHT."""
    if len(p) == 0:
        return 1.0, 0.0
    x, y = logit(p), right.astype(np.float64)

    def cost(params: np.ndarray) -> tuple[float, np.ndarray]:
        slope, intercept = params
        z = np.clip(slope * x + intercept, -50.0, 50.0)
        q = 1.0 / (1.0 + np.exp(-z))
        loss = np.sum(np.logaddexp(0.0, z) - y * z)
        loss += PRIOR_WEIGHT * ((slope - 1.0) ** 2 + intercept**2)
        residual = q - y
        grad = np.array([np.sum(residual * x), np.sum(residual)])
        grad += 2.0 * PRIOR_WEIGHT * np.array([slope - 1.0, intercept])
        return float(loss), grad

    found = minimize(cost, np.array([1.0, 0.0]), jac=True, method="L-BFGS-B")
    return float(found.x[0]), float(found.x[1])


def load(out_dir: Path) -> dict[str, dict[str, np.ndarray]]:
    """Per log: every attempt of all its cuts."""
    by_log: dict[str, list[np.lib.npyio.NpzFile]] = {}
    for path in sorted(out_dir.glob("*.npz")):
        name = path.stem.rsplit("_", 1)[0]
        by_log.setdefault(name, []).append(np.load(path))
    return {
        name: {key: np.concatenate([f[key] for f in files]) for key in files[0].files}
        for name, files in by_log.items()
    }


def fit_all(data: dict[str, dict[str, np.ndarray]]) -> dict[str, tuple[float, float]]:
    fits = {}
    for c, context in enumerate(CONTEXTS):
        p = np.concatenate([d["confidence"][d["context"] == c] for d in data.values()] or [[]])
        right = np.concatenate([d["right"][d["context"] == c] for d in data.values()] or [[]])
        fits[context] = fit_context(p, right.astype(bool))
    return fits


def report(data: dict[str, dict[str, np.ndarray]], threshold: float) -> list[str]:
    """Leave one log out: log loss before / after, and precision at ``threshold``."""
    lines = [
        "| left out | context | matches | right | log loss before / after | "
        f"at >= {threshold}: before (right / taken) | after (right / taken) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    pooled: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
    for name in data:
        others = {k: v for k, v in data.items() if k != name}
        if not others:
            break  # one log: nothing to fit on
        fits = fit_all(others)
        d = data[name]
        for c, context in enumerate(CONTEXTS):
            mask = d["context"] == c
            p, right = d["confidence"][mask], d["right"][mask]
            if not len(p):
                continue
            q = calibrated(p, *fits[context])
            pooled.setdefault(context, []).append((p, q, right))
            lines.append(_row(name, context, p, q, right, threshold))
    for context in CONTEXTS:
        if context in pooled:
            p, q, right = (np.concatenate(parts) for parts in zip(*pooled[context], strict=True))
            lines.append(_row("**all**", context, p, q, right, threshold))
    return lines


def _row(name: str, context: str, p: np.ndarray, q: np.ndarray, right: np.ndarray, t: float) -> str:
    before, after = p >= t, q >= t
    return (
        f"| {name} | {context} | {len(p)} | {int(right.sum())} | {log_loss(p, right):.3f} / "
        f"{log_loss(q, right):.3f} | {int(right[before].sum())} / {int(before.sum())} | "
        f"{int(right[after].sum())} / {int(after.sum())} |"
    )


def reliability(data: dict[str, dict[str, np.ndarray]]) -> list[str]:
    """Observed right share in bins of the match confidence, per context (all logs)."""
    edges = np.linspace(0.0, 1.0, 11)
    bins = list(itertools.pairwise(edges))
    lines = ["| context | " + " | ".join(f"{a:.1f}-{b:.1f}" for a, b in bins) + " |"]
    lines.append("| --- |" + " --- |" * 10)
    for c, context in enumerate(CONTEXTS):
        p = np.concatenate([d["confidence"][d["context"] == c] for d in data.values()])
        right = np.concatenate([d["right"][d["context"] == c] for d in data.values()])
        cells = []
        for a, b in bins:
            mask = (p >= a) & ((p < b) if b < 1.0 else (p <= b))
            cells.append(f"{right[mask].mean():.2f} ({mask.sum()})" if mask.any() else "-")
        lines.append(f"| {context} | " + " | ".join(cells) + " |")
    return lines


def write_model(
    fits: dict[str, tuple[float, float]], data: dict[str, dict[str, np.ndarray]]
) -> None:
    """``MODEL_FILE``: each context's fit, to 6 significant digits, with its provenance."""
    count = sum(len(d["confidence"]) for d in data.values())
    model = {
        c: ContextCalibration(float(f"{s:.6g}"), float(f"{b:.6g}")) for c, (s, b) in fits.items()
    }
    fitted = (
        f"bench/fit_placement.py on {datetime.date.today().isoformat()}: {count} front-end "
        f"matches of {', '.join(data)} (each log cut into 2 and 4 robots); checked leaving "
        "each log out in turn (README, 'Confidence in context')"
    )
    command = (
        ".venv/bin/python -m bench.fit_placement collect && "
        ".venv/bin/python -m bench.fit_placement fit --write"
    )
    MODEL_FILE.write_text(context_model_json(model, fitted, command))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    collect = sub.add_parser("collect")
    collect.add_argument("--logs", nargs="+", default=list(FIT_LOGS))
    collect.add_argument("--robots", nargs="+", type=int, default=[2, 4])
    collect.add_argument("--jobs", type=int, default=2)
    fit = sub.add_parser("fit")
    fit.add_argument("--write", action="store_true")
    for p in (collect, fit):
        p.add_argument("--out", type=Path, default=OUTPUT / "placement")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.command == "collect":
        cases = []
        for name in present_logs(args.logs):
            cases += [(name, k) for k in args.robots]
        # The longest (freiburg-079, dense) first, so that the jobs end together.
        cases.sort(key=lambda case: case[0] != "freiburg-079")
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            futures = [pool.submit(collect_case, name, k, args.out) for name, k in cases]
            for future in futures:
                print(future.result(), flush=True)
        return
    data = load(args.out)
    if not data:
        sys.exit(f"no collected matches in {args.out}: run `collect` first")
    threshold = LocalMapperConfig().integrate_confidence
    print("\n".join(reliability(data)))
    print()
    print("\n".join(report(data, threshold)))
    fits = fit_all(data)
    print()
    for context, (slope, intercept) in fits.items():
        print(f"{context}: slope {slope:.3f}, intercept {intercept:.3f}")
    if args.write:
        write_model(fits, data)
        print(f"wrote {MODEL_FILE.relative_to(REPO)}")


if __name__ == "__main__":
    main()
