"""One graph for all robots: the ``pivot`` method (issue 13).

Input: every robot's keyframes as its ``partial_map`` carries them (pose in its piece's frame,
segments in its own frame). Each piece of each robot is a map of its own (a
:class:`~multi_robot_mapper.core.merging.places.MapUnit`). One merge update
(:func:`merge_joint`):

1. **places** of every map (a keyframe and its map around it, ``place_*``);
2. **links** (:mod:`~multi_robot_mapper.core.merging.place_matching`): each place of each map
   of every pair searched for on the other map
   (:func:`~multi_robot_mapper.core.merging.place_links.match_place`), results kept from one
   update to the next: a place is matched again only when its keyframes or segments changed,
   or the other map grew by ``reuse_*``; an update takes about ``update_budget`` seconds in
   all: matching gets what the rest of the last update left, places never matched first (the
   rest waits, and the node merges again);
3. **consistency** (:mod:`~multi_robot_mapper.core.merging.consistency`): per pair of maps the
   heaviest set of mutually consistent links (PCM), accepted when confident or supported by
   enough places, unique, and leaving the walls near its places out of the free space the
   other robot saw; pairs taken best first, a pair closing a cycle only when the cycle
   closes, a pair joining two groups only when no robot would have to drive faster than
   ``max_speed`` between two of its pieces (:mod:`~multi_robot_mapper.core.merging.motion`),
   and, once a set is refused so, only sets that outweigh it ``link_set_uniqueness`` times;
4. **one graph** (:class:`~multi_robot_mapper.core.pose_graph.PoseGraph`, gtsam) of every
   keyframe of the maps joined to the reference: edges between a map's keyframes from their
   published poses (consecutive keyframes, and keyframes within ``graph.radius``: the wire
   carries no loop closures, so these keep what the robot's own closures made of its map),
   with a standard deviation growing with their distance; every accepted link between
   keyframes of two maps, under the DCS robust kernel. Solved in one batch from the maps
   placed rigidly along the accepted pairs;
5. **output**: every merged keyframe's pose in ``map`` (the reference robot's map frame),
   each map's ``T_map_piece`` as the rigid fit of its keyframes, and the global map: every
   merged keyframe's segments at its optimised pose, fused (Amigoni Alg. 5), each fused
   segment owned by one keyframe (:mod:`~multi_robot_mapper.core.merging.global_map`, which
   fuses again only from the first map that changed or moved).
"""

from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.model import installed_model
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.logistic import LogisticModel
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.consistency import (
    GROUP_DOUBT,
    TOO_FAST,
    Accepted,
    PairVerdict,
    accept_pairs,
)
from multi_robot_mapper.core.merging.global_map import FusionCache, fuse_keyframes
from multi_robot_mapper.core.merging.joint_graph import Solution, graph_model, solved
from multi_robot_mapper.core.merging.kept_graph import GraphSlot
from multi_robot_mapper.core.merging.link_graph import MergeResult
from multi_robot_mapper.core.merging.motion import robot_reaches
from multi_robot_mapper.core.merging.pair_evidence import group_conflict
from multi_robot_mapper.core.merging.pairwise import Link, MapSignature, PairRecord
from multi_robot_mapper.core.merging.place_links import LinkCandidate
from multi_robot_mapper.core.merging.place_matching import (
    MatchKey,
    MatchRecord,
    Places,
    Targets,
    cached,
    match_places,
    target_of,
)
from multi_robot_mapper.core.merging.placement_paths import chain_probabilities
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey, units_of
from multi_robot_mapper.core.merging.unmerged import unmerged_reason
from multi_robot_mapper.core.merging.verdicts import Judged, judge_pairs
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass
class JointState:
    """What one update leaves to the next: every place match made so far, and what was
    derived from maps that may not have changed (each kept per content, so that an update
    that changed one robot's map recomputes only what involves it)."""

    matches: dict[MatchKey, MatchRecord] = dataclasses.field(default_factory=dict)
    links: list[LinkCandidate] = dataclasses.field(default_factory=list)  # in the graph
    # Seconds the rest of an update (verdicts, graph, fusion) and its tail (graph, fusion)
    # took the last time a map changed, and every map's content then: what the next update's
    # matching and verdicts leave room for.
    rest_s: float = 0.0
    tail_s: float = 0.0
    contents: dict[UnitKey, str] = dataclasses.field(default_factory=dict)
    # Each pair's verdict and what it was made from (verdicts.judge_pairs).
    judged: Judged = dataclasses.field(default_factory=Judged)
    # The graph's solution and what it was solved from: an update that brought no change to
    # the maps joined or their links (the node's retries) gets the same poses.
    solution: tuple[Any, Solution] | None = None
    # Each map's intra-map edges, per content.
    intra: OrderedDict[Any, Any] = dataclasses.field(default_factory=OrderedDict)
    # The last update's graph, solved, to be brought up to date (ISAM2, kept_graph).
    graph: GraphSlot = dataclasses.field(default_factory=GraphSlot)
    # Each join of groups' walls in free space, per the groups' maps, content and placements:
    # an update that added a place match elsewhere weighs the same joins again (issue 50:
    # 1.4 s of each such update with 8 robots placed).
    conflicts: OrderedDict[Any, float] = dataclasses.field(default_factory=OrderedDict)
    # Each map as a place-matching target, and its places, per content (place_matching).
    targets: Targets = dataclasses.field(default_factory=Targets)
    places: Places = dataclasses.field(default_factory=Places)
    # The global map's fusion, map by map (global_map.fuse_keyframes).
    fusion: FusionCache = dataclasses.field(default_factory=FusionCache)


