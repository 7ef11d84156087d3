"""The merging table of issue 5: each CARMEN log cut into 2, 4 and 8 robots, mapped and merged.

For every log and robot count K the real pipeline runs end to end, each step in its own ``mrm``
process: ``mrm import-carmen LOG --robots K`` (the bag is cached under ``--work`` and reused),
``mrm replay BAG --method pivot|ffs`` (``--method``; local mapping per robot, then merging)
and ``mrm evaluate`` against the log's reference poses.

    .venv/bin/python -m bench.merge_table [--logs intel aces fhw csail] [--robots 2 4 8]
        [--jobs 1] [--work bench_output/merge_table] [--json PATH] [--overlap-scans 0]
        [--set NAME=VALUE ...] [--quick]

Prints one Markdown table (ready for the README) on standard output, each row on standard
error as soon as its run is done, and writes every figure (stats.json and metrics.json of each
run, the wall time of each step) to ``--json`` (default WORK/merge_table.json). ``--jobs N``
runs N (log, K) cases at once; every child is limited to one thread. ``--quick`` is intel,
K = 2 only. A missing log is skipped with a note; a failing step is reported in its row.
``--table`` prints the table of an earlier run's JSON without running anything; ``--summary``
prints the README's summary of it (one row per log: bench/results.py renders both).

Target (issue 5): every robot merged in every case, ATE <= 0.15 m.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path
from types import MappingProxyType
from typing import Any

from bench.harness import OUTPUT, imported_bag, mrm, present_logs
from multi_robot_mapper.cli.evaluate import METRICS_FILE
from multi_robot_mapper.core.merging.methods import MERGE_METHODS
from multi_robot_mapper.io.results import read_results

COLUMNS = (
    "log | robots | merged | placed | ATE merged (m) | ATE all (m) | map error (m) | coverage | "
    "precision | merge (s) | merge update (s) | replay (s) | pair_success | links | wrong links "
    "(wrong only by the reference)"
)


def run_case(name: str, robots: int, args: argparse.Namespace) -> dict[str, Any]:
    """Import (or reuse) the bag, replay with ``--method``, evaluate; every figure as one
    dict."""
    row: dict[str, Any] = {"log": name, "robots": robots}
    tag = f"{name}_{robots}" + (f"_o{args.overlap_scans}" if args.overlap_scans else "")
    bag, out = args.work / "bags" / tag, args.work / "runs" / tag
    # The log lies beside the run folder: replay refuses a folder that holds files unless
    # --overwrite, which replaces it as a whole at the end.
    out.parent.mkdir(parents=True, exist_ok=True)
    log = out.parent / f"{tag}.log"
    log.write_text("")
    try:
        imported_bag(name, robots, bag, args.overlap_scans, log)
        overrides = [item for pair in args.set for item in ("--set", pair)]
        replay = ["replay", str(bag), "--out", str(out), "--method", args.method]
        row["replay_wall_s"] = mrm([*replay, "--overwrite", *overrides], log)
        row["evaluate_wall_s"] = mrm(["evaluate", str(out), "--bag", str(bag), "--json"], log)
        row["stats"] = read_results(out).stats
        row["metrics"] = json.loads((out / METRICS_FILE).read_text())
        row["links_wrong"] = wrong_links(row["stats"].get("merge_graph_links", []), bag)
    except Exception as exc:  # one failing case must not stop the table
        row["error"] = str(exc)
    return row


def wrong_links(links: list[list[Any]], bag: Path) -> tuple[int, int] | None:
    """How many of the joint graph's links (``[robot_a, stamp_a, robot_b, stamp_b, x, y,
    theta]``: keyframe b at T_a_b in keyframe a's frame) are wrong against the bag's reference
    poses (off by more than the confidence's own tolerance, 0.30 m / 5 deg), and how many more
    are wrong only by the reference's own error at one of their scans
    (``reference_check.ReferenceJudge``). None when a link's keyframe has no reference pose."""
    from bench.reference_check import ReferenceJudge
    from multi_robot_mapper.io.bags import read_recordings

    if not links:
        return 0, 0
    judge = ReferenceJudge(read_recordings(bag))
    verdicts = [
        judge.verdict(a, stamp_a, b, stamp_b, (x, y, theta))
        for a, stamp_a, b, stamp_b, x, y, theta in links
    ]
    if None in verdicts:
        return None
    return verdicts.count("wrong"), verdicts.count("reference")


def fmt(value: Any, digits: int = 3) -> str:
    return "n/a" if value is None or value != value else f"{value:.{digits}f}"


def table_row(row: dict[str, Any]) -> str:
    head = f"| {row['log']} | {row['robots']} | "
    if "error" in row:
        return head + f"failed: {row['error'][:90]} |" + " |" * 12  # all of it in the JSON
    m, s = row["metrics"], row["stats"]
    links = str(s.get("merge_links_valid", "?"))
    wrong = row.get("links_wrong")
    # placed: robots the merger put in the map frame (not reported "unmerged"), however well.
    placed = sum(not r["reported_unmerged"] for r in m["robots"].values())
    cells = [
        f"{m['robots_merged']}/{m['robots_total']}",
        f"{placed}/{m['robots_total']}",
        fmt(m["ate_rmse_m"], 4),
        fmt(m["ate_all_rmse_m"], 3),
        fmt(m["map_error_m"], 4),
        fmt(m["map_coverage"]),
        fmt(m["map_precision"]),
        fmt(s.get("merge_s"), 1),
        fmt(s.get("merge_update_s"), 2),
        fmt(s.get("total_s"), 1),
        fmt(m["pair_success"]),
        links,
        "?" if wrong is None else f"{wrong[0]} ({wrong[1]})",
    ]
    return head + " | ".join(cells) + " |"


# What each shared log is, for the summary (its place and how far apart its scans are: the
# median distance and turn between consecutive scans).
LOG_PLACES = MappingProxyType(
    {
        "freiburg-079": "university building, dense (0.09 m, 3.3°)",
        "intel": "research lab (0.55 m, 18°)",
        "csail": "university building (0.94 m, 22°)",
        "fhw": "museum (0.83 m, 13°)",
        "aces": "long corridors (0.74 m, 15°)",
        "edmonton": "crowded convention hall (1.00 m, 8.8°)",
    }
)
SUMMARY_COLUMNS = (
    "log | place, spacing of the scans | pair_success 4 / 2 robots | unposed 4 / 2 | worst "
    "own-frame ATE, 2 and 4 robots (m) | merged 2 / 4 / 8 | ATE of the merged robots 2 / 4 / 8 (m)"
)


def summary_rows(rows: list[dict[str, Any]]) -> list[str]:
    """One row per log of the runs ``rows``: its 4- and 2-robot cuts' pair_success and
    unposed share, the worst own-frame ATE of their robots, and what each cut merged."""
    by_log: dict[str, dict[int, dict[str, Any]]] = {}
    for row in rows:
        if "metrics" in row:
            by_log.setdefault(row["log"], {})[row["robots"]] = row["metrics"]
    return [_summary_row(log, cuts) for log, cuts in by_log.items()]


def _pair_success(m: dict[str, Any]) -> str:
    return fmt(m["pair_success"])


def _unposed(m: dict[str, Any]) -> str:
    return f"{100.0 * m['scans_unposed'] / max(m['scans_total'], 1):.1f} %"


def _merged(m: dict[str, Any]) -> str:
    return f"{m['robots_merged']}/{m['robots_total']}"


def _merged_ate(m: dict[str, Any]) -> str:
    return fmt(m["ate_rmse_m"]) if m["robots_merged"] > 1 else "—"


def _summary_row(log: str, cuts: dict[int, dict[str, Any]]) -> str:
    """The summary row of one log from the metrics of its cuts (by robot count)."""

    def each(counts: tuple[int, ...], figure: Any, joint: str) -> str:
        return joint.join(figure(cuts[k]) if k in cuts else "—" for k in counts)

    own = [
        r["ate_own_frame_m"]
        for k in (2, 4)
        for r in cuts.get(k, {}).get("robots", {}).values()
        if r.get("ate_own_frame_m") is not None
    ]
    cells = [
        log,
        LOG_PLACES.get(log, ""),
        each((4, 2), _pair_success, " / "),
        each((4, 2), _unposed, " / "),
        fmt(max(own), 2) if own else "—",
        each((2, 4, 8), _merged, ", "),
        each((2, 4, 8), _merged_ate, ", "),
    ]
    return "| " + " | ".join(cells) + " |"


def print_table(path: Path, summary: bool) -> None:
    """The table (or with ``summary`` the README's summary) of the runs saved at ``path``."""
    rows = json.loads(path.read_text())["rows"]
    columns = SUMMARY_COLUMNS if summary else COLUMNS
    print(f"| {columns} |\n|" + " --- |" * (columns.count("|") + 1))
    print("\n".join(summary_rows(rows) if summary else (table_row(row) for row in rows)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=["intel", "aces", "fhw", "csail"])
    parser.add_argument("--robots", type=int, nargs="+", default=[2, 4, 8])
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--work", type=Path, default=OUTPUT / "merge_table")
    parser.add_argument("--json", type=Path, help="default WORK/merge_table.json")
    parser.add_argument("--overlap-scans", type=int, default=0)
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--quick", action="store_true", help="intel, 2 robots only")
    parser.add_argument("--method", choices=tuple(MERGE_METHODS), default="pivot")
    parser.add_argument("--table", action="store_true", help="print the saved run's table")
    parser.add_argument("--summary", action="store_true", help="print the saved run's summary")
    args = parser.parse_args()
    if args.table or args.summary:
        print_table(args.json or args.work / "merge_table.json", args.summary)
        return
    if args.quick:
        args.logs, args.robots = ["intel"], [2]
    args.work = args.work.resolve()
    cases = [(name, k) for name in present_logs(args.logs) for k in args.robots]
    started = time.perf_counter()
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:  # the work is in the mrm children
        futures = [pool.submit(run_case, name, k, args) for name, k in cases]
        for future in as_completed(futures):
            print(table_row(future.result()), file=sys.stderr, flush=True)
    rows = [future.result() for future in futures]  # in grid order
    wall = time.perf_counter() - started
    path = args.json or args.work / "merge_table.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    report = {"wall_s": wall, "jobs": args.jobs, "overrides": args.set, "rows": rows}
    path.write_text(json.dumps(report, indent=1) + "\n")
    print_table(path, summary=False)
    print(
        f"{len(rows)} runs, wall {wall / 60:.1f} min, --jobs {args.jobs} -> {path}", file=sys.stderr
    )


if __name__ == "__main__":
    main()
