"""The merging table of issue 5: each CARMEN log cut into 2, 4 and 8 robots, mapped and merged.

For every log and robot count K the real pipeline runs end to end, each step in its own ``mrm``
process: ``mrm import-carmen LOG --robots K`` (the bag is cached under ``--work`` and reused),
``mrm replay BAG --method pivot|ffs`` (``--method``; local mapping per robot, then merging)
and ``mrm evaluate`` against the log's reference poses.

    .venv/bin/python -m bench.merge_table [--logs intel aces fhw csail] [--robots 2 4 8]
        [--jobs 1] [--work bench_output/merge_table] [--json PATH] [--overlap-scans 0]
        [--set NAME=VALUE ...] [--quick]

``--bags intel aces fr079`` adds the shared dense bags (every scan, ``mrm import-bag`` with the
truth file and CARMEN's beam geometry instead of ``mrm import-carmen``; ``--robots 1 2 4 8``);
``--bag-table`` prints their table (issue 47: right / claimed / unmerged, worst own-frame ATE,
unposed share). Prints one Markdown table (ready for the README) on standard output, each row
on standard error as soon as its run is done, and writes every figure (stats.json and
metrics.json of each run, the wall time of each step) to ``--json`` (default
WORK/merge_table.json). ``--jobs N`` runs N (log, K) cases at once; every child is limited to
one thread. ``--quick`` is intel, K = 2 only. A missing log is skipped with a note; a failing
step is reported in its row. ``--table`` prints the table of an earlier run's JSON without
running anything (``--collect`` first saves it from every run evaluated in WORK, as after runs
of several invocations); ``--summary`` prints the README's summary of it (one row per log:
bench/results.py renders both).

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

from bench.harness import (
    OUTPUT,
    imported_bag,
    imported_dense_bag,
    mrm,
    present_bags,
    present_logs,
)
from multi_robot_mapper.cli.evaluate import METRICS_FILE
from multi_robot_mapper.core.merging.methods import MERGE_METHODS
from multi_robot_mapper.io.results import read_results

COLUMNS = (
    "log | robots | merged | placed | ATE merged (m) | ATE all (m) | map error (m) | coverage | "
    "precision | merge (s) | merge update (s) | replay (s) | pair_success | links | wrong links "
    "(wrong only by the reference)"
)


def run_case(
    name: str, robots: int, args: argparse.Namespace, dense: bool = False
) -> dict[str, Any]:
    """Import (or reuse) the bag, replay with ``--method``, evaluate; every figure as one
    dict. ``dense``: ``name`` is a shared dense bag (every scan), cut by ``mrm import-bag``."""
    row: dict[str, Any] = {"log": f"{name}.bag" if dense else name, "robots": robots}
    tag = f"{name}_{robots}" + (f"_o{args.overlap_scans}" if args.overlap_scans else "")
    tag = f"bag_{tag}" if dense else tag
    bag, out = args.work / "bags" / tag, args.work / "runs" / tag
    # The log lies beside the run folder: replay refuses a folder that holds files unless
    # --overwrite, which replaces it as a whole at the end.
    out.parent.mkdir(parents=True, exist_ok=True)
    log = out.parent / f"{tag}.log"
    log.write_text("")
    try:
        if dense:
            imported_dense_bag(name, robots, bag, log)
        else:
            imported_bag(name, robots, bag, args.overlap_scans, log)
        overrides = [item for pair in args.set for item in ("--set", pair)]
        replay = ["replay", str(bag), "--out", str(out), "--method", args.method]
        row["replay_wall_s"] = mrm([*replay, "--overwrite", *overrides], log)
        row["evaluate_wall_s"] = mrm(["evaluate", str(out), "--bag", str(bag), "--json"], log)
        row.update(scored(out, bag, dense))
    except Exception as exc:  # one failing case must not stop the table
        row["error"] = str(exc)
    return row


def scored(out: Path, bag: Path, dense: bool) -> dict[str, Any]:
    """The figures of a run evaluated in ``out`` (of the cut ``bag``)."""
    figures: dict[str, Any] = {"stats": read_results(out).stats}
    figures["metrics"] = json.loads((out / METRICS_FILE).read_text())
    links = figures["stats"].get("merge_graph_links", [])
    figures["links_wrong"] = wrong_links(links, bag)
    if dense:  # few keyframes have a reference pose: judge those that do
        figures["links_judged"] = judged_links(links, bag)
    return figures


def collected(work: Path) -> list[dict[str, Any]]:
    """The rows of every run evaluated under ``work`` (runs of several invocations, or of one
    stopped before it wrote its JSON), named by their folders (``NAME_K``, ``bag_NAME_K``)."""
    rows = []
    for out in sorted((work / "runs").iterdir()):
        if not (out / METRICS_FILE).is_file() or "_o" in out.name:
            continue
        dense = out.name.startswith("bag_")
        name, _, robots = out.name.removeprefix("bag_").rpartition("_")
        row = {"log": f"{name}.bag" if dense else name, "robots": int(robots)}
        rows.append(row | scored(out, work / "bags" / out.name, dense))
    return sorted(rows, key=lambda row: (row["log"], row["robots"]))


def _verdicts(links: list[list[Any]], bag: Path) -> list[str | None]:
    """Each joint-graph link (``[robot_a, stamp_a, robot_b, stamp_b, x, y, theta]``: keyframe b
    at T_a_b in keyframe a's frame) judged against the bag's reference poses
    (``reference_check.ReferenceJudge``): "wrong", "reference" (wrong only by the reference's
    own error), or None where a keyframe has no reference pose."""
    from bench.reference_check import ReferenceJudge
    from multi_robot_mapper.io.bags import read_recordings

    judge = ReferenceJudge(read_recordings(bag))
    return [
        judge.verdict(a, stamp_a, b, stamp_b, (x, y, theta))
        for a, stamp_a, b, stamp_b, x, y, theta in links
    ]


def wrong_links(links: list[list[Any]], bag: Path) -> tuple[int, int] | None:
    """How many of the joint graph's links are wrong against the bag's reference poses (off by
    more than the confidence's own tolerance, 0.30 m / 5 deg), and how many more are wrong only
    by the reference's own error at one of their scans (:func:`_verdicts`). None when a link's
    keyframe has no reference pose."""
    if not links:
        return 0, 0
    verdicts = _verdicts(links, bag)
    if None in verdicts:
        return None
    return verdicts.count("wrong"), verdicts.count("reference")


def judged_links(links: list[list[Any]], bag: Path) -> tuple[int, int, int, int]:
    """:func:`wrong_links` over the links both of whose keyframes have a reference pose (on a
    dense bag one scan in 15-17 has one): wrong, wrong only by the reference, judged, all."""
    judged = [v for v in _verdicts(links, bag) if v is not None] if links else []
    return judged.count("wrong"), judged.count("reference"), len(judged), len(links)


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


# Issue 47's table of the dense bags: each bag cut into K robots, end to end.
BAG_COLUMNS = (
    "bag | robots | right / claimed / unmerged | worst own-frame ATE (m) | unposed | "
    "ATE merged (m) | replay (s) | links wrong (only by the reference) / judged / all"
)


def bag_row(row: dict[str, Any]) -> str:
    """One row of :data:`BAG_COLUMNS`: "right" are the robots one rigid alignment of the map
    confirms, "claimed" those the merger placed, "unmerged" those it reported unmerged."""
    head = f"| {row['log']} | {row['robots']} | "
    if "error" in row:
        return head + f"failed: {row['error'][:90]} |" + " |" * 5
    m = row["metrics"]
    robots = m["robots"].values()
    claimed = sum(not r["reported_unmerged"] for r in robots)
    own = [r["ate_own_frame_m"] for r in robots if r.get("ate_own_frame_m") is not None]
    judged = row.get("links_judged")
    cells = [
        f"{m['robots_merged']} / {claimed} / {m['robots_total'] - claimed}",
        fmt(max(own), 3) if own else "—",
        _unposed(m),
        fmt(m["ate_rmse_m"], 3),
        fmt(row["stats"].get("total_s"), 0),
        "?" if judged is None else "{} ({}) / {} / {}".format(*judged),
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


def print_table(path: Path, summary: bool, bags: bool = False) -> None:
    """The table (with ``summary`` the README's summary; with ``bags`` issue 47's table of the
    dense bags) of the runs saved at ``path``."""
    rows = json.loads(path.read_text())["rows"]
    if bags:
        rows = [row for row in rows if row["log"].endswith(".bag")]
        lines = [bag_row(row) for row in rows]
        columns = BAG_COLUMNS
    else:
        lines = summary_rows(rows) if summary else [table_row(row) for row in rows]
        columns = SUMMARY_COLUMNS if summary else COLUMNS
    print(f"| {columns} |\n|" + " --- |" * (columns.count("|") + 1))
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--logs", nargs="+", help="default intel aces fhw csail, or none with --bags"
    )
    parser.add_argument("--bags", nargs="+", default=[], help="shared dense bags (intel aces ...)")
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
    parser.add_argument("--bag-table", action="store_true", help="print the saved bags' table")
    parser.add_argument(
        "--collect", action="store_true", help="save the JSON of every run evaluated in WORK"
    )
    args = parser.parse_args()
    if (args.table or args.summary or args.bag_table) and not args.collect:
        print_table(args.json or args.work / "merge_table.json", args.summary, args.bag_table)
        return
    if args.collect:
        path = args.json or args.work / "merge_table.json"
        path.write_text(json.dumps({"rows": collected(args.work)}, indent=1) + "\n")
        print_table(path, summary=False, bags=args.bag_table)
        return
    if args.logs is None:
        args.logs = [] if args.bags else ["intel", "aces", "fhw", "csail"]
    if args.quick:
        args.logs, args.robots = ["intel"], [2]
    args.work = args.work.resolve()
    cases = [(name, k, False) for name in present_logs(args.logs) for k in args.robots]
    cases += [(name, k, True) for name in present_bags(args.bags) for k in args.robots]
    started = time.perf_counter()
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:  # the work is in the mrm children
        futures = [pool.submit(run_case, name, k, args, dense) for name, k, dense in cases]
        for future in as_completed(futures):
            row = future.result()
            print((bag_row if row["log"].endswith(".bag") else table_row)(row), file=sys.stderr)
    rows = [future.result() for future in futures]  # in grid order
    wall = time.perf_counter() - started
    path = args.json or args.work / "merge_table.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    report = {"wall_s": wall, "jobs": args.jobs, "overrides": args.set, "rows": rows}
    path.write_text(json.dumps(report, indent=1) + "\n")
    print_table(path, summary=False, bags=bool(args.bags) and not args.logs)
    print(
        f"{len(rows)} runs, wall {wall / 60:.1f} min, --jobs {args.jobs} -> {path}", file=sys.stderr
    )


if __name__ == "__main__":
    main()
