"""Which links between robots to believe: the consistent set of each pair of maps (PCM), the
probability that its placement is right from the evidence model, and the joins of groups.

**Pairs of maps** (:func:`consistent_set`). Two links of the same two maps A and B agree when
the cycle link 1, B's map from link 1's end to link 2's, link 2 backwards, A's map back to
link 1's start closes: within the correctness tolerance (0.30 m, 5 deg) plus
``link_pair_slack`` (and ``link_pair_angle_slack``) per metre that the cycle runs inside the
two maps (their own drift). In the manner of pairwise consistency maximisation (Mangelson et
al. 2018), the largest consistent set (by weight: the sum over its links of the probability
that each is its place's right placement, :func:`placement_weights`) is kept, found by
growing a clique from each link in turn: the pair's hypothesis. Whether to believe it is not
a matter of counting its places (places along one corridor see the same walls, and a
corridor turned round fits at all of them): its placement is weighed by the evidence model
(:mod:`~multi_robot_mapper.core.evidence.placement`, both ways: each map's walls near the
linked places against their best rival placement on the whole other map) and by the walls it
puts in the free space the other robot saw (:func:`seen_through_near`); the join model
(:mod:`~multi_robot_mapper.core.evidence.model`) turns these into the probability that the
placement is right. The pair is a candidate join when that reaches ``join_probability``.

**Joins** (:func:`accept_pairs`). Candidate pairs are taken most probable first (Kruskal). A
pair joining two groups of maps is weighed again against every map of both groups: the walls
the joined group puts in free space any of its robots saw replace the pair's own in the join
model, and the join is made only when its probability still reaches ``join_probability`` and
no robot would have to drive faster than ``max_speed`` between two of its pieces
(:mod:`~multi_robot_mapper.core.merging.motion`). A pair whose maps are already joined closes
a cycle, and is accepted only when the cycle through its best link and the best links of the
chain joining its maps closes within the same tolerance: a link that breaks a cycle is
refused. Three robots that see each other check each other.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.logistic import LogisticModel
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.free_space import (
    MapViews,
    free_space_conflict,
    seen_through_length,
)
from multi_robot_mapper.core.merging.motion import RobotReach, motion_excess
from multi_robot_mapper.core.merging.pair_evidence import PairEvidence
from multi_robot_mapper.core.merging.place_links import LinkCandidate, segments_near
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Pair = tuple[UnitKey, UnitKey]  # sorted
ViewsOf = Callable[[UnitKey], "MapViews | None"]  # a map's free space, as its robot saw it
# metres of wall a consistent set's placement puts in free space (seen_through_near)
SeenThrough = Callable[[Sequence[LinkCandidate]], tuple[float, float]]
# the evidence of a consistent set's placement T_first_second (pair_evidence)
EvidenceOf = Callable[[Sequence[LinkCandidate], FloatArray], PairEvidence]


@dataclasses.dataclass(frozen=True)
class OrientedLink:
    """A link read from map ``first`` to map ``second``: keyframe ``k_second`` of ``second``
    lies at ``T`` in keyframe ``k_first``'s frame of ``first``."""

    first: UnitKey
    k_first: int
    second: UnitKey
    k_second: int
    T: FloatArray  # (3, 3)
    candidate: LinkCandidate


def oriented(candidate: LinkCandidate, first: UnitKey) -> OrientedLink:
    """The candidate read from map ``first`` (its target or its source)."""
    T = se2.matrix_from_pose(*candidate.T_keyframe_centre)
    if candidate.target == first:
        return OrientedLink(
            candidate.target, candidate.keyframe, candidate.source, candidate.centre, T, candidate
        )
    return OrientedLink(
        candidate.source,
        candidate.centre,
        candidate.target,
        candidate.keyframe,
        se2.invert(T),
        candidate,
    )


