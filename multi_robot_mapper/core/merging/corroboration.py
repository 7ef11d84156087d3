"""Joins that agree (issue 46): a map placed by several sets of links that put it in the same
place is placed on all of them, not on its single most probable path.

**Paths** (:func:`chain_probabilities`). A map joined to the reference is placed right when
every join along some path of joins from the reference is right. Every join of a group agrees
with every other (a join inside a group is taken only when its cycle closes:
:func:`~core.merging.consistency.accept_pairs`), so two paths to a map put it in the same
place, and the map is wrong only when *every* path holds a wrong join: wrong joins that agree
by chance are counted as if they always did. With the joins' evidence independent, the
probability of paths that share no join failing together is the product of their failing
alone, and ``1 - prod(1 - P(path))`` over any edge-disjoint paths is a lower bound on the map's
probability of being right (the paths are taken greedily, the most probable first). One path
gives the product of its joins' probabilities, as before.

**Sets short of the threshold** (:func:`corroborate`). A consistent set whose own probability
falls short of ``join_probability`` (equal rooms in a row, a pillar hall turned 180°: the
evidence model cannot tell, issue 46's P 0.9-0.99 band) is still evidence. Where two or more
such sets, between different pairs of maps, place one group of maps in another the same way
(within the cycle tolerance of :func:`~core.merging.consistency.closes`), each weighed again
as the join of the two groups (its walls in the free space of every map of both), they are
edge-disjoint paths between the groups and join them when ``1 - prod(1 - P)`` reaches
``join_probability``; a set inside a group that agrees with the group is one more path. The
rule and the threshold are those of the paths above; nothing else is tuned. Sets below
:data:`PLAUSIBLE` are left out: the model says they are more likely wrong than right.
"""

from __future__ import annotations

import dataclasses
import heapq
from collections.abc import Iterable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.model import JoinModel
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.consistency import (
    TOO_FAST,
    Accepted,
    GroupConflict,
    PairVerdict,
    judge_join,
    ordered_groups,
    placement,
)
from multi_robot_mapper.core.merging.motion import RobotReach
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey

FloatArray = NDArray[np.float64]
Edge = tuple[UnitKey, UnitKey, float]  # two maps and the probability of the join between them

# A set joins paths only when the join model finds it more likely right than wrong: below,
# agreeing with another set is more likely chance than evidence.
PLAUSIBLE = 0.5
# Edge-disjoint paths counted per map: a fourth path changes P by less than 1e-6 at the
# probabilities sets have (each path's failure is at most 0.5).
MAX_PATHS = 3


def chain_probabilities(ref_unit: UnitKey | None, edges: Sequence[Edge]) -> dict[UnitKey, float]:
    """The probability that each map joined to ``ref_unit`` by ``edges`` is placed right
    (module doc: up to :data:`MAX_PATHS` edge-disjoint paths, the most probable first)."""
    if ref_unit is None:
        return {}
    reached = _best_paths(ref_unit, edges)
    chains: dict[UnitKey, float] = {}
    for key, (probability, path) in reached.items():
        failing = 1.0 - probability
        remaining = [e for i, e in enumerate(edges) if i not in path]
        for _ in range(MAX_PATHS - 1):
            if key == ref_unit or not remaining:
                break
            other = _best_paths(ref_unit, remaining).get(key)
            if other is None:
                break
            failing *= 1.0 - other[0]
            remaining = [e for i, e in enumerate(remaining) if i not in other[1]]
        chains[key] = 1.0 - failing
    return chains


def _best_paths(
    ref_unit: UnitKey, edges: Sequence[Edge]
) -> dict[UnitKey, tuple[float, frozenset[int]]]:
    """Dijkstra on -log P: each reachable map's most probable path (its probability and the
    indices of its edges)."""
    neighbours: dict[UnitKey, list[tuple[UnitKey, float, int]]] = {}
    for index, (a, b, probability) in enumerate(edges):
        neighbours.setdefault(a, []).append((b, probability, index))
        neighbours.setdefault(b, []).append((a, probability, index))
    best: dict[UnitKey, tuple[float, frozenset[int]]] = {}
    frontier: list[tuple[float, int, UnitKey, frozenset[int]]] = [(-1.0, 0, ref_unit, frozenset())]
    tie = 0
    while frontier:
        negative, _, key, path = heapq.heappop(frontier)
        if key in best:
            continue
        best[key] = (-negative, path)
        for other, probability, index in neighbours.get(key, []):
            if other not in best:
                tie += 1
                heapq.heappush(frontier, (negative * probability, tie, other, path | {index}))
    return best


