"""The local back end's own decisions, judged by the truth: every loop closure and join of pieces
the evidence model weighed (issue 46), for fitting and checking the back end's models
(``core/evidence/closure_model.json`` and ``piece_join_model.json``: ``bench/fit_join.py
--decisions closure`` and ``piece_join``).

    .venv/bin/python -m bench.backend_decisions --scenarios carmen:intel:4 generated_own:0 ...
        [--generated FIRST COUNT] [--gate model|all] [--jobs 2] [--work bench_output/backend]

Each scenario's robots are mapped by their own :class:`LocalMapper` (back end in line, every
scan, as ``bench/decisions.py collect --maps own`` maps them, without the merger). Every
decision the evidence model weighed is judged against the truth (the two keyframes' true
relative pose; wrong beyond 0.30 m / 5 deg) and written with its evidence, in the records'
format ``bench/fit_join.py`` reads (``WORK/records/SCENARIO.json``, kind ``weighed``).

``--gate all`` accepts every decision the model weighed (the back end as it was before the
evidence gate: the closures and joins the other checks pass, right and wrong, and what a wrong
one does to the rest of the run); ``--gate model`` (default) runs the back end as it ships.
A scenario already recorded is skipped (the collection resumes). ``--table`` prints what a
work folder holds as a markdown table instead (by shared log and cut, generated buildings
together), for docs/results.md (``bench/results.py``).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from contextlib import contextmanager, nullcontext  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.decisions import scenario_of, snapshots_of  # noqa: E402
from bench.harness import OUTPUT  # noqa: E402
from multi_robot_mapper.core.local_mapping.windows import WindowMatcher  # noqa: E402


@contextmanager
def every_weighed_accepted() -> Iterator[None]:
    """The back end with the evidence gate open: each decision is still weighed (and kept in
    ``weighed``) but accepted whatever its probability."""
    original = WindowMatcher._believed

    def believed(self: WindowMatcher, *args: Any, **kwargs: Any) -> bool:
        original(self, *args, **kwargs)
        return True

    WindowMatcher._believed = believed  # type: ignore[method-assign]
    try:
        yield
    finally:
        WindowMatcher._believed = original  # type: ignore[method-assign]


def collect_one(name: str, gate: str, work: str) -> str:
    """Map and judge one scenario's robots; returns a line for the log."""
    out = Path(work) / "records" / f"{name.replace(':', '_')}.json"
    if out.is_file():
        return f"{name}: recorded already"
    started = time.perf_counter()
    scenario = scenario_of(name)
    if scenario is None:
        return f"{name}: absent (its data is not here)"
    try:
        with every_weighed_accepted() if gate == "all" else nullcontext():
            _, records = snapshots_of(scenario, "own", [])
    except Exception as error:  # one scenario's failure does not end the collection
        return f"{name}: failed: {type(error).__name__}: {error}"
    weighed = [r for r in records if r["kind"] == "weighed"]
    accepted = [r for r in records if r["kind"] != "weighed"]
    case = {
        "scenario": name,
        "maps": "own",
        "gate": gate,
        "description": scenario.description,
        "closures": records,
        "updates": [],
        "seconds": round(time.perf_counter() - started, 1),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(case, default=str))
    wrong = sum(not r["right"] for r in weighed)
    return (
        f"{name}: {len(weighed)} weighed ({wrong} wrong), {len(accepted)} accepted "
        f"({sum(r['wrong'] for r in accepted)} wrong), {case['seconds']} s"
    )