@dataclasses.dataclass(frozen=True)
class PairVerdict:
    """What the links of one pair of maps say."""

    pair: Pair
    links: list[LinkCandidate]  # the consistent set (accepted or not)
    weight: float  # sum of its links' placement weights (placement_weights)
    rival_weight: float  # weight of the best set contradicting it
    places: int  # distinct places the set links
    accepted: bool
    reason: str  # why refused ("" when accepted)
    # m of wall in the other's free space: near its places, of the whole maps
    seen_through: tuple[float, float] = (0.0, 0.0)
    evidence: PairEvidence | None = None  # the set's placement against its rivals
    probability: float = 0.0  # that its placement is right (join model); of the join once taken
    conflict: float = 0.0  # m of wall in free space weighed: the pair's, or its join's groups'


def _poses(unit: MapUnit, keyframes: Sequence[int]) -> FloatArray:
    return np.asarray(unit.poses[np.searchsorted(unit.index, np.asarray(keyframes))])


def consistency_matrix(
    links: Sequence[OrientedLink],
    units: Mapping[UnitKey, MapUnit],
    slack: float,
    angle_slack: float,
) -> BoolArray:
    """(n, n) which links of one pair of maps agree with each other (all read from the same
    map ``first``), within ``slack`` m and ``angle_slack`` rad per metre run inside the maps.
    Two placements of the same place never agree (they are rivals)."""
    n = len(links)
    if n == 0:
        return np.zeros((0, 0), dtype=bool)
    first, second = units[links[0].first], units[links[0].second]
    a = _poses(first, [lk.k_first for lk in links])
    b = _poses(second, [lk.k_second for lk in links])
    T = np.stack([lk.T for lk in links])
    # Predicted link i from link j: T_ai_aj . T_j . T_bj_bi, against T_i (every i, j at once).
    Ta = se2.matrices_from_poses(a)
    Tb = se2.matrices_from_poses(b)
    Ta_inv = np.linalg.inv(Ta)
    Tb_inv = np.linalg.inv(Tb)
    T_ai_aj = np.einsum("iab,jbc->ijac", Ta_inv, Ta)
    T_bj_bi = np.einsum("jab,ibc->ijac", Tb_inv, Tb)
    predicted = np.einsum("ijab,jbc,ijcd->ijad", T_ai_aj, T, T_bj_bi)
    residual = np.einsum("iab,ijbc->ijac", np.linalg.inv(T), predicted)
    shift = np.hypot(residual[..., 0, 2], residual[..., 1, 2])
    turn = np.abs(np.arctan2(residual[..., 1, 0], residual[..., 0, 0]))
    path = np.hypot(*(a[:, None, :2] - a[None, :, :2]).transpose(2, 0, 1)) + np.hypot(
        *(b[:, None, :2] - b[None, :, :2]).transpose(2, 0, 1)
    )
    agree = (shift <= RIGHT_DISTANCE + slack * path) & (turn <= RIGHT_ANGLE + angle_slack * path)
    places = [(lk.candidate.source, lk.candidate.centre) for lk in links]
    ids = {p: k for k, p in enumerate(dict.fromkeys(places))}
    place = np.array([ids[p] for p in places])
    agree &= place[:, None] != place[None, :]
    np.fill_diagonal(agree, True)
    return np.asarray(agree & agree.T)


def heaviest_clique(
    agree: BoolArray, weights: FloatArray, allowed: BoolArray | None = None
) -> list[int]:
    """A heavy set of mutually agreeing links: grown greedily (heaviest agreeing link first)
    from every link in turn, the heaviest kept. ``allowed`` limits the links used."""
    n = len(weights)
    usable = np.ones(n, dtype=bool) if allowed is None else allowed.copy()
    best: list[int] = []
    best_weight = 0.0
    order = np.argsort(-weights, kind="stable")
    for seed in order:
        if not usable[seed]:
            continue
        members = [int(seed)]
        open_ = usable & agree[seed]
        open_[seed] = False
        while open_.any():
            pick = int(order[np.argmax(open_[order])])
            members.append(pick)
            open_ &= agree[pick]
            open_[pick] = False
        total = float(weights[members].sum())
        if total > best_weight:
            best, best_weight = members, total
    return sorted(best)