@dataclasses.dataclass(frozen=True)
class _Candidate:
    """A set short of the threshold between two groups, read from group ``roots[0]``."""

    verdict: PairVerdict
    first: UnitKey  # the set's map in group roots[0]
    roots: tuple[UnitKey, UnitKey]
    T_roots: FloatArray  # T_root0_root1 as the set places group 1 in group 0


def corroborate(
    accepted: Accepted,
    verdicts: Iterable[PairVerdict],
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
    model: JoinModel,
    reaches: Mapping[str, RobotReach] | None = None,
    group_conflict: GroupConflict | None = None,
) -> Accepted:
    """``accepted`` with the joins of agreeing sets short of the threshold (module doc), best
    first, until none reaches ``join_probability``; and the sets inside a group that agree
    with it, as more paths."""
    taken = {v.pair for v in accepted.pairs}
    shy = [
        v
        for v in verdicts
        if v.links
        and v.pair not in taken
        and v.probability >= PLAUSIBLE
        and not v.reason.startswith(TOO_FAST)
    ]
    state = dataclasses.replace(
        accepted,
        pairs=list(accepted.pairs),
        placed={root: dict(group) for root, group in accepted.placed.items()},
        tree={key: list(near) for key, near in accepted.tree.items()},
    )
    while True:
        join = _best_join(state, shy, units, config, model, reaches, group_conflict)
        if join is None:
            break
        state = _joined(state, *join, units)
        joined_pairs = {v.pair for v in join[0]}
        shy = [v for v in shy if v.pair not in joined_pairs]
    return _with_cycles(state, shy, units, config)


def _roots(state: Accepted) -> dict[UnitKey, UnitKey]:
    return {key: root for root, group in state.placed.items() for key in group}


def _candidates(
    state: Accepted, shy: Sequence[PairVerdict], units: Mapping[UnitKey, MapUnit]
) -> dict[tuple[UnitKey, UnitKey], list[_Candidate]]:
    """Each set between two groups, read from the group of lower root."""
    root_of = _roots(state)
    by_groups: dict[tuple[UnitKey, UnitKey], list[_Candidate]] = {}
    for verdict in shy:
        a, b = verdict.pair
        if root_of[a] == root_of[b]:
            continue
        if root_of[a] > root_of[b]:
            a, b = b, a
        ra, rb = root_of[a], root_of[b]
        T = state.placed[ra][a] @ placement(verdict, a, units) @ se2.invert(state.placed[rb][b])
        by_groups.setdefault((ra, rb), []).append(_Candidate(verdict, a, (ra, rb), T))
    return by_groups


def _best_join(
    state: Accepted,
    shy: Sequence[PairVerdict],
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
    model: JoinModel,
    reaches: Mapping[str, RobotReach] | None,
    group_conflict: GroupConflict | None,
) -> tuple[list[PairVerdict], _Candidate] | None:
    """The most probable join of two groups by two or more agreeing sets that reaches
    ``join_probability``: its sets, weighed again as that join, and the set that places it."""
    best: tuple[float, list[PairVerdict], _Candidate] | None = None
    for (ra, rb), found in _candidates(state, shy, units).items():
        group_a, group_b = state.placed[ra], state.placed[rb]
        for seed, agreeing in _clusters(found, group_b, units, config):
            # The sets' own probabilities bound the join's from above: weighed with the free
            # space of every map of both groups a set's P can only fall (the join model is
            # sign-constrained: more wall in free space never raises it). Most clusters stop
            # here, before the costly free-space measure.
            bound = 1.0 - float(np.prod([1.0 - c.verdict.probability for c in agreeing]))
            if bound < config.join_probability or (best is not None and bound <= best[0]):
                continue
            joined = {**group_a, **{key: seed.T_roots @ T for key, T in group_b.items()}}
            weighed = [
                judge_join(
                    c.verdict,
                    joined,
                    (group_a, group_b, seed.T_roots),
                    units,
                    config,
                    model,
                    reaches,
                    group_conflict,
                )
                for c in agreeing
            ]
            if any(v.reason.startswith(TOO_FAST) for v in weighed):
                continue
            probability = 1.0 - float(np.prod([1.0 - v.probability for v in weighed]))
            if probability >= config.join_probability and (best is None or probability > best[0]):
                best = (probability, weighed, seed)
    return None if best is None else (best[1], best[2])