def merge_joint(
    keyframes: Mapping[str, Sequence[Keyframe]],
    config: MergeConfig | None = None,
    previous: MergeResult | None = None,
    reference: str | None = None,
    budget: float | None = None,
    model: LogisticModel | None = None,
) -> MergeResult:
    """Merge the robots' keyframe maps (module doc). ``budget``: seconds the update may take
    (default ``config.update_budget``; 0 or None with a config of 0: every place matched, every
    pair judged): matching, then the verdicts, get what the rest of the last update left
    (:func:`_matching_budget`, :func:`~core.merging.verdicts.judge_pairs`). ``reference`` (or
    ``config.reference``) names the robot whose map frame is ``map`` (default: the previous
    update's while it is in the largest group). ``model``: the join model (default
    :func:`~core.evidence.model.installed_model`)."""
    config = config if config is not None else MergeConfig()
    started = time.perf_counter()
    robots = sorted(str(r) for r in keyframes)
    chosen = _chosen_reference(reference if reference is not None else config.reference, robots)
    units = units_of(keyframes)
    kept = previous.state if previous is not None else None
    state = kept if isinstance(kept, JointState) else None
    new_state = _next_state(state)
    budget = config.update_budget if budget is None else budget
    new_state.matches, counts = match_places(
        units,
        config,
        state.matches if state is not None else {},
        _matching_budget(budget, state),
        (new_state.targets, new_state.places),
    )
    matched = time.perf_counter()
    model = model if model is not None else installed_model()
    deadline = started + budget - (state.tail_s if state is not None else 0.0) if budget else None
    verdicts = _judged(units, config, model, state, new_state, deadline)
    counts["verdicts_pending"] = new_state.judged.pending
    accepted = _accepted_pairs(units, verdicts, config, model, new_state)
    checked = time.perf_counter()
    last = None if previous is None else previous.reference
    group, ref_unit, chains = _placed_group(accepted, units, chosen, last, config.join_probability)
    new_state.solution = solved(
        units,
        group,
        ref_unit,
        accepted,
        graph_model(config.graph),
        state.solution if state is not None else None,
        new_state.intra,
        new_state.graph,
    )
    solution = new_state.solution[1]
    optimised = time.perf_counter()
    result = _result(
        robots, units, accepted, verdicts, solution, ref_unit, chains, config, new_state.fusion
    )
    finished = time.perf_counter()
    times = (started, matched, checked, optimised, finished)
    _finish_update(result, units, solution, state, new_state, times)
    result.stats.update(counts)
    return result


def _chosen_reference(reference: str | None, robots: Sequence[str]) -> str | None:
    """The reference robot asked for ("" or None: none), which must have a map."""
    if reference and reference not in robots:
        raise ValueError(f"reference robot {reference!r} has no map; robots: {', '.join(robots)}")
    return reference or None


def _judged(
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
    model: LogisticModel,
    state: JointState | None,
    new_state: JointState,
    deadline: float | None,
) -> dict[tuple[UnitKey, UnitKey], PairVerdict]:
    """Every pair's verdict (:func:`~core.merging.verdicts.judge_pairs`, until ``deadline``),
    what they leave to the next update kept in ``new_state.judged``."""
    last = state.judged if state is not None else None
    verdicts, new_state.judged = judge_pairs(
        units, new_state.matches, config, model, new_state.targets, last, deadline
    )
    return verdicts