def table(work: str) -> str:
    """The records of ``work`` as a markdown table: per shared-log cut or bag cut (generated
    buildings in one row), loop closures and joins of pieces weighed and accepted, each with
    how many were wrong by the truth, and the worst accepted one's error."""
    rows: dict[str, dict[str, Any]] = {}
    for path in sorted((Path(work) / "records").glob("*.json")):
        case = json.loads(path.read_text())
        source, *rest = case["scenario"].split(":")
        key = "generated buildings" if source.startswith("generated") else " ".join(rest)
        row = rows.setdefault(key, {"scenarios": 0, "worst": 0.0})
        row["scenarios"] += 1
        for record in case["closures"]:
            weighed = record["kind"] == "weighed"
            kind = record["weighed_kind"] if weighed else record["kind"]
            wrong = not record["right"] if weighed else bool(record["wrong"])
            column = f"{kind} {'weighed' if weighed else 'accepted'}"
            done, bad = row.get(column, (0, 0))
            row[column] = (done + 1, bad + int(wrong))
            if not weighed and wrong and kind != "heading":  # a heading's error is an angle
                row["worst"] = max(row["worst"], float(record["error_m"]))
    columns = ("loop weighed", "loop accepted", "join weighed", "join accepted", "heading accepted")
    lines = [
        "| scenario | runs | closures weighed (wrong) | closures accepted (wrong) "
        "| joins weighed (wrong) | joins accepted (wrong) | headings bridged (wrong) "
        "| worst accepted wrong (m) |",
        "| --- |" + " --- |" * 7,
    ]
    order = sorted(rows, key=lambda key: (key == "generated buildings", key))
    for key in order:
        row = rows[key]
        cells = [f"{row.get(c, (0, 0))[0]} ({row.get(c, (0, 0))[1]})" for c in columns]
        worst = f"{row['worst']:.2f}" if row["worst"] else "—"
        lines.append(f"| {key} | {row['scenarios']} | {' | '.join(cells)} | {worst} |")
    return "\n".join(lines)


def _weighed_loops(work: str) -> dict[str, list[dict[str, Any]]]:
    """The loop closures weighed in each scenario of ``work``, in the order weighed."""
    loops: dict[str, list[dict[str, Any]]] = {}
    for path in sorted((Path(work) / "records").glob("*.json")):
        case = json.loads(path.read_text())
        loops[case["scenario"]] = [
            r for r in case["closures"] if r["kind"] == "weighed" and r["weighed_kind"] == "loop"
        ]
    return loops


def compare(before: str, after: str) -> str:
    """The same decisions weighed two ways (two ``--gate all`` runs whose maps are the same: the
    evidence changed, not the decisions), per scenario: right and wrong closures' median score
    and conflict, and how many have no margin (score <= 0 or a rival at least as good)."""

    def summary(rows: list[dict[str, Any]]) -> str:
        if not rows:
            return "—"
        score = float(np.median([r["score"] for r in rows]))
        conflict = float(np.median([r["conflict"] for r in rows]))
        none = sum(r["score"] <= 0.0 or r["rival"] >= r["score"] for r in rows)
        return f"{len(rows)}: {score:.1f} / {conflict:.2f} / {none}"

    lines = [
        "| scenario | right closures: n: median score / conflict (m) / no margin, before "
        "| after | wrong closures, before | after |",
        "| --- | --- | --- | --- | --- |",
    ]
    old, new = _weighed_loops(before), _weighed_loops(after)
    for name in sorted(set(old) & set(new)):
        pairs = list(zip(old[name], new[name], strict=False))
        if any(a["right"] != b["right"] or a["error_m"] != b["error_m"] for a, b in pairs):
            lines.append(f"| {name} | not the same decisions (maps differ) | | | |")
            continue
        cells = [
            summary([pair[side] for pair in pairs if pair[0]["right"] == right])
            for right in (True, False)
            for side in (0, 1)
        ]
        lines.append(f"| {name} | {' | '.join(cells)} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--scenarios", nargs="*", default=[])
    parser.add_argument(
        "--generated",
        nargs=2,
        type=int,
        metavar=("FIRST", "COUNT"),
        help="also generated buildings FIRST .. FIRST+COUNT-1 (generated_own:SEED)",
    )
    parser.add_argument("--gate", choices=("model", "all"), default="model")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--work", default=str(OUTPUT / "backend"))
    parser.add_argument("--table", action="store_true", help="print WORK's records as a table")
    parser.add_argument(
        "--compare",
        nargs=2,
        metavar=("BEFORE", "AFTER"),
        help="two --gate all work folders of the same maps: the closures' evidence side by side",
    )
    args = parser.parse_args()
    if args.table:
        print(table(args.work))
        return
    if args.compare:
        print(compare(*args.compare))
        return
    names = list(args.scenarios)
    if args.generated:
        first, count = args.generated
        names += [f"generated_own:{seed}" for seed in range(first, first + count)]
    with ProcessPoolExecutor(args.jobs) as pool:
        for line in pool.map(
            collect_one, names, [args.gate] * len(names), [args.work] * len(names)
        ):
            print(line, flush=True)


if __name__ == "__main__":
    main()
