"""Unknown order: pairwise links, maximum-value spanning tree, placement, global map."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.correlation import Drawing
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.merging.compose import as_map, fuse_maps
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.free_space import (
    ViewSource,
    free_space_conflict,
    no_views,
    seen_through_allowance,
    view_source,
)
from multi_robot_mapper.core.merging.pairwise import (
    Link,
    LinkTests,
    MapSignature,
    PairRecord,
    draw_map,
    link_of,
    link_tests,
    match_maps,
    no_match,
    reuse_change,
)
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.segment_map import SegmentMap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass
class MergeResult:
    """Every robot frame in ``map`` (or unmerged), the links used and the global map."""

    robots: list[str]  # sorted; segment_robot indexes this list
    placements: dict[str, Pose | None]  # T_map_robot as (x, y, theta); None = unmerged
    reference: str | None  # the robot whose map frame is `map` (None: no robots)
    links: list[Link]  # the spanning tree's edges, the transforms composed
    pairs: dict[tuple[str, str], PairRecord]  # every pair's result (a < b), reusable
    segments: FloatArray  # (M, 4) fused global map in `map`
    segment_robot: IntArray  # (M,) index into robots of each segment's owner
    timings: dict[str, float]  # seconds: pairs_s, tree_s, fusion_s, total_s
    # pairs_computed, pairs_reused, integrate_calls, links_valid, cycle_conflicts
    stats: dict[str, int]
    # The joint graph's (method pivot; empty when each robot was placed as one rigid map):
    # robot -> (K, 3) T_map_keyframe of its merged keyframes, and their keyframe indices
    keyframe_poses: dict[str, FloatArray] = dataclasses.field(default_factory=dict)
    keyframe_index: dict[str, IntArray] = dataclasses.field(default_factory=dict)
    # robot -> piece -> T_map_piece (piece 0: the robot's map frame, as ``placements``)
    frames: dict[str, dict[int, Pose]] = dataclasses.field(default_factory=dict)
    # (M,) the keyframe (index in its robot's map) owning each global map segment
    segment_keyframe: IntArray | None = None
    # what the next update reuses (joint graph: every place match), and each pair of maps'
    # consistent links with the verdict on them
    state: object | None = None
    verdicts: dict[object, object] = dataclasses.field(default_factory=dict)
    # what the next update's refinement after the graph resumes from (ffs: FfsState)
    refinement: object | None = None
    # robot -> the probability that its placement (its map frame's) is right (placed robots;
    # joint graph); robot -> piece -> the same of each placed piece (as ``frames``); robot ->
    # why its map frame is not placed (unmerged robots)
    probabilities: dict[str, float] = dataclasses.field(default_factory=dict)
    frame_probabilities: dict[str, dict[int, float]] = dataclasses.field(default_factory=dict)
    unmerged_reasons: dict[str, str] = dataclasses.field(default_factory=dict)

    @property
    def unmerged(self) -> list[str]:
        """Robots with no valid chain of links to the reference."""
        return [r for r in self.robots if self.placements[r] is None]

    def matrix(self, robot: str) -> FloatArray | None:
        """T_map_robot as a 3x3 matrix, or None when the robot is unmerged."""
        pose = self.placements.get(robot)
        return None if pose is None else se2.matrix_from_pose(*pose)

    def keyframe_maps(self, robot: str) -> list[tuple[int, FloatArray, FloatArray]]:
        """Each merged keyframe of ``robot`` with ``T_map_keyframe`` (3,) and the global map
        segments it owns, in its own frame (every keyframe the joint graph placed, those owning
        no segment included; empty without keyframes in the result)."""
        index = self.keyframe_index.get(robot)
        if index is None or self.segment_keyframe is None:
            return []
        poses = self.keyframe_poses[robot]
        mine = self.segment_robot == self.robots.index(robot)
        owner = np.asarray(self.segment_keyframe)[mine]
        rows = np.searchsorted(index, owner)
        local = se2.inverse_transform_segments_each(poses[rows], self.segments[mine])
        order = np.argsort(rows, kind="stable")
        bounds = np.searchsorted(rows[order], np.arange(len(index) + 1))
        return [
            (int(k), poses[r], local[order[bounds[r] : bounds[r + 1]]]) for r, k in enumerate(index)
        ]


def pair_links(
    maps: Mapping[str, FloatArray],
    config: MergeConfig,
    previous: Mapping[tuple[str, str], PairRecord] | None = None,
    views: ViewSource | None = None,
) -> tuple[dict[tuple[str, str], PairRecord], int]:
    """INTEGRATE every pair (a, b) with a < b, reusing earlier results where maps barely
    changed (:meth:`MapSignature.close_to`), each judged on free space where ``views`` has
    the robots' views. Returns the records and the INTEGRATE calls."""
    view = views or no_views
    robots = sorted(maps)
    segment_maps = {r: SegmentMap.of(maps[r]) for r in robots}
    signatures = {r: MapSignature.of(segment_maps[r]) for r in robots}
    records: dict[tuple[str, str], PairRecord] = {}
    calls = 0
    drawings: dict[str, Drawing] = {}

    def drawing(robot: str) -> Drawing:  # once per robot, on first use
        if robot not in drawings:
            drawings[robot] = draw_map(segment_maps[robot], view(robot), config.free_drawing())
        return drawings[robot]

    for i, a in enumerate(robots):
        for b in robots[i + 1 :]:
            old = None if previous is None else previous.get((a, b))
            if (
                old is not None
                and signatures[a].close_to(old.signature_a, reuse_change(config))
                and signatures[b].close_to(old.signature_b, reuse_change(config))
            ):
                records[(a, b)] = dataclasses.replace(old, reused=True)
                continue
            if len(maps[a]) and len(maps[b]):
                drawn = (drawing(a), drawing(b))
                pair = (segment_maps[a], segment_maps[b])
                match = match_maps(*pair, config, view(a), view(b), drawn)
            else:
                match = no_match()
            calls += match.integrate_calls
            records[(a, b)] = PairRecord(link_of(a, b, match), signatures[a], signatures[b], False)
    return records, calls