def _accepted_pairs(
    units: Mapping[UnitKey, MapUnit],
    verdicts: Mapping[tuple[UnitKey, UnitKey], PairVerdict],
    config: MergeConfig,
    model: LogisticModel,
    new_state: JointState,
) -> Accepted:
    """The pairs of maps accepted over the groups (:func:`~core.merging.consistency.
    accept_pairs`): no robot driving faster than ``max_speed`` between two of its pieces, and
    a join of groups weighed with its walls in free space on every map of both (kept per the
    groups' maps, their content and placements: ``JointState.conflicts``)."""
    reaches = robot_reaches(units, config.max_speed)
    kept = new_state.targets
    digests = {key: unit.content for key, unit in units.items()}

    def placed(group: Mapping[UnitKey, FloatArray]) -> tuple[Any, ...]:
        return tuple(sorted((k, digests[k], np.asarray(T).tobytes()) for k, T in group.items()))

    def conflict(group_a: Any, group_b: Any, T: FloatArray) -> float:
        def measure() -> float:
            targets = {key: target_of(units[key], config, kept) for key in (*group_a, *group_b)}
            return group_conflict(group_a, group_b, T, units, targets, config.place_radius)

        key = (placed(group_a), placed(group_b), np.asarray(T).tobytes(), config)
        return cast(float, cached(new_state.conflicts, key, measure))

    return accept_pairs(list(verdicts.values()), units, config, model, reaches, conflict)


def _placed_group(
    accepted: Accepted,
    units: Mapping[UnitKey, MapUnit],
    chosen: str | None,
    previous: str | None,
    join_probability: float,
) -> tuple[list[UnitKey], UnitKey | None, dict[UnitKey, float]]:
    """The maps placed in ``map`` (:func:`_reference`'s group, each joined to the reference
    map with a probability of at least ``join_probability``), the reference map and each
    map's probability of being joined right (:func:`chain_probabilities`)."""
    group, ref_unit = _reference(accepted, units, chosen, previous)
    chains = chain_probabilities(ref_unit, [(*v.pair, v.probability) for v in accepted.pairs])
    group = [key for key in group if chains.get(key, 0.0) >= join_probability]
    return group, ref_unit, chains


def _next_state(state: JointState | None) -> JointState:
    """The state this update leaves to the next (its matches set once made), with what the
    last update's ``state`` kept per content (targets, places, intra-map edges, joins' walls
    in free space, the fusion)."""
    new_state = JointState()
    if state is not None:
        new_state.targets, new_state.places = state.targets, state.places
        new_state.intra, new_state.conflicts = state.intra, state.conflicts
        new_state.graph = state.graph
        new_state.fusion = state.fusion
    return new_state


def _finish_update(
    result: MergeResult,
    units: Mapping[UnitKey, MapUnit],
    solution: Solution,
    state: JointState | None,
    new_state: JointState,
    times: tuple[float, float, float, float, float],
) -> None:
    """``new_state`` completed for the next update (the links in the graph, every map's
    content, and the seconds the update took after matching, unless nothing changed) and
    kept in ``result``, with the update's timings (``times``: when it started, matching,
    consistency, the graph and the fusion ended)."""
    started, matched, checked, optimised, finished = times
    contents = {key: unit.content for key, unit in units.items()}
    rest, tail = finished - matched, finished - checked
    if state is not None and state.contents == contents:
        # nothing changed: this update says nothing of a changing one
        rest, tail = state.rest_s, state.tail_s
    new_state.links, new_state.contents = solution.accepted, contents
    new_state.rest_s, new_state.tail_s = rest, tail
    result.state = new_state
    result.timings = {
        "matching_s": matched - started,
        "consistency_s": checked - matched,
        "graph_s": optimised - checked,
        "fusion_s": finished - optimised,
        "total_s": finished - started,
    }


def _matching_budget(budget: float | None, state: JointState | None) -> float | None:
    """Seconds of place matching in an update of ``budget`` seconds (0 or None: no limit):
    room is left for the rest of the update (verdicts, graph, fusion) as long as it took the
    last time a map changed (``JointState.rest_s``), so that an update takes about ``budget``
    in all, but at least half of what the graph and fusion leave (``tail_s``: the verdicts
    wait their turn too, :func:`~core.merging.verdicts.judge_pairs`); at least one match is
    made."""
    if not budget:
        return budget
    if state is None:
        return budget
    return max(budget - state.rest_s, 0.5 * (budget - state.tail_s), 1e-6)


# --- the reference ------------------------------------------------------------------------


