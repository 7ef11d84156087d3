"""docs/results.md's and the README's tables from the benches, by one command (issue 48).

    .venv/bin/python -m bench.results run [--only NAME ...] [--work bench_output/results]
    .venv/bin/python -m bench.results render [--only NAME ...] [--work ...]
    .venv/bin/python -m bench.results adopt NAME FOLDER --commit C --date D   # a run made by hand
    .venv/bin/python -m bench.results list

Each *block* is one table of the docs: the bench commands that measure it (``run``: each in a
child process from the repository root, into ``WORK/NAME``, which resumes where the benches
resume) and the command that prints it as Markdown from what they wrote. ``run`` records the
commit, date and time taken in ``WORK/NAME/provenance.json``; ``render`` replaces the text
between ``<!-- results:NAME -->`` and ``<!-- /results:NAME -->`` in docs/results.md and
README.md with the table and a line saying what made it, at which commit. A block with no run
is left as it is, and ``render`` says so. ``run`` with no ``--only`` runs every block: many
hours on two cores (``list`` gives each block's time as measured).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import re
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from bench.harness import OUTPUT

REPO = Path(__file__).resolve().parent.parent
DOCS = (REPO / "docs" / "results.md", REPO / "README.md")
PROVENANCE = "provenance.json"
_CARMEN_CUTS = tuple(
    f"carmen:{log}:{k}"
    for log in ("freiburg-079", "intel", "csail", "fhw", "aces", "edmonton")
    for k in (2, 4, 8)
)


@dataclasses.dataclass(frozen=True)
class Block:
    """One table: ``runs`` measure it into the work folder, ``table`` prints it (argv after
    ``python -m``; ``{work}`` is the block's folder). Blocks with the same ``work`` share one
    run (the README's summary is a view of the merging table)."""

    name: str
    question: str
    runs: tuple[tuple[str, ...], ...]
    table: tuple[str, ...]
    work: str = ""
    # about how long ``runs`` take on two cores, from their per-scenario times on this
    # project's 2-core machine (0: made by another block's runs)
    hours: float = 0.0

    @property
    def folder(self) -> str:
        return self.work or self.name


def _backend_block(
    name: str, question: str, scenarios: tuple[str, ...], hours: float, jobs: int = 2
) -> Block:
    """A block of ``bench.backend_decisions`` on ``scenarios`` (its arguments), the back end as
    shipped, and its table."""
    run = ("bench.backend_decisions", *scenarios, "--gate", "model", "--jobs", str(jobs))
    table = ("bench.backend_decisions", "--table", "--work", "{work}")
    return Block(name, question, ((*run, "--work", "{work}"),), table, hours=hours)


def _decisions_block(
    name: str, question: str, collects: tuple[tuple[str, ...], ...], hours: float, judge: bool
) -> Block:
    """A block of ``bench.decisions``: each of ``collects`` (``collect``'s arguments) into the
    block's folder, then (``judge``) every kept decision judged again with the code of the run,
    and its table."""
    runs = tuple(("bench.decisions", "collect", *c, "--work", "{work}") for c in collects)
    if judge:
        runs += (("bench.decisions", "judge", "--work", "{work}", "--jobs", "2"),)
    table = ("bench.decisions", "table", "--work", "{work}")
    return Block(name, question, runs, table, hours=hours)


BLOCKS = (
    Block(
        "merge_table",
        "Each shared log cut into 2, 4 and 8 robots, mapped and merged end to end",
        (
            (
                "bench.merge_table",
                "--logs",
                *("freiburg-079", "intel", "csail", "fhw", "aces", "edmonton"),
                *("--robots", "2", "4", "8", "--jobs", "2", "--method", "pivot"),
                *("--work", "{work}"),
            ),
        ),
        ("bench.merge_table", "--table", "--work", "{work}"),
        hours=0.3,
    ),
    Block(
        "summary",
        "The README's table: one row per shared log, from the merging table's runs",
        (),
        ("bench.merge_table", "--summary", "--work", "{work}"),
        work="merge_table",
    ),
    _backend_block(
        "backend_carmen",
        "The back end's loop closures and joins on every shared-log cut, judged by the truth",
        ("--scenarios", *_CARMEN_CUTS),
        hours=0.8,
    ),
    _backend_block(
        "backend_generated",
        "The back end's decisions on generated buildings no model was fitted on (100-119)",
        ("--generated", "100", "20"),
        hours=0.5,
    ),
    _backend_block(
        "backend_generated120",
        "The same on buildings 120-139, never traced (the run at 25aa847 stopped before 139)",
        ("--generated", "120", "20"),
        hours=0.5,
    ),
    _backend_block(
        "backend_generated139",
        "The same on building 139, a cluttered pillar hall, alone",
        ("--generated", "139", "1"),
        hours=0.15,
        jobs=1,
    ),
    _decisions_block(
        "decisions_truth",
        "Placements published wrong and robots merged on maps built at the truth: shared-log "
        "cuts and generated buildings 0-183, judged again with the code of the run",
        (
            (
                *("--source", "generated", "--first", "0", "--count", "184"),
                *("--maps", "truth", "--updates", "3", "--jobs", "2"),
            ),
            (
                *("--source", "carmen", "--logs", "intel", "aces", "fhw", "csail"),
                *("freiburg-079", "--robots", "2", "4", "8", "--maps", "truth"),
            ),
        ),
        hours=5.2,
        judge=True,
    ),
    _decisions_block(
        "decisions_truth_heldout",
        "The same on generated buildings 184-243, held out from every fit and rule",
        (
            (
                *("--source", "generated", "--first", "184", "--count", "60"),
                *("--maps", "truth", "--updates", "3", "--jobs", "1"),
            ),
        ),
        hours=1.3,
        judge=True,
    ),
    _decisions_block(
        "decisions_bags_own",
        "Placements published wrong, robots merged, closures and joins: dense bags, own maps",
        (
            (
                *("--source", "bag", "--bags", "mit-csail", "fr079", "aces"),
                *("--robots", "2", "4", "--maps", "own", "--updates", "8", "--jobs", "2"),
            ),
        ),
        hours=1.0,
        judge=False,
    ),
    _decisions_block(
        "decisions_generated_own",
        "The same on generated buildings 244-273, each robot mapped by its own back end",
        (
            (
                *("--source", "generated", "--first", "244", "--count", "30"),
                *("--maps", "own", "--updates", "3", "--jobs", "2"),
            ),
        ),
        hours=2.0,
        judge=False,
    ),
    _decisions_block(
        "decisions_generated_own_250",
        "The same on generated buildings 250-273, own maps: a later run than 244-273's",
        (
            (
                *("--source", "generated", "--first", "250", "--count", "24"),
                *("--maps", "own", "--updates", "3", "--jobs", "2"),
            ),
        ),
        hours=0.7,
        judge=False,
    ),
)


def blocks_named(names: Sequence[str]) -> list[Block]:
    """The blocks ``names`` (all when empty), or an error naming the unknown ones."""
    known = {block.name: block for block in BLOCKS}
    unknown = sorted(set(names) - set(known))
    if unknown:
        raise SystemExit(f"bench.results: unknown blocks {unknown}; known: {sorted(known)}")
    return [known[name] for name in names] if names else list(BLOCKS)


def _argv(command: tuple[str, ...], folder: Path) -> list[str]:
    return [sys.executable, "-m", *(part.replace("{work}", str(folder)) for part in command)]


def commit() -> str:
    """The checkout's commit, with ``+dirty`` when the tracked files differ from it."""
    head = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True
    ).stdout.strip()
    dirty = subprocess.run(["git", "diff", "--quiet", "HEAD"], cwd=REPO).returncode != 0
    return head + ("+dirty" if dirty else "")


def run(block: Block, work: Path) -> None:
    """Measure ``block`` into ``work/<its folder>`` and record what made it."""
    folder = work / block.folder
    folder.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    for command in block.runs:
        argv = _argv(command, folder)
        print("bench.results:", " ".join(argv[2:]), file=sys.stderr, flush=True)
        subprocess.run(argv, cwd=REPO, check=True)
    record = {
        "commit": commit(),
        "date": datetime.date.today().isoformat(),
        "hours": round((time.perf_counter() - started) / 3600.0, 2),
        "commands": [" ".join(_argv(c, Path("W"))[2:]) for c in block.runs],
    }
    (folder / PROVENANCE).write_text(json.dumps(record, indent=1) + "\n")


def adopt(block: Block, folder: Path, commit_: str, date: str) -> None:
    """Record that ``folder`` holds ``block``'s runs made by hand at ``commit_`` on ``date``
    (the same commands, run before this command existed)."""
    record = {
        "commit": commit_,
        "date": date,
        "hours": None,
        "commands": [" ".join(_argv(c, Path("W"))[2:]) for c in block.runs],
        "adopted": True,
    }
    (folder / PROVENANCE).write_text(json.dumps(record, indent=1) + "\n")


def rendered(block: Block, folder: Path) -> str | None:
    """The block's table and the line saying what made it (None: never run)."""
    source = folder / PROVENANCE
    if not source.is_file():
        return None
    record = json.loads(source.read_text())
    table = subprocess.run(
        _argv(block.table, folder), cwd=REPO, capture_output=True, text=True, check=True
    ).stdout.strip()
    took = f", {record['hours']} h" if record.get("hours") else ""
    owner = next((b for b in BLOCKS if b.folder == block.folder and b.runs), block)
    line = (
        f"*Made by `.venv/bin/python -m bench.results run --only {owner.name}` "
        f"(W/{block.folder}: {'; '.join(record['commands']) or 'the runs above'}) at "
        f"{record['commit']}, {record['date']}{took}.*"
    )
    return f"{table}\n\n{line}"


def replace_block(text: str, name: str, body: str) -> tuple[str, int]:
    """``text`` with every ``<!-- results:NAME -->`` ... ``<!-- /results:NAME -->`` span's
    inside replaced by ``body``; and how many spans there were."""
    pattern = re.compile(
        rf"(<!-- results:{re.escape(name)} -->\n)(?:.*?\n)?(<!-- /results:{re.escape(name)} -->)",
        re.DOTALL,
    )
    return pattern.subn(lambda m: m.group(1) + body + "\n" + m.group(2), text)


def markers(text: str) -> list[str]:
    """The block names ``text`` marks."""
    return re.findall(r"<!-- results:([\w-]+) -->", text)


def render(blocks: Sequence[Block], work: Path, docs: Sequence[Path] = DOCS) -> list[str]:
    """Write each block's table into the docs that mark it; returns a line per block."""
    lines = []
    texts = {path: path.read_text() for path in docs}
    for block in blocks:
        body = rendered(block, work / block.folder)
        if body is None:
            lines.append(f"{block.name}: not run (in {work / block.folder}); left as it is")
            continue
        spans = 0
        for path, text in texts.items():
            texts[path], found = replace_block(text, block.name, body)
            spans += found
        lines.append(f"{block.name}: {spans} table(s) written")
    for path, text in texts.items():
        path.write_text(text)
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in ("run", "render"):
        command = sub.add_parser(name)
        command.add_argument("--only", nargs="*", default=[])
        command.add_argument("--work", type=Path, default=OUTPUT / "results")
    adopted = sub.add_parser("adopt")
    adopted.add_argument("name")
    adopted.add_argument("folder", type=Path)
    adopted.add_argument("--commit", required=True)
    adopted.add_argument("--date", required=True)
    sub.add_parser("list")
    args = parser.parse_args()
    if args.command == "list":
        width = max(len(block.name) for block in BLOCKS)
        for block in BLOCKS:
            took = f"{block.hours} h" if block.hours else f"with {block.folder}"
            print(f"{block.name:{width}s} {took:17s} {block.question}")
    elif args.command == "adopt":
        adopt(blocks_named([args.name])[0], args.folder, args.commit, args.date)
    elif args.command == "run":
        chosen = blocks_named(args.only)
        for block in chosen:
            if block.runs:
                run(block, args.work.resolve())
        print("\n".join(render(chosen, args.work.resolve())))
    else:
        print("\n".join(render(blocks_named(args.only), args.work.resolve())))


if __name__ == "__main__":
    main()