JoinCheck = Callable[[Link, Mapping[str, FloatArray], Mapping[str, FloatArray], FloatArray], bool]


def spanning_tree(
    robots: Sequence[str],
    links: Sequence[Link],
    previous_edges: set[tuple[str, str]] | None = None,
    margin: float = 0.0,
    joins: JoinCheck | None = None,
) -> list[Link]:
    """Maximum-value spanning forest of the valid links (Kruskal).

    Edges of the previous tree count as ``(1 + margin)`` times their value, so a new link
    replaces one only when clearly better. Ties break on the robot names: the result does not
    depend on the order the robots or links come in. ``joins(link, group_a, group_b,
    T_ga_gb)``, when given, may refuse a link that would join two groups of robots (each
    ``robot -> T_group_robot``; ``T_ga_gb`` places group b in group a): the next link is
    tried instead.
    """
    kept = previous_edges or set()

    def weight(link: Link) -> float:
        key = (link.robot_a, link.robot_b)
        return link.value * (1.0 + margin) if key in kept else link.value

    order = sorted(
        (lk for lk in links if lk.valid), key=lambda lk: (-weight(lk), lk.robot_a, lk.robot_b)
    )
    parent = {r: r for r in robots}
    groups: dict[str, dict[str, FloatArray]] = {r: {r: np.eye(3)} for r in robots}

    def root(r: str) -> str:
        while parent[r] != r:
            parent[r] = parent[parent[r]]
            r = parent[r]
        return r

    tree: list[Link] = []
    for link in order:
        ra, rb = root(link.robot_a), root(link.robot_b)
        if ra == rb:
            continue
        group_a, group_b = groups[ra], groups[rb]
        T_ga_gb = group_a[link.robot_a] @ link.matrix @ se2.invert(group_b[link.robot_b])
        if joins is not None and not joins(link, group_a, group_b, T_ga_gb):
            continue
        if ra < rb:  # the smaller name stays the root; the other group moves into its frame
            group_a.update({r: T_ga_gb @ T for r, T in group_b.items()})
            parent[rb] = ra
            del groups[rb]
        else:
            T_gb_ga = se2.invert(T_ga_gb)
            group_b.update({r: T_gb_ga @ T for r, T in group_a.items()})
            parent[ra] = rb
            del groups[ra]
        tree.append(link)
    return tree