def consistent_set(
    pair: Pair,
    candidates: Sequence[LinkCandidate],
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
    seen_through: SeenThrough,
    evidence_of: EvidenceOf,
    model: LogisticModel,
) -> PairVerdict:
    """The pair's heaviest consistent set of links, its evidence and the probability that its
    placement is right (module doc): a candidate join when that reaches ``join_probability``.
    ``seen_through``: :func:`seen_through_near` over the robots' views; ``evidence_of``: the
    evidence model of a set's placement (:func:`~core.merging.pair_evidence.pair_evidence`)."""
    usable = [c for c in candidates if c.fit >= config.link_fit and c.value >= config.link_min_wall]
    if not usable:
        return PairVerdict(pair, [], 0.0, 0.0, 0, False, "no link fits")
    links = [oriented(c, pair[0]) for c in usable]
    agree = consistency_matrix(links, units, config.link_pair_slack, config.link_pair_angle_slack)
    weights = placement_weights(usable)
    chosen = heaviest_clique(agree, weights)
    members = [usable[i] for i in chosen]
    weight = float(weights[chosen].sum())
    # The heaviest set contradicting it, for the record (the evidence model searches every
    # placement of the linked walls for rivals, not only those some place's match found).
    contradicting = np.asarray(~agree[chosen].all(axis=0), dtype=bool)
    rival = heaviest_clique(agree, weights, contradicting)
    rival_weight = float(weights[rival].sum()) if rival else 0.0
    through = seen_through(members)
    evidence = evidence_of(members, _link_placement(_best_of(members, pair[0]), units))
    conflict = max(evidence.conflict, through[1])
    probability = model.probability(evidence.features(conflict))
    reason = doubt(probability, evidence, conflict, config.join_probability)
    return PairVerdict(
        pair,
        members,
        weight,
        rival_weight,
        _places(members),
        not reason,
        reason,
        through,
        evidence,
        probability,
        conflict,
    )


def doubt(probability: float, evidence: PairEvidence, conflict: float, threshold: float) -> str:
    """Why a placement is not believed ("" when it is): its probability below ``threshold``
    (``join_probability``), and the evidence behind it (the wall no rival explains, the walls
    in free space)."""
    if probability >= threshold:
        return ""
    return (
        f"P {probability:.3f} < {threshold:g}: {evidence.margin:.1f} m of wall "
        f"no rival placement explains (of {evidence.score:.1f} m), {conflict:.1f} m in free space"
    )


