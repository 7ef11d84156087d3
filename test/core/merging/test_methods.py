"""The merging methods by name (core/merging/methods.py): one registry, read-only, and an
unknown name refused naming the known ones."""

from __future__ import annotations

import pytest

from multi_robot_mapper.core.merging.ffs.method import merge_ffs
from multi_robot_mapper.core.merging.joint import merge_joint
from multi_robot_mapper.core.merging.methods import MERGE_METHODS, merge_method


def test_each_method_is_its_function_and_an_unknown_name_lists_the_known_ones() -> None:
    assert list(MERGE_METHODS) == ["pivot", "ffs"]
    assert merge_method("pivot") is merge_joint
    assert merge_method("ffs") is merge_ffs
    with pytest.raises(
        ValueError, match=r"^unknown merging method 'Pivot'; choose one of pivot, ffs$"
    ):
        merge_method("Pivot")
    with pytest.raises(TypeError):
        MERGE_METHODS["mine"] = merge_joint  # type: ignore[index]
