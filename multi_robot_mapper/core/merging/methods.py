"""The merging methods by name, one registry read by the node, the replay and the docs."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Protocol

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.ffs.method import merge_ffs
from multi_robot_mapper.core.merging.joint import merge_joint
from multi_robot_mapper.core.merging.link_graph import MergeResult


class MergeMethod(Protocol):
    def __call__(
        self,
        keyframes: Mapping[str, Sequence[Keyframe]],
        config: MergeConfig | None = ...,
        previous: MergeResult | None = ...,
        *,
        budget: float | None = ...,
    ) -> MergeResult: ...


# pivot: the joint graph of every robot's keyframes, linked where their places match (the
# pivot idea of Amigoni et al. without an order); ffs: the same, then Force Field Simulation.
MERGE_METHODS: Mapping[str, MergeMethod] = MappingProxyType(
    {"pivot": merge_joint, "ffs": merge_ffs}
)


def merge_method(name: str) -> MergeMethod:
    """The merging function called ``name``; ValueError naming the known ones otherwise."""
    try:
        return MERGE_METHODS[name]
    except KeyError:
        known = ", ".join(MERGE_METHODS)
        raise ValueError(f"unknown merging method {name!r}; choose one of {known}") from None
