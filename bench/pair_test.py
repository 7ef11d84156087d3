"""Pair test in the manner of Amigoni's Table 2: consecutive scans matched by INTEGRATE alone.

For every consecutive scan pair of the CARMEN logs, INTEGRATE (no initial guess, no
prediction, no extra hypotheses) estimates the relative pose; a pair succeeds within 0.30 m
and 5 deg of the reference (strict: 0.10 m and 2 deg). Prints the success rates, how far the
validity flag can be trusted, and the median time per pair (INTEGRATE only, one core).

    .venv/bin/python -m bench.pair_test [--logs intel aces] [--limit 200]
        [--heuristics consecutive random histogram all endpoints] [--no-views] [--no-refine]
        [--set NAME=VALUE ...]
    .venv/bin/python -m bench.pair_test --table [--heuristic-limit 300] [--json out.json]

``--table`` runs Amigoni's Table 2 layout: every heuristic alone and their combination, each
without refinement (``refine_iterations=0``: no least squares at all; the candidates are still
ranked by their beams and slid along corridors) and with it, on every log, and prints one
markdown table. ``all`` engages only for sets of at most ``all_pairs_below`` segments.
``--json`` writes every row's figures to a file (``-`` for standard output).

Target (issue 4): >= 97 % on every log with one parameter set, median < 20 ms per pair.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import TextIO  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import LOGS, ExtractedLog, extracted_log, pair_indices  # noqa: E402
from bench.reference_check import judge_of_log  # noqa: E402
from multi_robot_mapper.cli.common import add_set_option  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.config import config_from_flat, parse_override  # noqa: E402
from multi_robot_mapper.core.local_mapping import LocalMapperConfig  # noqa: E402
from multi_robot_mapper.core.matching import HEURISTICS, IntegrateConfig, integrate  # noqa: E402

# The local mapper's threshold for integrating a scan (LocalMapperConfig.integrate_confidence).
INTEGRATE_CONFIDENCE = LocalMapperConfig().integrate_confidence
COMBINATION = "combination"


@dataclasses.dataclass(frozen=True)
class Row:
    """Figures of one configuration on one log."""

    log: str
    heuristics: str  # one heuristic's name, or "combination"
    refine: bool
    views: bool
    pairs: int
    success: float
    strict: float
    valid: float
    precision: float  # correct among valid
    recall: float  # valid among correct
    median_ms: float
    p90_ms: float
    # median ms per stage of INTEGRATE (MatchResult.seconds: hypotheses, prescreen, ...)
    stage_median_ms: dict[str, float] = dataclasses.field(default_factory=dict)
    # "confidence >= integrate_confidence" as the validity test (the fitted model includes
    # these pairs: the held-out figures come from bench/fit_confidence.py)
    confident_precision: float = float("nan")
    confident_recall: float = float("nan")
    # confident pairs wrong by the reference but right once the reference of their scans is
    # replaced by the pose the scans either side agree on (reference_check.ReferenceJudge)
    confident_wrong_by_reference: int = 0
    confident_precision_judged: float = float("nan")


def run_log(
    log: ExtractedLog,
    pairs: np.ndarray,
    heuristics: tuple[str, ...],
    views: bool,
    config: IntegrateConfig,
) -> Row:
    ok = strict = valid = valid_and_ok = confident = confident_and_ok = 0
    times = []
    stages: dict[str, list[float]] = {}
    suspects: list[tuple[int, tuple[float, float, float]]] = []  # confident and wrong
    for k in pairs:
        T_world_1 = se2.matrix_from_pose(*log.poses[k])
        T_world_2 = se2.matrix_from_pose(*log.poses[k + 1])
        T_1_2 = se2.invert(T_world_1) @ T_world_2
        start = time.perf_counter()
        result = integrate(
            log.segments[k],
            log.segments[k + 1],
            config,
            heuristics=heuristics,
            views=(log.views[k], log.views[k + 1]) if views else (None, None),
        )
        times.append(time.perf_counter() - start)
        for stage, seconds in result.seconds.items():
            stages.setdefault(stage, []).append(seconds)
        dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_1_2) @ result.matrix)
        error, turn = np.hypot(dx, dy), abs(dtheta)
        correct = bool(error < 0.30 and turn < np.radians(5))
        ok += correct
        strict += bool(error < 0.10 and turn < np.radians(2))
        valid += result.valid
        valid_and_ok += result.valid and correct
        sure = result.confidence >= INTEGRATE_CONFIDENCE
        confident += sure
        confident_and_ok += sure and correct
        if sure and not correct:
            suspects.append((int(k), se2.pose_from_matrix(result.matrix)))
    by_reference = wrong_by_reference(log, suspects)
    n = max(len(pairs), 1)
    return Row(
        log=log.name,
        heuristics=COMBINATION if len(heuristics) > 1 else heuristics[0],
        refine=config.refine_iterations > 0,
        views=views,
        pairs=len(pairs),
        success=ok / n,
        strict=strict / n,
        valid=valid / n,
        precision=valid_and_ok / valid if valid else float("nan"),
        recall=valid_and_ok / ok if ok else float("nan"),
        median_ms=float(np.median(times)) * 1e3 if times else float("nan"),
        p90_ms=float(np.percentile(times, 90)) * 1e3 if times else float("nan"),
        stage_median_ms={k: float(np.median(v)) * 1e3 for k, v in stages.items()},
        confident_precision=confident_and_ok / confident if confident else float("nan"),
        confident_recall=confident_and_ok / ok if ok else float("nan"),
        confident_wrong_by_reference=by_reference,
        confident_precision_judged=(
            (confident_and_ok + by_reference) / confident if confident else float("nan")
        ),
    )


def wrong_by_reference(
    log: ExtractedLog, suspects: list[tuple[int, tuple[float, float, float]]]
) -> int:
    """How many of ``suspects`` (pair k, k+1 and its match) are wrong only by the reference:
    right once the reference of scan k or k+1 is replaced by the pose their neighbours agree
    on (``ReferenceJudge.verdict`` "reference", the judge of the local and merge tables)."""
    if not suspects:
        return 0
    judge = judge_of_log(log.name, log.views, log.poses)
    return sum(
        judge.verdict(log.name, float(k), log.name, float(k + 1), found) == "reference"
        for k, found in suspects
    )


def print_row(row: Row, out: TextIO) -> None:
    print(
        f"{row.log:6s} {row.heuristics:11s} refine {'on ' if row.refine else 'off'} "
        f"pairs {row.pairs:4d}  success {row.success:.3f}  strict {row.strict:.3f}  "
        f"valid {row.valid:.3f} (correct among valid {row.precision:.3f}, "
        f"valid among correct {row.recall:.3f})  median {row.median_ms:.1f} ms  "
        f"p90 {row.p90_ms:.1f} ms\n"
        f"       confidence >= {INTEGRATE_CONFIDENCE:g}: precision {row.confident_precision:.3f}"
        f" recall {row.confident_recall:.3f} ({row.confident_wrong_by_reference} wrong only by "
        f"the reference: precision judged {row.confident_precision_judged:.3f}); "
        "median ms per stage: " + ", ".join(f"{k} {v:.2f}" for k, v in row.stage_median_ms.items()),
        file=out,
        flush=True,
    )


def markdown_table(rows: list[Row], logs: list[str]) -> str:
    """Amigoni Table 2 layout: one line per heuristic and refinement, one column per log."""
    head = "| heuristic | refinement | " + " | ".join(logs) + " |"
    rule = "| --- | --- | " + " | ".join("---" for _ in logs) + " |"
    lines = [
        "Each cell: success (0.30 m / 5 deg) / strict (0.10 m / 2 deg) / median ms per pair "
        "[pairs]",
        "",
        head,
        rule,
    ]
    keys: list[tuple[str, bool]] = []
    for row in rows:
        if (row.heuristics, row.refine) not in keys:
            keys.append((row.heuristics, row.refine))
    # Single heuristics first, their combination last, as in Amigoni's Table 2.
    keys.sort(
        key=lambda key: (
            key[0] == COMBINATION,
            HEURISTICS.index(key[0]) if key[0] in HEURISTICS else 0,
            key[1],
        )
    )
    for name, refine in keys:
        cells = []
        for log in logs:
            match = [r for r in rows if (r.heuristics, r.refine, r.log) == (name, refine, log)]
            cells.append(
                f"{match[0].success:.3f} / {match[0].strict:.3f} / {match[0].median_ms:.1f} "
                f"[{match[0].pairs}]"
                if match
                else "-"
            )
        lines.append(f"| {name} | {'on' if refine else 'off'} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=list(LOGS))
    parser.add_argument("--limit", type=int, default=0, help="at most this many pairs per log")
    parser.add_argument("--heuristics", nargs="+", default=list(HEURISTICS), choices=HEURISTICS)
    parser.add_argument("--no-views", action="store_true", help="no free-space check")
    parser.add_argument(
        "--no-refine", action="store_true", help="no least-squares refinement (refine_iterations=0)"
    )
    parser.add_argument(
        "--table",
        action="store_true",
        help="every heuristic alone and combined, without and with refinement: a markdown table",
    )
    parser.add_argument(
        "--heuristic-limit",
        type=int,
        default=None,
        help="with --table, at most this many pairs per log for the single-heuristic rows "
        "(default: --limit)",
    )
    parser.add_argument("--json", metavar="PATH", help="write every row's figures ('-': stdout)")
    add_set_option(parser, "override an IntegrateConfig field, e.g. --set refine_candidates=8")
    args = parser.parse_args()
    flat = dict(parse_override(o) for o in args.overrides)
    if args.no_refine:
        flat["refine_iterations"] = 0
    config = config_from_flat(IntegrateConfig, flat)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    out = sys.stderr if args.json == "-" else sys.stdout
    logs = [log for log in (extracted_log(name) for name in args.logs) if log is not None]
    rows: list[Row] = []
    if args.table:
        refined = (
            config
            if config.refine_iterations > 0
            else dataclasses.replace(config, refine_iterations=IntegrateConfig().refine_iterations)
        )
        unrefined = dataclasses.replace(config, refine_iterations=0)
        heuristic_limit = args.limit if args.heuristic_limit is None else args.heuristic_limit
        print(
            f"INTEGRATE pair test, table: views {not args.no_views}, overrides "
            f"{args.overrides or 'none'}, pairs per log {args.limit or 'all'} (combination), "
            f"{heuristic_limit or 'all'} (single heuristics)",
            file=out,
            flush=True,
        )
        setups: list[tuple[tuple[str, ...], int]] = [(HEURISTICS, args.limit)]
        setups += [((name,), heuristic_limit) for name in HEURISTICS]
        for heuristics, limit in setups:
            for cfg in (unrefined, refined):
                for log in logs:
                    row = run_log(log, pair_indices(log, limit), heuristics, not args.no_views, cfg)
                    rows.append(row)
                    print_row(row, out)
        print(file=out)
        print(markdown_table(rows, [log.name for log in logs]), file=out, flush=True)
    else:
        print(
            f"INTEGRATE pair test: heuristics {' '.join(args.heuristics)}, "
            f"views {not args.no_views}, refine {config.refine_iterations > 0}, "
            f"overrides {args.overrides or 'none'}",
            file=out,
            flush=True,
        )
        for log in logs:
            row = run_log(
                log,
                pair_indices(log, args.limit),
                tuple(args.heuristics),
                not args.no_views,
                config,
            )
            rows.append(row)
            print_row(row, out)
    if args.json:
        text = json.dumps([dataclasses.asdict(r) for r in rows], indent=1)
        if args.json == "-":
            print(text)
        else:
            Path(args.json).write_text(text + "\n")


if __name__ == "__main__":
    main()
