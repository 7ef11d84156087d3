"""bench/ is a package: its shared harness and every bench script import with plain package
imports (``python -m bench.NAME`` from the repository root), none through sys.path tricks."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest
from conftest import REPO

SCRIPTS = sorted(p.stem for p in (REPO / "bench").glob("*.py") if p.stem != "__init__")
# Imported by a script at the top, and not among the test environment's packages.
OPTIONAL = {"building_gallery": "matplotlib"}


@pytest.mark.parametrize("script", SCRIPTS)
def test_every_bench_module_imports_as_part_of_the_package(script: str) -> None:
    optional = OPTIONAL.get(script)
    if optional is not None:
        pytest.importorskip(optional, reason=f"bench/{script}.py needs {optional}")
    path_before = list(sys.path)
    module = importlib.import_module(f"bench.{script}")
    assert Path(module.__file__ or "").resolve() == REPO / "bench" / f"{script}.py"
    assert sys.path == path_before  # importing it changed no search path


def test_no_bench_script_puts_a_folder_on_the_import_path() -> None:
    offenders = [
        name
        for name in SCRIPTS
        if "sys.path" in (REPO / "bench" / f"{name}.py").read_text(encoding="utf-8")
    ]
    assert offenders == []


def test_the_harness_finds_a_log_where_the_shared_data_is() -> None:
    harness = importlib.import_module("bench.harness")
    assert harness.carmen_log("intel") == harness.DATA / "carmen" / "intel.log.gz"
    assert harness.present_logs(["no-such-log"]) == []
    # The judgement is the confidence's own tolerance: 0.29 m is right, 0.31 m is not.
    assert harness.right((0.29, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert not harness.right((0.31, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert not harness.right((0.0, 0.0, 0.09), (0.0, 0.0, 0.0))  # 5.2 deg


def test_a_log_is_cut_into_runs_as_mrm_import_carmen_cuts_it() -> None:
    harness = importlib.import_module("bench.harness")
    split_runs = importlib.import_module("multi_robot_mapper.io.recordings").split_runs
    scans = list(range(10))
    runs = harness.equal_runs(scans, 3, 1)  # the issue-13 benches' cut: 3 scans each
    assert runs == [[0, 1, 2], [2, 3, 4, 5], [5, 6, 7, 8]]
    assert split_runs(10, 3, 1) == [(0, 3), (2, 7), (6, 10)]


def test_a_test_helper_is_loaded_from_test_without_touching_the_path() -> None:
    harness = importlib.import_module("bench.harness")
    streams = harness.test_helper("hostile_streams")
    assert callable(streams.hostile_stream)
    assert harness.test_helper("hostile_streams") is streams