def free_space_join(
    maps: Mapping[str, FloatArray], views: ViewSource, tests: LinkTests
) -> JoinCheck:
    """A :func:`spanning_tree` join check: two groups of robots join only if no robot's walls
    lie in the free space any robot of the other group saw (as a link is judged, ``tests``:
    beyond the link's allowance, ``link_max_seen_through`` or that fraction of its value).

    A pair's own link was judged on the two maps alone; a group has more viewpoints. A
    look-alike place can fit one robot's map and still cross rooms a third robot saw empty.
    """

    def joins(
        link: Link,
        group_a: Mapping[str, FloatArray],
        group_b: Mapping[str, FloatArray],
        T_ga_gb: FloatArray,
    ) -> bool:
        if len(group_a) == 1 and len(group_b) == 1:
            return True  # exactly the pair match_maps judged
        allowed = seen_through_allowance(link.value, *tests.seen_through)
        for x, T_ga_x in group_a.items():
            for y, T_gb_y in group_b.items():
                view_x, view_y = views(x), views(y)
                if view_x is None and view_y is None:
                    continue
                T_x_y = se2.invert(T_ga_x) @ T_ga_gb @ T_gb_y
                through = free_space_conflict(
                    maps[x], view_x, maps[y], view_y, T_x_y, tests.free_space
                )
                if through > allowed:
                    return False
        return True

    return joins


def _components(robots: Sequence[str], tree: Sequence[Link]) -> list[list[str]]:
    adjacency: dict[str, list[str]] = {r: [] for r in robots}
    for link in tree:
        adjacency[link.robot_a].append(link.robot_b)
        adjacency[link.robot_b].append(link.robot_a)
    seen: set[str] = set()
    groups: list[list[str]] = []
    for start in robots:
        if start in seen:
            continue
        group, stack = [], [start]
        seen.add(start)
        while stack:
            r = stack.pop()
            group.append(r)
            for n in adjacency[r]:
                if n not in seen:
                    seen.add(n)
                    stack.append(n)
        groups.append(sorted(group))
    return groups


def choose_reference(
    robots: Sequence[str],
    tree: Sequence[Link],
    lengths: Mapping[str, float],
    previous: str | None = None,
) -> str:
    """The largest map (total segment length) in the largest linked group of robots.

    ``previous`` (the last run's reference) is kept while it is in a group as large as any,
    so the ``map`` frame does not jump between runs.
    """
    groups = _components(robots, tree)
    size = max(len(g) for g in groups)
    if (
        previous is not None
        and previous in robots
        and len(next(g for g in groups if previous in g)) == size
    ):
        return previous
    best = min(
        (g for g in groups if len(g) == size), key=lambda g: (-sum(lengths[r] for r in g), g[0])
    )
    return min(best, key=lambda r: (-lengths[r], r))


def place(reference: str, robots: Sequence[str], tree: Sequence[Link]) -> dict[str, FloatArray]:
    """T_map_robot of every robot linked to ``reference`` (the frame `map`), composed along
    the tree (breadth first, so the order of placing is also the order of fusing)."""
    adjacency: dict[str, list[tuple[str, FloatArray]]] = {r: [] for r in robots}
    for link in tree:
        T_a_b = link.matrix
        adjacency[link.robot_a].append((link.robot_b, T_a_b))
        adjacency[link.robot_b].append((link.robot_a, se2.invert(T_a_b)))
    placed: dict[str, FloatArray] = {reference: np.eye(3)}
    queue = [reference]
    while queue:
        a = queue.pop(0)
        for b, T_a_b in sorted(adjacency[a], key=lambda item: item[0]):
            if b not in placed:
                placed[b] = placed[a] @ T_a_b
                queue.append(b)
    return placed


def cycle_conflicts(
    placed: Mapping[str, FloatArray],
    links: Sequence[Link],
    distance: float = 0.3,
    angle: float = np.radians(3.0),
) -> list[Link]:
    """Valid links between placed robots that disagree with the placements (by more than
    ``distance`` or ``angle``): a cycle of links that does not close. Some link on that cycle
    is wrong (self-similar buildings match at wrong offsets); reported, not resolved."""
    out = []
    for link in links:
        if not (link.valid and link.robot_a in placed and link.robot_b in placed):
            continue
        T_a_b = se2.invert(placed[link.robot_a]) @ placed[link.robot_b]
        dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_a_b) @ link.matrix)
        if np.hypot(dx, dy) > distance or abs(dtheta) > angle:
            out.append(link)
    return out


