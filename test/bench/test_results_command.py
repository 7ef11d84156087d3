"""bench/results.py: the docs' tables written by one command from the benches' outputs."""

from __future__ import annotations

import json
import re
from pathlib import Path

from conftest import REPO

from bench import results
from bench.merge_table import summary_rows


def test_every_marked_table_in_the_docs_is_a_known_block_and_is_closed() -> None:
    known = {block.name for block in results.BLOCKS}
    for path in results.DOCS:
        text = path.read_text(encoding="utf-8")
        names = results.markers(text)
        assert set(names) <= known, f"{path.name}: unknown blocks {set(names) - known}"
        for name in names:
            assert text.count(f"<!-- /results:{name} -->") == names.count(name), (path, name)


def test_every_block_runs_and_prints_a_bench_module() -> None:
    benches = {p.stem for p in (REPO / "bench").glob("*.py")}
    for block in results.BLOCKS:
        for command in block.runs:  # a bench, or mrm itself
            module = command[0]
            assert module == "multi_robot_mapper.cli.main" or (
                module.startswith("bench.") and module.removeprefix("bench.") in benches
            )
        module = block.table[0]
        assert module.startswith("bench.") and module.removeprefix("bench.") in benches
        owners = [b for b in results.BLOCKS if b.folder == block.folder and b.runs]
        assert owners, f"{block.name}: no block runs what it prints"


def test_run_records_what_made_a_table_and_render_writes_it_between_the_markers(
    tmp_path: Path,
) -> None:
    work = tmp_path / "work"
    (work / "toy").mkdir(parents=True)
    (work / "toy" / "table.json").write_text(json.dumps({"cell": 42}))
    toy = results.Block(
        "toy",
        "a toy table",
        (("bench.results", "list"),),
        ("json.tool", "{work}/table.json"),
    )
    results.run(toy, work)
    record = json.loads((work / "toy" / results.PROVENANCE).read_text())
    assert record["commands"] == ["bench.results list"]
    assert "merge_table" in (work / "toy" / "run-0.txt").read_text()  # what it printed, kept
    assert re.fullmatch(r"[0-9a-f]{4,}(\+dirty)?", record["commit"])
    doc = tmp_path / "doc.md"
    doc.write_text("before\n<!-- results:toy -->\nold table\n<!-- /results:toy -->\nafter\n")
    untouched = tmp_path / "other.md"
    untouched.write_text("no marker here\n")
    lines = results.render([toy], work, docs=[doc, untouched])
    assert lines == ["toy: 1 table(s) written"]
    text = doc.read_text()
    assert "old table" not in text and '"cell": 42' in text
    assert text.startswith("before\n<!-- results:toy -->\n") and text.endswith(
        "<!-- /results:toy -->\nafter\n"
    )
    assert f"at {record['commit']}" in text
    assert untouched.read_text() == "no marker here\n"


def test_an_empty_span_is_filled() -> None:
    text, spans = results.replace_block("a\n<!-- results:x -->\n<!-- /results:x -->\n", "x", "T")
    assert spans == 1 and text == "a\n<!-- results:x -->\nT\n<!-- /results:x -->\n"


def test_a_block_never_run_is_left_as_it_is(tmp_path: Path) -> None:
    doc = tmp_path / "doc.md"
    doc.write_text("<!-- results:merge_table -->\nkept\n<!-- /results:merge_table -->\n")
    block = results.blocks_named(["merge_table"])[0]
    lines = results.render([block], tmp_path, docs=[doc])
    assert "not run" in lines[0]
    assert "kept" in doc.read_text()


def _metrics(merged: int, total: int, ate: float, unposed: int, own: list[float]) -> dict:
    return {
        "robots_merged": merged,
        "robots_total": total,
        "ate_rmse_m": ate,
        "pair_success": 0.5,
        "scans_unposed": unposed,
        "scans_total": 200,
        "robots": {f"r{i}": {"ate_own_frame_m": a} for i, a in enumerate(own)},
    }


def test_the_summary_row_of_a_log_takes_each_cut_from_its_own_run() -> None:
    rows = [
        {"log": "intel", "robots": 2, "metrics": _metrics(2, 2, 0.1, 2, [0.05, 0.07])},
        {"log": "intel", "robots": 4, "metrics": _metrics(1, 4, 0.3, 20, [0.2, 0.1, 0.1, 0.1])},
        {"log": "intel", "robots": 8, "error": "replay failed"},
    ]
    (line,) = summary_rows(rows)
    cells = [cell.strip() for cell in line.strip("|").split("|")]
    assert cells[0] == "intel"
    assert cells[3] == "10.0 % / 1.0 %"  # unposed, 4 then 2 robots
    assert cells[4] == "0.20"  # the worst own-frame ATE of the 2- and 4-robot cuts
    assert cells[5] == "2/2, 1/4, —"  # the 8-robot run failed
    assert cells[6] == "0.100, —, —"  # one robot merged is no merged ATE


def test_a_table_of_a_bench_that_only_prints_is_read_from_its_kept_output(tmp_path: Path) -> None:
    from bench import results_tables

    (tmp_path / "provenance.json").write_text(
        json.dumps({"commands": ["bench.frontend_throughput --repeat 3"]})
    )
    (tmp_path / "run-0.txt").write_text(
        "front-end throughput, one core (scans/s; best / median of passes)\n"
        "    180 beams:    2080 best,    1971 median  (target >= 2000: MISSES)  [real]\n"
        "   1081 beams:     910 best,     845 median  (target >= 500: meets)  [simulated]\n"
    )
    rows = results_tables.throughput(tmp_path)
    assert rows[0].startswith("| scans | target | measured (median of 3 passes)")
    assert rows[2] == "| 180 beams (real, intel) | ≥ 2000 scans/s | 1971 scans/s | 2080 scans/s |"
    assert rows[3].split(" | ")[2] == "845 scans/s"