def _reference(
    accepted: Accepted,
    units: Mapping[UnitKey, MapUnit],
    chosen: str | None,
    previous: str | None,
) -> tuple[list[UnitKey], UnitKey | None]:
    """The group of maps placed in ``map`` and its reference map: the chosen robot's (its
    group), else the previous reference's while its group is as large as any, else the
    largest group (with no two robots linked, the first robot by name, its longest map);
    within it a robot's main frame (piece 0), longest first."""
    if not accepted.groups:
        return [], None

    def robots_in(group: list[UnitKey]) -> int:
        return len({robot for robot, _ in group})

    size = robots_in(accepted.groups[0])
    group = accepted.groups[0]
    for wanted, must in ((chosen, True), (previous, False)):
        if wanted is None:
            continue
        holding = [g for g in accepted.groups if (wanted, 0) in g]
        if holding and (must or robots_in(holding[0]) == size):
            return holding[0], (wanted, 0)
    if size == 1:
        # No two robots linked: the first robot by name is ``map``, whatever the lengths of
        # the other robots' maps, so that ``map`` does not jump between robots as they grow.
        # Of its pieces, the longest: a robot lost early maps most of its run in a later piece
        # (the dense intel bag alone: its main piece was not piece 0, and nothing was placed).
        robot = min(key[0] for key in units)
        first = max(
            (key for key in units if key[0] == robot),
            key=lambda key: (units[key].length, -key[1]),
        )
        return next(g for g in accepted.groups if first in g), first
    mains = [key for key in group if key[1] == 0]
    pool = mains or group
    return group, max(pool, key=lambda key: (units[key].length, [-ord(c) for c in key[0]]))


# --- the result ---------------------------------------------------------------------------


def _result(
    robots: list[str],
    units: Mapping[UnitKey, MapUnit],
    accepted: Accepted,
    verdicts: Mapping[tuple[UnitKey, UnitKey], PairVerdict],
    solved: Solution,
    ref_unit: UnitKey | None,
    chains: Mapping[UnitKey, float],
    config: MergeConfig,
    fusion: FusionCache,
) -> MergeResult:
    """The merge as a :class:`MergeResult`: frames, keyframe poses, links, global map, and
    each robot's probability of being placed right or why it is not placed."""
    frames: dict[str, dict[int, Pose]] = {}
    for key, T in solved.frames.items():
        frames.setdefault(key[0], {})[key[1]] = se2.pose_from_matrix(T)
    placements: dict[str, Pose | None] = {r: frames.get(r, {}).get(0) for r in robots}
    keyframe_index, keyframe_poses = _robot_keyframes(robots, units, solved)
    segments, owner_robot, owner_keyframe = fuse_keyframes(
        robots, units, solved.order, solved.poses, config, fusion
    )
    links = _robot_links(accepted, solved, units)
    pairs = _robot_pairs(verdicts, units)
    result = MergeResult(
        robots=robots,
        placements=placements,
        reference=None if ref_unit is None else ref_unit[0],
        links=links,
        pairs=pairs,
        segments=segments,
        segment_robot=owner_robot,
        timings={},
        stats=_joint_stats(accepted, verdicts, solved),
        keyframe_poses=keyframe_poses,
        keyframe_index=keyframe_index,
        frames=frames,
        segment_keyframe=owner_keyframe,
    )
    result.verdicts = dict(verdicts)
    result.probabilities = {
        robot: chains[(robot, 0)] for robot in robots if placements[robot] is not None
    }
    for key in solved.frames:
        result.frame_probabilities.setdefault(key[0], {})[key[1]] = chains[key]
    result.unmerged_reasons = {
        robot: unmerged_reason(
            robot, units, verdicts, accepted, chains, ref_unit, config.join_probability
        )
        for robot in robots
        if placements[robot] is None
    }
    return result


def _robot_keyframes(
    robots: list[str], units: Mapping[UnitKey, MapUnit], solved: Solution
) -> tuple[dict[str, IntArray], dict[str, FloatArray]]:
    """Each merged robot's keyframes (of every map of it in the graph), sorted by index:
    their indices, and their optimised poses in ``map``."""
    keyframe_poses: dict[str, FloatArray] = {}
    keyframe_index: dict[str, IntArray] = {}
    for robot in robots:
        keys = [key for key in solved.order if key[0] == robot]
        if not keys:
            continue
        index = np.concatenate([units[key].index for key in keys])
        poses = np.vstack([solved.poses[key] for key in keys])
        order = np.argsort(index, kind="stable")
        keyframe_index[robot], keyframe_poses[robot] = index[order], poses[order]
    return keyframe_index, keyframe_poses


