"""The blocks of bench/results.py: each table of the docs it writes, with the bench commands
that measure it and the command that prints it (no ``main``; imported by ``bench.results``)."""

from __future__ import annotations

import dataclasses

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
                *("--source", "bag", "--bags", "mit-csail", "fr079", "aces", "intel"),
                *("--robots", "2", "4", "8", "--maps", "own", "--updates", "8", "--jobs", "2"),
            ),
        ),
        hours=2.5,
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


def _printed(name: str, question: str, runs: tuple[tuple[str, ...], ...], **kw: object) -> Block:
    """A block of benches that only print: ``bench.results_tables TABLE`` reads their output
    (``kw``: ``table``, that printer's name, the block's by default; and Block's own)."""
    table = str(kw.pop("table", name))
    printer = ("bench.results_tables", table, "--work", "{work}")
    return Block(name, question, runs, printer, **kw)  # type: ignore[arg-type]


def _ffs(log: str, distortion: str, seeds: int) -> tuple[str, ...]:
    figure = f"{{work}}/ffs_{log}_{distortion.replace(',', '_')}.png"  # not the docs' figure
    return (
        "bench.ffs_bench",
        "--log",
        log,
        "--seeds",
        str(seeds),
        "--distortion",
        distortion,
        "--figure",
        figure,
    )


MEASURED = (
    _printed(
        "frontend",
        "Segments per scan on the four sparse logs (mrm frontend)",
        tuple(
            ("multi_robot_mapper.cli.main", "frontend", f"{{data}}/carmen/{log}.log.gz")
            for log in ("intel", "aces", "fhw", "csail")
        ),
        hours=0.01,
    ),
    _printed(
        "frontend_throughput",
        "The front end's scans/s on one core at 180 and 1081 beams (make bench)",
        (("bench.frontend_throughput", "--repeat", "5"),),
        table="throughput",
        hours=0.01,
    ),
    _printed(
        "merge_speed",
        "Two ~100-segment partial maps merged with no guess: time and placement error",
        tuple(
            ("bench.merge_speed", "--repeats", "15", *more)
            for more in (
                (),
                ("--overlap", "10"),
                ("--log", "aces"),
                ("--log", "fhw"),
                ("--log", "csail"),
            )
        ),
        hours=0.02,
    ),
    _printed(
        "ffs_seeds",
        "FFS re-convergence per seed at the paper's distortion (±0.30 m, ±20°), six logs",
        tuple(
            _ffs(log, "0.30,20", 10)
            for log in ("intel", "freiburg-079", "csail", "aces", "fhw", "edmonton")
        ),
        hours=0.1,
    ),
    _printed(
        "ffs_distortions",
        "FFS re-convergence by distortion: where it stops working",
        (
            *(_ffs("intel", d, 10) for d in ("0.02,1", "0.10,5", "0.50,30", "1.00,45")),
            *(
                _ffs(log, d, 3)
                for log in ("freiburg-079", "csail")
                for d in ("0.02,1", "0.10,5", "0.50,30", "1.00,45")
            ),
        ),
        hours=0.2,
    ),
    Block(
        "confidence",
        "The match confidence held out by log (fit_confidence collect, then fit)",
        (
            ("bench.fit_confidence", "collect", "--jobs", "2", "--out", "{work}"),
            ("bench.fit_confidence", "fit", "--out", "{work}"),
        ),
        ("bench.results_tables", "confidence", "--work", "{work}"),
        hours=0.2,
    ),
    _printed(
        "confidence_judged",
        "The same, precision judged (pairs wrong only by the reference counted right)",
        (),
        work="confidence",
    ),
    _printed(
        "local_table",
        "Each log cut into 4 and 2 robots, mapped robot by robot, closures judged",
        (
            (
                "bench.local_table",
                *("--logs", "freiburg-079", "intel", "fhw", "aces", "csail", "edmonton"),
                *("--robots", "4", "2", "--jobs", "1", "--work", "{work}"),
            ),
        ),
        table="printed",
        hours=0.4,
    ),
    _printed(
        "merge_alone",
        "Merging alone on maps built at the reference poses (joint merger, every place)",
        (
            (
                "bench.merge_speed",
                "--joint",
                "--split",
                "2",
                "4",
                "8",
                "--logs",
                "intel",
                "aces",
                "fhw",
                "csail",
            ),
            ("bench.merge_speed", "--joint", "--split", "2", "--logs", "freiburg-079", "edmonton"),
        ),
        hours=0.6,
    ),
)
BLOCKS = (*BLOCKS, *MEASURED)