def seen_through_near(
    links: Sequence[LinkCandidate],
    units: Mapping[UnitKey, MapUnit],
    views_of: ViewsOf,
    config: MergeConfig,
) -> tuple[float, float]:
    """Metres of wall that the set's placement puts in free space the other robot saw, either
    way: (of the walls within twice ``place_radius`` of the linked keyframes, of all the
    walls).

    Near the places the set is read two ways, and the lesser figure counts: the two maps as
    rigid bodies at the best-fitting link, or each wall placed by the confident link
    (``link_confidence``; all links when none is) whose keyframe on its map lies nearest
    (:func:`_placed_by_nearest_link`). The maps bend a little between their places; where
    links say so, each region then sits where its own place matched. A look-alike that fits
    a few places along a corridor is one placement at all of them (its links agree), so both
    readings put the walls around them where the other robot saw through (1.8 m for the
    test's look-alike building on one office robot). The rigid reading alone refused right
    sets: on intel cut into 4 robots two maps 0.2 m RMS from the reference (0.4-0.5 m at
    worst) put 3.9 m of wall in each other's free space even at the reference's own best
    rigid fit, and a right set of 26 links was refused at 7.5 m (0.6 m read piecewise). The
    piecewise reading alone refused others: a link at confidence 0.11, 0.44 m off, placed its
    region 2.1 m into the other's free space.

    Over the whole maps (the best-fitting link's placement, the maps rigid) a drifting map
    puts some wall in the other's free space even where it is placed right, hence the
    allowance in proportion to the set's matched wall; the look-alike building fits another
    office robot's map cleanly near its places, but puts 5.6 m of wall in its free space
    elsewhere (4.4 m allowed)."""
    best = oriented(max(links, key=lambda c: c.fit), links[0].source)
    first, second = units[best.first], units[best.second]
    views_first, views_second = views_of(best.first), views_of(best.second)
    T_first_second = _link_placement(best, units)
    limits = config.free_space_limits()
    whole = free_space_conflict(
        first.segments, views_first, second.segments, views_second, T_first_second, limits
    )
    # The same walls both ways: those within twice place_radius of the linked keyframes.
    reach = 2.0 * config.place_radius
    sides = [oriented(c, best.first) for c in links]
    walls_first = segments_near(
        first.segments, _poses(first, [lk.k_first for lk in sides])[:, :2], reach
    )
    walls_second = segments_near(
        second.segments, _poses(second, [lk.k_second for lk in sides])[:, :2], reach
    )
    rigid = free_space_conflict(
        walls_first, views_first, walls_second, views_second, T_first_second, limits
    )
    confident = [c for c in links if c.confidence >= config.link_confidence] or list(links)
    piecewise = 0.0
    if views_first is not None:
        by_second = [oriented(c, best.second) for c in confident]
        placed = _placed_by_nearest_link(walls_second, by_second, units)
        piecewise = seen_through_length(views_first, placed, limits)
    if views_second is not None:
        by_first = [oriented(c, best.first) for c in confident]
        placed = _placed_by_nearest_link(walls_first, by_first, units)
        piecewise = max(piecewise, seen_through_length(views_second, placed, limits))
    return min(rigid, piecewise), whole


def _placed_by_nearest_link(
    walls: FloatArray, links: Sequence[OrientedLink], units: Mapping[UnitKey, MapUnit]
) -> FloatArray:
    """``walls`` of map ``first`` (the links' ``first``) in map ``second``'s frame, each moved
    by the link whose ``first`` keyframe lies nearest its middle (of the links of one
    keyframe, the best-fitting)."""
    if len(walls) == 0:
        return walls
    by_keyframe: dict[int, OrientedLink] = {}
    for link in links:
        held = by_keyframe.get(link.k_first)
        if held is None or link.candidate.fit > held.candidate.fit:
            by_keyframe[link.k_first] = link
    chosen = list(by_keyframe.values())
    centres = _poses(units[chosen[0].first], [link.k_first for link in chosen])[:, :2]
    middles = 0.5 * (walls[:, :2] + walls[:, 2:])
    offsets = middles[:, None, :] - centres[None, :, :]
    nearest = np.argmin(np.hypot(offsets[..., 0], offsets[..., 1]), axis=1)
    placed = np.empty_like(walls)
    for row, link in enumerate(chosen):
        mine = nearest == row
        # T_second_first: the other side's placement, read from ``second``.
        placed[mine] = se2.transform_segments(se2.invert(_link_placement(link, units)), walls[mine])
    return placed


