"""Known order: the paper's three methods (Amigoni Sec. IV)."""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.merging.compose import as_map, fuse_maps
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.pairwise import Link, link_of, match_maps
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass
class OrderedMerge:
    """The result of merging an ordered list of maps; ``map`` is the first map's frame."""

    method: str
    placements: list[Pose | None]  # T_map_i (x, y, theta) per map; None = never integrated
    links: list[Link]  # every INTEGRATE call (robots named by their index)
    segments: FloatArray  # (M, 4) final map S_1..n
    segment_robot: IntArray  # (M,) index of the map each segment came from
    integrations: int  # pairs of maps INTEGRATE was run on (the paper's count)
    elapsed_s: float


def _fused(
    segments: FloatArray,
    owner: IntArray,
    T_map_i: FloatArray,
    segments_i: FloatArray,
    i: int,
    config: MergeConfig,
) -> tuple[FloatArray, IntArray]:
    """The global map so far fused with map ``i`` placed by ``T_map_i`` (Amigoni Alg. 5)."""
    moved = se2.transform_segments(T_map_i, segments_i)
    owned = np.full(len(moved), i, dtype=np.int64)
    return fuse_maps(
        segments, owner, moved, owned, pair_tolerance(config.integrate), config.fusion_tolerance
    )


def _ordered_result(
    method: str,
    count: int,
    placed: Mapping[int, FloatArray],
    links: list[Link],
    segments: FloatArray,
    owner: IntArray,
    started: float,
) -> OrderedMerge:
    placements: list[Pose | None] = [
        se2.pose_from_matrix(placed[i]) if i in placed else None for i in range(count)
    ]
    return OrderedMerge(
        method, placements, links, segments, owner, len(links), time.perf_counter() - started
    )


def merge_sequential(maps: Sequence[FloatArray], config: MergeConfig | None = None) -> OrderedMerge:
    """Sequential method (IV-A): S_1,2 = INTEGRATE(S_1, S_2), S_1,2,3 = INTEGRATE(S_1,2, S_3)...

    A map whose integration is not valid is left out (``None``) and the next one tried.
    """
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    clean = [as_map(m) for m in maps]
    if not clean:
        return OrderedMerge("sequential", [], [], np.zeros((0, 4)), np.zeros(0, np.int64), 0, 0.0)
    segments = clean[0]
    owner = np.zeros(len(segments), dtype=np.int64)
    placed: dict[int, FloatArray] = {0: np.eye(3)}
    links: list[Link] = []
    for i in range(1, len(clean)):
        result = match_maps(segments, clean[i], config)
        links.append(link_of("0", str(i), result))
        if not result.valid:
            continue
        placed[i] = result.matrix
        segments, owner = _fused(segments, owner, placed[i], clean[i], i, config)
    return _ordered_result("sequential", len(clean), placed, links, segments, owner, started)


@dataclasses.dataclass
class _Node:
    """A partial map of the tree method: segments in its first member's frame."""

    segments: FloatArray
    owner: IntArray
    members: dict[int, FloatArray]  # map index -> T_node_map
    first: int


def merge_tree(maps: Sequence[FloatArray], config: MergeConfig | None = None) -> OrderedMerge:
    """Tree method (IV-B): each map integrated with the next, level after level, until one.

    Level 0 is the maps; level l+1 integrates every node of level l with the next one
    (n(n-1)/2 INTEGRATE calls). A failed integration keeps the left node as it is, so a map
    missing from one node can still arrive through the next.
    """
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    clean = [as_map(m) for m in maps]
    if not clean:
        return OrderedMerge("tree", [], [], np.zeros((0, 4)), np.zeros(0, np.int64), 0, 0.0)
    nodes = [
        _Node(m, np.full(len(m), i, dtype=np.int64), {i: np.eye(3)}, i) for i, m in enumerate(clean)
    ]
    links: list[Link] = []
    while len(nodes) > 1:
        level: list[_Node] = []
        for left, right in itertools.pairwise(nodes):
            result = match_maps(left.segments, right.segments, config)
            links.append(link_of(str(left.first), str(right.first), result))
            if not result.valid:
                level.append(left)
                continue
            T_left_right = result.matrix
            members = dict(left.members)
            for index, T_right_map in right.members.items():
                members.setdefault(index, T_left_right @ T_right_map)
            moved = se2.transform_segments(T_left_right, right.segments)
            segments, owner = fuse_maps(
                left.segments,
                left.owner,
                moved,
                right.owner,
                pair_tolerance(config.integrate),
                config.fusion_tolerance,
            )
            level.append(_Node(segments, owner, members, left.first))
        nodes = level
    root = nodes[0]
    return _ordered_result(
        "tree", len(clean), root.members, links, root.segments, root.owner, started
    )


def merge_pivot(maps: Sequence[FloatArray], config: MergeConfig | None = None) -> OrderedMerge:
    """Pivot method (IV-C, Algorithm 6), the cleaner variant.

    t_i-1,i = INTEGRATE(S_i-1, S_i) (two partial maps of similar size), t_1,i = t_1,i-1 t_i-1,i,
    and S_1..i = fusion of S_1..i-1 with S_i moved by t_1,i (S_i, not S_i-1,i: each map's
    segments are fused once). When S_i-1 was left out, the last map placed is the pivot.
    """
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    clean = [as_map(m) for m in maps]
    if not clean:
        return OrderedMerge("pivot", [], [], np.zeros((0, 4)), np.zeros(0, np.int64), 0, 0.0)
    segments = clean[0]
    owner = np.zeros(len(segments), dtype=np.int64)
    placed: dict[int, FloatArray] = {0: np.eye(3)}
    links: list[Link] = []
    pivot = 0
    for i in range(1, len(clean)):
        result = match_maps(clean[pivot], clean[i], config)
        links.append(link_of(str(pivot), str(i), result))
        if not result.valid:
            continue
        placed[i] = placed[pivot] @ result.matrix  # t_1,i = t_1,pivot t_pivot,i
        segments, owner = _fused(segments, owner, placed[i], clean[i], i, config)
        pivot = i
    return _ordered_result("pivot", len(clean), placed, links, segments, owner, started)
