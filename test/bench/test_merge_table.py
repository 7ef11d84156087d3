"""bench/merge_table.py's table of the dense bags (issue 47): a row made from known figures."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench import merge_table


def _row(robots: int) -> dict[str, object]:
    per_robot = {
        "robot1": {"reported_unmerged": False, "ate_own_frame_m": 0.08},
        "robot2": {"reported_unmerged": False, "ate_own_frame_m": 0.12},
        "robot3": {"reported_unmerged": True, "ate_own_frame_m": None},
    }
    metrics = {
        "robots": per_robot,
        "robots_merged": 1,
        "robots_total": 3,
        "scans_unposed": 25,
        "scans_total": 1000,
        "ate_rmse_m": 0.0912,
    }
    stats = {"total_s": 123.4}
    return {"log": "aces.bag", "robots": robots, "metrics": metrics, "stats": stats}


def test_a_bag_row_counts_right_claimed_and_unmerged_and_the_worst_own_frame_ate() -> None:
    row = merge_table.bag_row({**_row(3), "links_judged": (1, 0, 4, 30)})
    assert row == "| aces.bag | 3 | 1 / 2 / 1 | 0.120 | 2.5 % | 0.091 | 123 | 1 (0) / 4 / 30 |"


def test_a_failed_bag_run_says_why_in_its_row() -> None:
    row = merge_table.bag_row({"log": "fr079.bag", "robots": 2, "error": "mrm replay exited 1"})
    assert row.startswith("| fr079.bag | 2 | failed: mrm replay exited 1 |")


def test_the_bag_table_keeps_only_the_bags(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log_row = {**_row(2), "log": "intel"}
    saved = tmp_path / "merge_table.json"
    saved.write_text(json.dumps({"rows": [log_row, _row(2)]}))
    merge_table.print_table(saved, summary=False, bags=True)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("| bag | robots | right / claimed / unmerged |")
    assert [line.split(" | ")[0] for line in lines[2:]] == ["| aces.bag"]