def merge(
    maps: Mapping[str, FloatArray],
    config: MergeConfig | None = None,
    previous: MergeResult | None = None,
    reference: str | None = None,
    viewpoints: Mapping[str, FloatArray] | None = None,
) -> MergeResult:
    """Merge partial maps whose relative poses are unknown, in no particular order.

    ``maps``: robot name -> (N, 4) segments in that robot's own map frame. ``viewpoints``:
    robot name -> (K, 3) keyframe poses in the same frame, where the robot's laser stood; a
    link putting either map in the free space the other robot saw is refused (a robot without
    viewpoints is judged on segments alone). ``reference`` (or ``config.reference``) names
    the robot whose frame becomes ``map``; by default the previous run's reference is kept,
    else the largest map of the largest linked group is taken.
    ``previous`` (the last result) supplies pair results to reuse and the tree to keep.
    """
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    clean = {str(r): as_map(s) for r, s in maps.items()}
    robots = sorted(clean)
    chosen = reference if reference is not None else (config.reference or None)
    if chosen is not None and chosen not in clean:
        raise ValueError(f"reference robot {chosen!r} has no map; robots: {', '.join(robots)}")
    if not robots:
        return _no_maps()
    views = view_source(clean, viewpoints or {}, config.view_fan())
    records, calls = pair_links(clean, config, None if previous is None else previous.pairs, views)
    pairs_done = time.perf_counter()
    lengths = {r: SegmentMap.of(clean[r]).total_length for r in robots}
    kept = set() if previous is None else {(lk.robot_a, lk.robot_b) for lk in previous.links}
    all_links = [record.link for record in records.values()]
    joins = free_space_join(clean, views, link_tests(config)) if viewpoints else None
    tree = spanning_tree(robots, all_links, kept, config.pairwise.stability_margin, joins)
    if chosen is None:
        chosen = choose_reference(
            robots, tree, lengths, None if previous is None else previous.reference
        )
    placed = place(chosen, robots, tree)
    used = [lk for lk in tree if lk.robot_a in placed and lk.robot_b in placed]
    tree_done = time.perf_counter()
    segments, owner = _global_map(placed, clean, robots, config)
    finished = time.perf_counter()
    return MergeResult(
        robots=robots,
        placements=_placements(placed, robots),
        reference=chosen,
        links=used,
        pairs=records,
        segments=segments,
        segment_robot=owner,
        timings={
            "pairs_s": pairs_done - started,
            "tree_s": tree_done - pairs_done,
            "fusion_s": finished - tree_done,
            "total_s": finished - started,
        },
        stats=_merge_stats(records, calls, all_links, placed),
    )


def _no_maps() -> MergeResult:
    """The merge of no maps: nothing placed, an empty global map."""
    empty = np.zeros((0, 4))
    return MergeResult([], {}, None, [], {}, empty, np.zeros(0, dtype=np.int64), {}, {})


def _placements(placed: Mapping[str, FloatArray], robots: list[str]) -> dict[str, Pose | None]:
    """Each robot's frame in ``map`` as a pose (None: not placed)."""
    return {r: (se2.pose_from_matrix(placed[r]) if r in placed else None) for r in robots}


def _global_map(
    placed: Mapping[str, FloatArray],
    maps: Mapping[str, FloatArray],
    robots: list[str],
    config: MergeConfig,
) -> tuple[FloatArray, IntArray]:
    """The global map: each placed robot's map moved into ``map`` and fused, in the order
    the robots were placed (the reference first); its segments and each one's robot."""
    segments = np.zeros((0, 4))
    owner = np.zeros(0, dtype=np.int64)
    for robot, T_map_robot in placed.items():
        moved = se2.transform_segments(T_map_robot, maps[robot])
        index = np.full(len(moved), robots.index(robot), dtype=np.int64)
        segments, owner = fuse_maps(
            segments, owner, moved, index, pair_tolerance(config.integrate), config.fusion_tolerance
        )
    return segments, owner


def _merge_stats(
    records: Mapping[tuple[str, str], PairRecord],
    calls: int,
    links: Sequence[Link],
    placed: Mapping[str, FloatArray],
) -> dict[str, int]:
    """A merge's counts: pairs matched and reused, INTEGRATE calls, valid links, and valid
    links that disagree with the placements."""
    return {
        "pairs_computed": sum(not r.reused for r in records.values()),
        "pairs_reused": sum(r.reused for r in records.values()),
        "integrate_calls": calls,
        "links_valid": sum(lk.valid for lk in links),
        "cycle_conflicts": len(cycle_conflicts(placed, links)),
    }