def placement_weights(links: Sequence[LinkCandidate]) -> FloatArray:
    """Each link's weight: the probability that it is its place's right placement on that
    map. A place searched on a map gives its best placement and its best rival, each with a
    calibrated confidence judged against the other: exclusive hypotheses about one place
    (at most one is right). Their odds o = c / (1 - c) combine as P(i) = o_i / (1 + sum o),
    the 1 standing for "neither" (a lone candidate keeps its confidence). Summing raw
    confidences instead counted one place's ambiguity twice: three right links at 0.97-1.0
    were vetoed as ambiguous by their own places' rivals at 0.2-0.74 lying 6 m along the
    office corridor (1.62 against 2.96, within the factor of 2 of ``link_set_uniqueness``)."""
    confidence = np.clip([c.confidence for c in links], 1e-6, 1.0 - 1e-6)
    odds = confidence / (1.0 - confidence)
    place = [(c.source, c.centre, c.target) for c in links]
    total: dict[tuple[UnitKey, int, UnitKey], float] = {}
    for key, o in zip(place, odds, strict=True):
        total[key] = total.get(key, 0.0) + float(o)
    return np.array([o / (1.0 + total[key]) for key, o in zip(place, odds, strict=True)])


def _places(links: Sequence[LinkCandidate]) -> int:
    """Distinct places the links join, counted on the side with more: a place of map A found
    on B and a place of B found on A at the same spot see the same walls, one piece of
    evidence (a look-alike building that fits one place of A fits B's place there too)."""
    per_side: dict[UnitKey, set[int]] = {}
    for c in links:
        per_side.setdefault(c.source, set()).add(c.centre)
    return max((len(centres) for centres in per_side.values()), default=0)


def cycle_error(
    chain: Sequence[OrientedLink], units: Mapping[UnitKey, MapUnit]
) -> tuple[float, float, float]:
    """How far a cycle of links fails to close: (metres, radians, metres run inside the maps).
    ``chain[i].second`` is ``chain[i + 1].first`` and the last link returns to the first map."""
    T = np.eye(3)
    entry = chain[-1].k_second  # where the cycle enters the first map
    path = 0.0
    for link in chain:
        unit = units[link.first]
        a, b = _poses(unit, [entry, link.k_first])
        T = T @ se2.invert(se2.matrix_from_pose(*a)) @ se2.matrix_from_pose(*b) @ link.T
        path += float(np.hypot(*(b[:2] - a[:2])))
        entry = link.k_second
    x, y, theta = se2.pose_from_matrix(T)
    return float(np.hypot(x, y)), abs(theta), path


class JoinLimits(NamedTuple):
    """What accepting pairs over the groups reads of the merge config: the slack a cycle of
    links may miss closing by, per metre run inside the maps (m, rad: ``link_pair_slack``,
    ``link_pair_angle_slack``; the first is also a robot's allowance beyond ``max_speed``),
    and the probability a join of groups must keep (``join_probability``)."""

    distance_slack: float
    angle_slack: float
    join_probability: float


def closes(
    chain: Sequence[OrientedLink], units: Mapping[UnitKey, MapUnit], limits: JoinLimits
) -> bool:
    """Does a cycle of links close within the tolerance (per metre run inside the maps)?"""
    shift, turn, path = cycle_error(chain, units)
    return shift <= RIGHT_DISTANCE + limits.distance_slack * path and turn <= (
        RIGHT_ANGLE + limits.angle_slack * path
    )


@dataclasses.dataclass(frozen=True)
class Accepted:
    """The pairs accepted and the groups of maps they join."""

    pairs: list[PairVerdict]  # accepted, in the order taken
    refused: list[PairVerdict]  # consistent within the pair, refused over the groups
    groups: list[list[UnitKey]]  # connected maps, largest first
    tree: dict[UnitKey, list[tuple[UnitKey, PairVerdict]]]  # spanning tree adjacency


# Why a pair was refused over the groups (the start of PairVerdict.reason).
TOO_FAST = "a robot would drive"
GROUP_DOUBT = "joined with every map of both groups"
# metres of wall a join puts in free space: (every map of the joined group placed in the
# root's frame, the maps of one side, those of the other) -> metres
# the walls in free space of joining two groups: (group A's maps placed in its root's frame,
# group B's in its root's, T_roota_rootb) -> metres (pair_evidence.group_conflict)
GroupConflict = Callable[
    [Mapping[UnitKey, FloatArray], Mapping[UnitKey, FloatArray], FloatArray], float
]