def _joint_stats(
    accepted: Accepted,
    verdicts: Mapping[tuple[UnitKey, UnitKey], PairVerdict],
    solved: Solution,
) -> dict[str, int]:
    """The merge's counts: maps merged, pairs linked and refused (by reason), links and the
    graph."""
    return {
        "maps_merged": len(solved.order),
        "pairs_linked": len(accepted.pairs),
        "pairs_consistent": sum(v.accepted for v in verdicts.values()),
        "pairs_breaking_cycles": sum(v.reason == "breaks a cycle" for v in accepted.refused),
        # joins that would make a robot drive faster than max_speed, and sets refused as
        # no heavier than such a proven look-alike (consistency.accept_pairs)
        "pairs_too_fast": sum(v.reason.startswith(TOO_FAST) for v in accepted.refused),
        # joins whose probability fell short once weighed with every map of both groups
        "pairs_doubted_by_groups": sum(v.reason.startswith(GROUP_DOUBT) for v in accepted.refused),
        "links_accepted": len(solved.accepted),
        "link_candidates": sum(len(v.links) for v in verdicts.values()),
        "graph_nodes": solved.nodes,
        "graph_edges": solved.edges,
        "graph_iterations": solved.iterations,
    }


def _robot_links(
    accepted: Accepted, solved: Solution, units: Mapping[UnitKey, MapUnit]
) -> list[Link]:
    """The accepted pairs between the placed maps of two different robots, as one link per pair
    of robots (``T_a_b`` between their fitted frames, ``value`` the matched wall of its links)
    for the diagnostics."""
    by_robots: dict[tuple[str, str], Link] = {}
    for verdict in accepted.pairs:
        a, b = verdict.pair
        if a[0] == b[0] or a not in solved.frames or b not in solved.frames:
            continue
        (ra, ka), (rb, kb) = sorted((a, b))
        T_a_b = se2.invert(solved.frames[(ra, ka)]) @ solved.frames[(rb, kb)]
        value = float(sum(c.value for c in verdict.links))
        link = Link(
            ra,
            rb,
            se2.pose_from_matrix(T_a_b),
            value,
            0.0,
            True,
            uniqueness=verdict.weight / verdict.rival_weight if verdict.rival_weight else np.inf,
        )
        if (ra, rb) not in by_robots or by_robots[(ra, rb)].value < value:
            by_robots[(ra, rb)] = link
    return sorted(by_robots.values(), key=lambda lk: (lk.robot_a, lk.robot_b))


def _robot_pairs(
    verdicts: Mapping[tuple[UnitKey, UnitKey], PairVerdict], units: Mapping[UnitKey, MapUnit]
) -> dict[tuple[str, str], PairRecord]:
    """Every pair of robots' strongest pair of maps (its consistent set's matched wall, valid
    when accepted), for the diagnostics' best value with any robot."""
    out: dict[tuple[str, str], PairRecord] = {}
    for (a, b), verdict in verdicts.items():
        if a[0] == b[0]:
            continue
        ra, rb = sorted((a[0], b[0]))
        value = float(sum(c.value for c in verdict.links))
        if (ra, rb) in out and out[(ra, rb)].link.value >= value:
            continue
        link = Link(ra, rb, (0.0, 0.0, 0.0), value, 0.0, verdict.accepted)
        signature_a = MapSignature.of(units[a].segment_map)
        signature_b = MapSignature.of(units[b].segment_map)
        out[(ra, rb)] = PairRecord(link, signature_a, signature_b, False)
    return out


def place_scans(
    result: MergeResult, robot: str, anchors: tuple[FloatArray, IntArray, FloatArray]
) -> tuple[FloatArray, FloatArray] | None:
    """The scans of ``robot`` placed in ``map`` through their keyframes' optimised poses
    (``anchors``: stamps, keyframe of each scan, ``T_keyframe_scan``; LocalMapper.anchors):
    stamps and (N, 3) poses, by stamp, of the scans whose keyframe was merged. None when no
    keyframe of the robot was merged."""
    index = result.keyframe_index.get(robot)
    if index is None or len(index) == 0:
        return None
    stamps, keyframe, T_keyframe_scan = anchors
    row = np.searchsorted(index, keyframe)
    row = np.minimum(row, len(index) - 1)
    merged = index[row] == keyframe
    poses = result.keyframe_poses[robot][row[merged]]
    placed = np.array(
        [se2.compose(p, s) for p, s in zip(poses, np.asarray(T_keyframe_scan)[merged], strict=True)]
    ).reshape(-1, 3)
    chosen = np.asarray(stamps)[merged]
    order = np.argsort(chosen, kind="stable")
    return chosen[order], placed[order]
