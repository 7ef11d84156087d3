"""The offline pipeline's choices (core/pipeline.py): the replay's methods in one list, and a
method or a request it cannot serve refused by name before any work."""

from __future__ import annotations

import pytest

from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.merging.methods import MERGE_METHODS
from multi_robot_mapper.core.pipeline import METHODS, require_method, run_offline


def test_the_methods_are_the_two_that_merge_nothing_then_the_merging_ones() -> None:
    assert list(METHODS) == ["reference", "local", *MERGE_METHODS]
    for method in METHODS:
        require_method(method)
    with pytest.raises(
        ValueError, match=r"^unknown method 'icp'; choose one of reference, local, "
    ):
        require_method("icp")


def test_a_request_the_method_cannot_serve_is_refused_before_any_scan_is_read() -> None:
    def never(_: object) -> None:
        raise AssertionError("no snapshot of a method that merges nothing")

    for method in ("reference", "local"):
        with pytest.raises(ValueError, match=r"snapshots need a merging method \(pivot, ffs\)"):
            run_offline({"robot1": []}, method, ExtractionConfig(), snapshots=never)
    with pytest.raises(ValueError, match="unknown method 'Pivot'"):
        run_offline({}, "Pivot", ExtractionConfig())
    empty = run_offline({}, "reference", ExtractionConfig())
    assert empty.robots == [] and empty.map_segments.shape == (0, 4)
