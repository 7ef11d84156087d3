"""docs/results.md's and the README's tables from the benches, by one command (issue 48).

    .venv/bin/python -m bench.results run [--only NAME ...] [--work bench_output/results]
    .venv/bin/python -m bench.results render [--only NAME ...] [--work ...]
    .venv/bin/python -m bench.results adopt NAME FOLDER --commit C --date D   # a run made by hand
    .venv/bin/python -m bench.results list

Each *block* is one table of the docs: the bench commands that measure it (``run``: each in a
child process from the repository root, into ``WORK/NAME``, which resumes where the benches
resume; ``{data}`` in a command is the shared data, ``../shared/data``) and the command that
prints it as Markdown from what they wrote or printed (each run's output is kept in
``WORK/NAME/run-I.txt``). ``run`` records the commit, date and time taken in
``WORK/NAME/provenance.json``; ``render`` replaces the text between ``<!-- results:NAME -->``
and ``<!-- /results:NAME -->`` in docs/results.md and README.md with the table and a line
saying what made it, at which commit. A block with no run is left as it is, and ``render`` says
so. ``run`` with no ``--only`` runs every block: many hours on two cores (``list`` gives each
block's time as measured). The blocks are defined in ``bench/results_blocks.py``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import re
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from bench.harness import DATA, OUTPUT
from bench.results_blocks import BLOCKS, Block

__all__ = ["BLOCKS", "Block"]

REPO = Path(__file__).resolve().parent.parent
DOCS = (REPO / "docs" / "results.md", REPO / "README.md")
PROVENANCE = "provenance.json"


def blocks_named(names: Sequence[str]) -> list[Block]:
    """The blocks ``names`` (all when empty), or an error naming the unknown ones."""
    known = {block.name: block for block in BLOCKS}
    unknown = sorted(set(names) - set(known))
    if unknown:
        raise SystemExit(f"bench.results: unknown blocks {unknown}; known: {sorted(known)}")
    return [known[name] for name in names] if names else list(BLOCKS)


def _argv(command: tuple[str, ...], folder: Path, data: Path = DATA) -> list[str]:
    """``python -m`` and ``command`` with ``{work}`` the block's folder and ``{data}`` the
    shared data (``../shared/data``)."""
    return [
        sys.executable,
        "-m",
        *(part.replace("{work}", str(folder)).replace("{data}", str(data)) for part in command),
    ]


def _shown(command: tuple[str, ...]) -> str:
    """``command`` as the docs show it: the block's folder ``W``, the data ``../shared/data``."""
    return " ".join(_argv(command, Path("W"), Path("../shared/data"))[2:])


def _tee(argv: list[str], log: Path) -> None:
    """Run ``argv`` from the repository root, its output both shown and kept in ``log`` (the
    tables of benches that only print are read from there)."""
    with (
        log.open("w") as kept,
        subprocess.Popen(argv, cwd=REPO, stdout=subprocess.PIPE, text=True) as child,
    ):
        for line in child.stdout or ():
            sys.stdout.write(line)
            kept.write(line)
    if child.returncode:
        raise subprocess.CalledProcessError(child.returncode, argv)


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
    for index, command in enumerate(block.runs):
        argv = _argv(command, folder)
        print("bench.results:", " ".join(argv[2:]), file=sys.stderr, flush=True)
        _tee(argv, folder / f"run-{index}.txt")
    record = {
        "commit": commit(),
        "date": datetime.date.today().isoformat(),
        "hours": round((time.perf_counter() - started) / 3600.0, 3),
        "commands": [_shown(c) for c in block.runs],
    }
    (folder / PROVENANCE).write_text(json.dumps(record, indent=1) + "\n")


def adopt(block: Block, folder: Path, commit_: str, date: str) -> None:
    """Record that ``folder`` holds ``block``'s runs made by hand at ``commit_`` on ``date``
    (the same commands, run before this command existed)."""
    record = {
        "commit": commit_,
        "date": date,
        "hours": None,
        "commands": [_shown(c) for c in block.runs],
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
    hours = record.get("hours") or 0.0
    took = f", {hours} h" if hours >= 0.1 else f", {round(hours * 60.0, 1)} min" if hours else ""
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