def _clusters(
    found: Sequence[_Candidate],
    group_b: Mapping[UnitKey, FloatArray],
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
) -> list[tuple[_Candidate, list[_Candidate]]]:
    """The distinct clusters of two or more sets that agree with a seed set, each placed by
    its most probable set."""
    clusters: dict[frozenset[object], tuple[_Candidate, list[_Candidate]]] = {}
    ranked = sorted(found, key=lambda c: -c.verdict.probability)
    for seed in ranked:
        agreeing = [c for c in ranked if _agree(seed, c, group_b, units, config)]
        members = frozenset(c.verdict.pair for c in agreeing)
        if len(agreeing) >= 2 and members not in clusters:
            clusters[members] = (seed, agreeing)
    return list(clusters.values())


def _agree(
    seed: _Candidate,
    other: _Candidate,
    group_b: Mapping[UnitKey, FloatArray],
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
) -> bool:
    """Do two sets place group B alike: at each set's linked keyframe in B, within the cycle
    tolerance over the distance between the two sets' places (as
    :func:`~core.merging.consistency.closes` allows a cycle its drift)?"""
    if other is seed:
        return True
    places = np.array([_linked_place(c, group_b, units) for c in (seed, other)])
    difference = se2.invert(seed.T_roots) @ other.T_roots
    shift = float(np.hypot(*(se2.transform_points(difference, places) - places).T).max())
    turn = abs(float(se2.pose_from_matrix(difference)[2]))
    run = float(np.hypot(*(places[0] - places[1])))
    return shift <= RIGHT_DISTANCE + config.link_pair_slack * run and turn <= (
        RIGHT_ANGLE + config.link_pair_angle_slack * run
    )


def _linked_place(
    candidate: _Candidate, group_b: Mapping[UnitKey, FloatArray], units: Mapping[UnitKey, MapUnit]
) -> FloatArray:
    """Where the set's best link lands in group B's root frame (x, y)."""
    link = max(candidate.verdict.links, key=lambda c: c.fit)
    a, b = candidate.verdict.pair
    second = b if candidate.first == a else a
    keyframe = link.keyframe if link.target == second else link.centre
    unit = units[second]
    pose = unit.poses[unit.row(keyframe)]
    point = np.asarray(pose[:2], dtype=np.float64)[None]
    return np.asarray(se2.transform_points(group_b[second], point)[0], dtype=np.float64)


def _joined(
    state: Accepted,
    weighed: list[PairVerdict],
    seed: _Candidate,
    units: Mapping[UnitKey, MapUnit],
) -> Accepted:
    """``state`` with group ``seed.roots[1]`` joined to ``seed.roots[0]`` by ``weighed``."""
    ra, rb = seed.roots
    placed = dict(state.placed)
    group_b = placed.pop(rb)
    placed[ra] = {**placed[ra], **{key: seed.T_roots @ T for key, T in group_b.items()}}
    taken = [dataclasses.replace(v, accepted=True, reason="") for v in weighed]
    tree = {key: list(near) for key, near in state.tree.items()}
    a, b = seed.verdict.pair
    main = next(v for v in taken if v.pair == seed.verdict.pair)
    tree[a].append((b, main))
    tree[b].append((a, main))
    joined_pairs = {v.pair for v in taken}
    groups = ordered_groups(placed.values(), units)
    return dataclasses.replace(
        state,
        pairs=[*state.pairs, *taken],
        refused=[v for v in state.refused if v.pair not in joined_pairs],
        groups=groups,
        tree=tree,
        placed=placed,
    )


def _with_cycles(
    state: Accepted,
    shy: Sequence[PairVerdict],
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
) -> Accepted:
    """``state`` with every set short of the threshold inside a group that places its two
    maps as the group does (one more path between them)."""
    root_of = _roots(state)
    agreeing = []
    for verdict in shy:
        a, b = verdict.pair
        if root_of[a] != root_of[b]:
            continue
        group = state.placed[root_of[a]]
        as_group = _Candidate(verdict, a, (a, b), se2.invert(group[a]) @ group[b])
        as_set = _Candidate(verdict, a, (a, b), placement(verdict, a, units))
        if _agree(as_group, as_set, {b: np.eye(3)}, units, config):
            agreeing.append(dataclasses.replace(verdict, accepted=True, reason=""))
    return dataclasses.replace(state, pairs=[*state.pairs, *agreeing])
