"""Outputs written whole or not at all (io/outputs.py): what check_output refuses before any
work, and what the staged writers leave when they succeed or fail."""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

import pytest

from multi_robot_mapper.io.outputs import (
    OutputError,
    atomic_write_text,
    check_output,
    staged_entries,
    staged_folder,
    staged_new,
)


def test_check_output_refuses_what_it_would_overwrite_or_cannot_create(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "old.json").write_text("{}")
    (tmp_path / "empty").mkdir()
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    refused = {
        ("file", "new"): "already exists; not overwriting it",
        ("full", "file"): "is a folder, not a file",
        ("file", "folder"): "exists and is not a folder",
        ("full", "folder"): "already holds files (of an earlier run?); pass --overwrite",
        ("file/below", "folder"): "is not a folder",
        ("dangling/below", "folder"): "is a broken link",
    }
    for (name, kind), words in refused.items():
        with pytest.raises(OutputError, match=re.escape(words)):
            check_output(tmp_path / name, kind=kind)
    assert check_output(tmp_path / "full", overwrite=True) == tmp_path / "full"
    assert check_output(tmp_path / "empty") == tmp_path / "empty"
    assert check_output(tmp_path / "file", kind="file") == tmp_path / "file"
    assert check_output(tmp_path / "new" / "deeper" / "out") == tmp_path / "new" / "deeper" / "out"
    # Checking creates nothing: no probe left, no parent made.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling", "empty", "file", "full"]


def test_a_staged_folder_replaces_the_old_one_whole_or_leaves_it(tmp_path: Path) -> None:
    final = tmp_path / "out"
    final.mkdir()
    (final / "old.txt").write_text("old")
    with pytest.raises(KeyboardInterrupt), staged_folder(final) as staging:
        (staging / "new.txt").write_text("new")
        raise KeyboardInterrupt
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # nothing staged is left
    assert [p.name for p in final.iterdir()] == ["old.txt"]
    with staged_folder(final) as staging:
        (staging / "new.txt").write_text("new")
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
    assert [p.name for p in final.iterdir()] == ["new.txt"]  # never a mix of the two runs
    assert stat.S_IMODE(final.stat().st_mode) == 0o755


def test_staged_entries_replace_only_the_entries_made_and_keep_the_rest(tmp_path: Path) -> None:
    (tmp_path / "logs").mkdir()
    (tmp_path / "map.png").write_text("old map")
    (tmp_path / "notes.txt").write_text("the user's")
    with staged_entries(tmp_path) as staging:
        (staging / "map.png").write_text("new map")
        (staging / "logs").mkdir()
        (staging / "logs" / "run.log").write_text("log")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["logs", "map.png", "notes.txt"]
    assert (tmp_path / "map.png").read_text() == "new map"
    assert (tmp_path / "notes.txt").read_text() == "the user's"
    assert [p.name for p in (tmp_path / "logs").iterdir()] == ["run.log"]


def test_a_path_staged_new_is_never_written_over_one_that_appeared(tmp_path: Path) -> None:
    final = tmp_path / "bag"
    with (
        pytest.raises(OutputError, match="appeared while it was being written"),
        staged_new(final) as path,
    ):
        path.write_text("ours")
        final.write_text("theirs")
    assert final.read_text() == "theirs"
    assert [p.name for p in tmp_path.iterdir()] == ["bag"]


def test_an_atomic_file_is_readable_by_all_and_replaces_the_old_one(tmp_path: Path) -> None:
    path = tmp_path / "sub" / "map.json"
    atomic_write_text(path, "first")
    atomic_write_text(path, "second")
    assert path.read_text() == "second"
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o644
    assert [p.name for p in path.parent.iterdir()] == ["map.json"]