def accept_pairs(
    verdicts: Sequence[PairVerdict],
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
    model: LogisticModel,
    reaches: Mapping[str, RobotReach] | None = None,
    group_conflict: GroupConflict | None = None,
) -> Accepted:
    """Candidate pairs, most probable first: a pair joining two groups joins them, one inside
    a group must close the cycle through the group's tree (module doc). With ``reaches``
    (:mod:`~multi_robot_mapper.core.merging.motion`) a join is refused when the joined group
    would need a robot to drive faster than ``max_speed`` between two of its pieces; with
    ``group_conflict`` (:func:`~core.merging.pair_evidence.group_conflict`), a join of groups
    of more than one map is weighed again with its walls in free space measured on every map
    of both."""
    order = sorted(
        (v for v in verdicts if v.accepted), key=lambda v: (-v.probability, -v.weight, v.pair)
    )
    parent: dict[UnitKey, UnitKey] = {key: key for key in units}
    # Each group's maps placed rigidly in its root's frame along the tree's best links.
    placed: dict[UnitKey, dict[UnitKey, FloatArray]] = {key: {key: np.eye(3)} for key in units}
    tree: dict[UnitKey, list[tuple[UnitKey, PairVerdict]]] = {key: [] for key in units}
    taken: list[PairVerdict] = []
    refused: list[PairVerdict] = []
    limits = JoinLimits(
        config.link_pair_slack, config.link_pair_angle_slack, config.join_probability
    )
    for verdict in order:
        a, b = verdict.pair
        if _root(parent, a) == _root(parent, b):
            if _closes_cycle(verdict, tree, units, limits):
                taken.append(verdict)
            else:
                refused.append(
                    dataclasses.replace(verdict, accepted=False, reason="breaks a cycle")
                )
            continue
        group_a, group_b = placed[_root(parent, a)], placed[_root(parent, b)]
        T_ra_rb = group_a[a] @ placement(verdict, a, units) @ se2.invert(group_b[b])
        joined = {**group_a, **{key: T_ra_rb @ T for key, T in group_b.items()}}
        judged = _judge_join(
            verdict,
            joined,
            (group_a, group_b, T_ra_rb),
            units,
            limits,
            model,
            reaches,
            group_conflict,
        )
        if not judged.accepted:
            refused.append(judged)
            continue
        del placed[_root(parent, b)]
        placed[_root(parent, a)] = joined
        parent[_root(parent, b)] = _root(parent, a)
        tree[a].append((b, judged))
        tree[b].append((a, judged))
        taken.append(judged)
    return Accepted(taken, refused, _ordered_groups(placed.values(), units), tree)


def _root(parent: dict[UnitKey, UnitKey], key: UnitKey) -> UnitKey:
    """The root of ``key``'s group in the union-find forest ``parent`` (its path halved on
    the way)."""
    while parent[key] != key:
        parent[key] = parent[parent[key]]
        key = parent[key]
    return key


def _closes_cycle(
    verdict: PairVerdict,
    tree: Mapping[UnitKey, list[tuple[UnitKey, PairVerdict]]],
    units: Mapping[UnitKey, MapUnit],
    limits: JoinLimits,
) -> bool:
    """Does the pair of ``verdict``, between two maps of one group, close the cycle through
    the group's ``tree`` (:func:`closes`)?"""
    a, b = verdict.pair
    chain = _tree_path(tree, b, a)  # b ... a through the tree, then the new link a -> b
    return closes([_best(v, x) for x, v in chain] + [_best(verdict, a)], units, limits)


def _ordered_groups(
    groups: Iterable[Iterable[UnitKey]], units: Mapping[UnitKey, MapUnit]
) -> list[list[UnitKey]]:
    """Groups of maps, most robots first, then the longest maps."""
    return sorted(
        (sorted(g) for g in groups),
        key=lambda g: (-len({robot for robot, _ in g}), -sum(units[k].length for k in g), g),
    )


