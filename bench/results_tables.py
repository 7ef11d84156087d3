"""The tables bench/results.py renders from benches that only print (issue 48).

    .venv/bin/python -m bench.results_tables NAME --work W

``W`` is a block's folder as ``bench.results run`` leaves it: ``provenance.json`` (the commands,
in order) and ``run-I.txt``, what command I printed. Each NAME below reads those and prints one
Markdown table; it measures nothing.
"""

from __future__ import annotations

import argparse
import json
import re
from collections.abc import Callable
from pathlib import Path


def _runs(work: Path) -> list[tuple[list[str], str]]:
    """Each run's command (split) and printed output, in the block's order."""
    commands = json.loads((work / "provenance.json").read_text())["commands"]
    return [(c.split(), (work / f"run-{i}.txt").read_text()) for i, c in enumerate(commands)]


def _option(command: list[str], name: str, default: str) -> str:
    return command[command.index(name) + 1] if name in command else default


def _find(pattern: str, text: str) -> re.Match[str]:
    found = re.search(pattern, text, re.M)
    if found is None:
        raise SystemExit(f"bench.results_tables: no {pattern!r} in a run's output")
    return found


def frontend(work: Path) -> list[str]:
    """Segments per scan on each log (``mrm frontend LOG``)."""
    rows = [
        "| log | scans | beams | segments per scan (median) | lone points dropped (median) "
        "| beams without return (median) |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for command, text in _runs(work):
        log = Path(command[-1]).name.removesuffix(".gz").removesuffix(".log")
        cells = (
            _find(r"^scans: (\d+)", text)[1],
            _find(r"^beams: (\d+)", text)[1],
            _find(r"^segments per scan: median (\d+)", text)[1],
            _find(r"^points dropped in small clusters per scan: median (\d+)", text)[1],
            _find(r"^beams without a valid return per scan: median (\d+)", text)[1],
        )
        rows.append(f"| {log} | {' | '.join(cells)} |")
    return rows


def throughput(work: Path) -> list[str]:
    """``bench.frontend_throughput``'s two lines as a table."""
    ((command, text),) = _runs(work)
    passes = _option(command, "--repeat", "5")
    rows = [
        f"| scans | target | measured (median of {passes} passes) | best pass |",
        "| --- | --- | --- | --- |",
    ]
    for beams, source in (("180", "real, intel"), ("1081", "simulated UTM-30LX")):
        line = _find(rf"^\s*{beams} beams:\s+(\d+) best,\s+(\d+) median\s+\(target >= (\d+)", text)
        rows.append(
            f"| {beams} beams ({source}) | ≥ {line[3]} scans/s | {line[2]} scans/s | "
            f"{line[1]} scans/s |"
        )
    return rows


def merge_speed(work: Path) -> list[str]:
    """``bench.merge_speed``'s pairs: the median merge time and the placement error."""
    rows = [
        "| pair | merge time (median) | CPU time per merge (median) | placement error |",
        "| --- | --- | --- | --- |",
    ]
    for command, text in _runs(work):
        log = _option(command, "--log", "intel")
        overlap = _option(command, "--overlap", "40")
        pair = f"{log}, halves overlapping by {overlap} scans"
        error = re.search(r"^error vs reference: ([\d.]+) cm, ([\d.]+) deg", text, re.M)
        placed = f"{error[1]} cm, {error[2]}°" if error else "unmerged (no valid link)"
        wall = _find(r"^merge: median ([\d.]+) ms", text)[1]
        cpu = _find(r"^CPU time per merge: median ([\d.]+) ms", text)[1]
        rows.append(f"| {pair} | {wall} ms | {cpu} ms | {placed} |")
    return rows


_SEED_ROW = re.compile(
    r"^\| (\d+) \| (\d+) \| \w+ \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| (\d+)/(\d+) \| ([\d.]+) \|$",
    re.M,
)


def _ffs_runs(work: Path) -> list[dict]:
    """Each ``bench.ffs_bench`` run: log, distortion, seeds hit and per-seed rows."""
    out = []
    for command, text in _runs(work):
        hits = _find(r"within 1 cm and 0.5 deg: (\d+)/(\d+) seeds", text)
        median = _find(r"median ([\d.]+) ms per iteration", text)[1]
        metres, degrees = _option(command, "--distortion", "0.30,20").split(",")
        out.append(
            {
                "log": _option(command, "--log", "intel"),
                "distortion": f"±{float(metres):.2f} m, ±{degrees}°",
                "hits": f"{hits[1]}/{hits[2]}",
                "rows": _SEED_ROW.findall(text),
                "ms": median,
            }
        )
    return out


def ffs_seeds(work: Path) -> list[str]:
    """Per seed at the paper's distortion (±0.30 m, ±20°), one column per log."""
    runs = [r for r in _ffs_runs(work) if r["distortion"] == "±0.30 m, ±20°"]
    rows = [
        "| seed | " + " | ".join(r["log"] for r in runs) + " |",
        "| --- |" + " --- |" * len(runs),
    ]
    for index, first in enumerate(runs[0]["rows"]):
        cells = [
            f"{r[2]} / {r[3]} / {r[4]} / {r[5]} ({r[1]} it)"
            for r in (run["rows"][index] for run in runs)
        ]
        rows.append(f"| {first[0]} | " + " | ".join(cells) + " |")
    rows.append("| ms per iteration (median) | " + " | ".join(r["ms"] for r in runs) + " |")
    return rows


def _span(values: list[str]) -> str:
    low, high = min(values, key=float), max(values, key=float)
    return low if low == high else f"{low}–{high}"


def ffs_distortions(work: Path) -> list[str]:
    """One row per log and distortion: the seeds' ranges."""
    rows = [
        "| log | distortion | seeds all within 1 cm, 0.5° | max deviation (cm) | max deviation (°) "
        "| median deviation (cm) | bodies back | ms per iteration (median) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for run in _ffs_runs(work):
        seeds = run["rows"]
        cells = (
            run["hits"],
            _span([s[2] for s in seeds]),
            _span([s[3] for s in seeds]),
            _span([s[4] for s in seeds]),
            f"{_span([s[5] for s in seeds])} of {seeds[0][6]}",
            run["ms"],
        )
        rows.append(f"| {run['log']} | {run['distortion']} | " + " | ".join(cells) + " |")
    return rows


def printed(work: Path) -> list[str]:
    """The Markdown tables the runs printed, one header kept where several repeat it."""
    rows: list[str] = []
    for _, text in _runs(work):
        lines = [line for line in text.splitlines() if line.startswith("|")]
        if rows and lines[:2] == rows[:2]:
            lines = lines[2:]
        rows += lines
    return rows


def merge_alone(work: Path) -> list[str]:
    """``bench.merge_speed --joint --split``'s rows (it prints no header: its ``--joint`` help
    names the columns)."""
    header = (
        "| log | robots | placed | worst placement | worst keyframe | links | wrong | merge (s) "
        "| update, nothing new (s) | update, a keyframe per robot (s) | update, one robot's "
        "keyframe, budget (s) (of which not matching) | keyframes |"
    )
    return [header, "|" + " --- |" * (header.count("|") - 1), *printed(work)]


def confidence(work: Path, judged: bool = False) -> list[str]:
    """``bench.fit_confidence fit``'s held-out checks at confidence ≥ 0.8."""
    report = json.loads((work / "cross_validation.json").read_text())
    if judged:
        rows = [
            "| log (held out) | consecutive precision → judged (pairs wrong only by the reference) "
            "| all kinds precision → judged |",
            "| --- | --- | --- |",
        ]
    else:
        rows = [
            "| log (held out) | consecutive precision / recall | all kinds precision / recall "
            "| Brier score |",
            "| --- | --- | --- | --- |",
        ]
    for log, entry in report.items():
        at = entry["t0.8"]
        if not judged:
            rows.append(
                f"| {log} | {at['consecutive_precision']:.3f} / {at['consecutive_recall']:.3f} "
                f"| {at['all_precision']:.3f} / {at['all_recall']:.3f} | {entry['brier']:.3f} |"
            )
        elif "consecutive_precision_judged" in entry:
            rows.append(
                f"| {log} | {at['consecutive_precision']:.3f} → "
                f"{entry['consecutive_precision_judged']:.3f} ({entry['consecutive_by_reference']})"
                f" | {at['all_precision']:.3f} → {entry['all_precision_judged']:.3f} "
                f"({entry['all_by_reference']}) |"
            )
    return rows


TABLES: dict[str, Callable[[Path], list[str]]] = {
    "frontend": frontend,
    "throughput": throughput,
    "merge_speed": merge_speed,
    "ffs_seeds": ffs_seeds,
    "ffs_distortions": ffs_distortions,
    "printed": printed,
    "merge_alone": merge_alone,
    "confidence": confidence,
    "confidence_judged": lambda work: confidence(work, judged=True),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("name", choices=sorted(TABLES))
    parser.add_argument("--work", type=Path, required=True)
    args = parser.parse_args()
    print("\n".join(TABLES[args.name](args.work)))


if __name__ == "__main__":
    main()