def _judge_join(
    verdict: PairVerdict,
    joined: Mapping[UnitKey, FloatArray],
    groups: tuple[Mapping[UnitKey, FloatArray], Mapping[UnitKey, FloatArray], FloatArray],
    units: Mapping[UnitKey, MapUnit],
    limits: JoinLimits,
    model: LogisticModel,
    reaches: Mapping[str, RobotReach] | None,
    group_conflict: GroupConflict | None,
) -> PairVerdict:
    """The pair's verdict as a join of its two groups (``groups``: each group's maps in its
    root's frame and T_roota_rootb; ``joined``: every map of both in A's root frame, as the
    join places them): refused when a robot would have to drive too fast, or, for groups of
    more than one map, when the pair's evidence with the walls it puts in the free space of
    every map of both falls below ``limits.join_probability``."""
    excess = (
        0.0 if reaches is None else motion_excess(joined, units, reaches, limits.distance_slack)
    )
    if excess > 0.0:
        reason = f"{TOO_FAST} {excess:.1f} m beyond max_speed"
        return dataclasses.replace(verdict, accepted=False, reason=reason)
    group_a, group_b, T_ra_rb = groups
    if group_conflict is None or len(group_a) + len(group_b) <= 2:
        return verdict  # two maps alone: the pair's own probability
    evidence = verdict.evidence
    if evidence is None:
        return verdict
    # The pair's own evidence, its walls in free space now measured on every map of both
    # groups (pair_evidence.group_conflict).
    conflict = max(verdict.conflict, group_conflict(group_a, group_b, T_ra_rb))
    probability = model.probability(evidence.features(conflict))
    doubted = doubt(probability, evidence, conflict, limits.join_probability)
    return dataclasses.replace(
        verdict,
        accepted=not doubted,
        reason=f"{GROUP_DOUBT}: {doubted}" if doubted else "",
        probability=probability,
        conflict=conflict,
    )


def _best(verdict: PairVerdict, first: UnitKey) -> OrientedLink:
    """The set's best-fitting link, read from map ``first``."""
    return _best_of(verdict.links, first)


def _best_of(links: Sequence[LinkCandidate], first: UnitKey) -> OrientedLink:
    """The best-fitting of ``links``, read from map ``first``."""
    return oriented(max(links, key=lambda c: c.fit), first)


def placement(verdict: PairVerdict, first: UnitKey, units: Mapping[UnitKey, MapUnit]) -> FloatArray:
    """T_first_second: the pair's other map placed in map ``first`` as a rigid body, by the
    set's best-fitting link."""
    return _link_placement(_best(verdict, first), units)


def _link_placement(link: OrientedLink, units: Mapping[UnitKey, MapUnit]) -> FloatArray:
    """T_first_second by one link: its keyframes' poses in their maps, and the link."""
    a = _poses(units[link.first], [link.k_first])[0]
    b = _poses(units[link.second], [link.k_second])[0]
    return se2.matrix_from_pose(*a) @ link.T @ se2.invert(se2.matrix_from_pose(*b))


def _tree_path(
    tree: Mapping[UnitKey, list[tuple[UnitKey, PairVerdict]]], start: UnitKey, goal: UnitKey
) -> list[tuple[UnitKey, PairVerdict]]:
    """The tree's pairs from ``start`` to ``goal``: (the map each is read from, the pair)."""
    previous: dict[UnitKey, tuple[UnitKey, PairVerdict] | None] = {start: None}
    frontier = [start]
    while frontier:
        key = frontier.pop(0)
        if key == goal:
            break
        for other, verdict in tree[key]:
            if other not in previous:
                previous[other] = (key, verdict)
                frontier.append(other)
    path: list[tuple[UnitKey, PairVerdict]] = []
    key = goal
    while previous[key] is not None:
        before, verdict = previous[key]  # type: ignore[misc]
        path.append((before, verdict))
        key = before
    return path[::-1]
