"""The joint graph of the maps joined to the reference (:mod:`~multi_robot_mapper.core.merging.
joint`, step 4): every keyframe of those maps a node, edges between a map's keyframes from its
published poses, every accepted link between maps under the DCS robust kernel; solved in one
batch (gtsam, :class:`~multi_robot_mapper.core.pose_graph.PoseGraph`) from the maps placed
rigidly along the accepted pairs, then kept and brought up to date from one update to the next
(:mod:`~multi_robot_mapper.core.merging.kept_graph`)."""

from __future__ import annotations

import dataclasses
import hashlib
from collections import OrderedDict
from collections.abc import Mapping
from typing import Any, NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.consistency import Accepted, placement
from multi_robot_mapper.core.merging.joint_graph_config import JointGraphConfig
from multi_robot_mapper.core.merging.kept_graph import GraphSlot, GraphSpec, KeptGraph, NamedEdge
from multi_robot_mapper.core.merging.place_links import LinkCandidate
from multi_robot_mapper.core.merging.place_matching import cached
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass
class Solution:
    """Optimised keyframe poses and fitted frames of the maps placed in ``map``."""

    poses: dict[UnitKey, FloatArray]  # (K, 3) T_map_keyframe, rows as in the unit
    frames: dict[UnitKey, FloatArray]  # 3x3 T_map_unit (rigid fit of its keyframes)
    order: list[UnitKey]  # placing order (the reference first)
    accepted: list[LinkCandidate] = dataclasses.field(default_factory=list)  # in the graph
    nodes: int = 0
    edges: int = 0
    iterations: int = 0


def solved(
    units: Mapping[UnitKey, MapUnit],
    group: list[UnitKey],
    ref_unit: UnitKey | None,
    accepted: Accepted,
    model: GraphModel,
    last: tuple[Any, Solution] | None,
    intra: OrderedDict[Any, Any],
    slot: GraphSlot | None = None,
) -> tuple[Any, Solution]:
    """:func:`_solve`, or ``last`` (the last update's solution and what it was solved from)
    where the graph is the same; with what it was solved from. ``intra``: each map's edges
    kept per content, from one update to the next; ``model``: :func:`graph_model`; ``slot``:
    where the graph is kept from one update to the next (None: solved afresh)."""
    key = (
        tuple((k, units[k].content) for k in sorted(group)),
        ref_unit,
        tuple(tuple(c.identity() for c in verdict.links) for verdict in accepted.pairs),
        tuple((k, tuple((o, v.pair) for o, v in accepted.tree[k])) for k in sorted(accepted.tree)),
        model,
    )
    if last is not None and last[0] == key:
        return last
    return key, _solve(units, group, ref_unit, accepted, model, intra, slot)


def _solve(
    units: Mapping[UnitKey, MapUnit],
    group: list[UnitKey],
    ref_unit: UnitKey | None,
    accepted: Accepted,
    model: GraphModel,
    intra: OrderedDict[Any, Any],
    slot: GraphSlot | None,
) -> Solution:
    """The graph of every keyframe of the maps joined to ``ref_unit`` (module doc), solved:
    the last update's graph in ``slot`` brought up to date where it can be
    (:class:`~multi_robot_mapper.core.merging.kept_graph.KeptGraph`), else from the maps
    placed rigidly along the accepted pairs. Either reaches the optimum of the same factors
    (the kept graph to within ISAM2's relinearisation threshold), so that a merger started
    again on the same maps puts every robot in the same place."""
    if ref_unit is None:
        return Solution({}, {}, [])
    rigid = _rigid_placements(ref_unit, accepted, units, set(group))
    order = list(rigid)
    spec, links = _spec(units, order, rigid, accepted, model, intra)
    estimate, iterations = spec.start, 0
    if links:
        kept = _brought_up_to_date(slot.kept if slot is not None else None, spec)
        if slot is not None:
            slot.kept = kept
        estimate, iterations = kept.poses(spec.nodes), kept.iterations
    bounds = np.cumsum([0] + [len(units[key].index) for key in order])
    poses = {key: estimate[bounds[i] : bounds[i + 1]] for i, key in enumerate(order)}
    frames = {key: se2.rigid_fit(units[key].poses, poses[key]) for key in order}
    # ``map`` is the reference map's frame exactly: its fitted frame is the identity.
    T_fix = se2.invert(frames[ref_unit])
    fix = np.array(se2.pose_from_matrix(T_fix))
    for key in order:
        frames[key] = np.eye(3) if key == ref_unit else T_fix @ frames[key]
        poses[key] = se2.compose_each(np.broadcast_to(fix, poses[key].shape), poses[key])
    return Solution(poses, frames, order, links, len(spec.nodes), len(spec.edges), iterations)


def _brought_up_to_date(kept: KeptGraph | None, spec: GraphSpec) -> KeptGraph:
    """``kept`` brought up to ``spec`` where it carries it, else ``spec``'s graph solved from
    its rigid start (also where gtsam fails on the increment: an update half taken leaves
    the kept graph unusable, never the merge)."""
    if kept is not None and kept.carries(spec):
        try:
            kept.update(spec)
            return kept
        except RuntimeError:  # gtsam's (an indeterminate system, a missing key)
            pass
    return KeptGraph(spec)


def _spec(
    units: Mapping[UnitKey, MapUnit],
    order: list[UnitKey],
    rigid: Mapping[UnitKey, FloatArray],
    accepted: Accepted,
    model: GraphModel,
    intra: OrderedDict[Any, Any],
) -> tuple[GraphSpec, list[LinkCandidate]]:
    """The graph of the maps ``order`` (the reference first, its first keyframe anchored),
    placed rigidly (``rigid``), with their edges and the accepted links between them; the
    links."""
    nodes = [(key, int(index)) for key in order for index in units[key].index]
    published = np.vstack([units[key].poses for key in order]).reshape(-1, 3)
    start = np.vstack(
        [
            se2.compose_each(
                np.broadcast_to(se2.pose_from_matrix(rigid[key]), units[key].poses.shape),
                units[key].poses,
            )
            for key in order
        ]
    ).reshape(-1, 3)
    edges = [edge for key in order for edge in _intra_edges(units[key], model.edges, intra)]
    links = _links(accepted, units, set(order))
    edges += [_link_edge(candidate, units) for candidate in links]
    spec = GraphSpec(nodes, start, published, nodes[0], edges, model.link_robust_scale)
    return spec, links


def _links(
    accepted: Accepted, units: Mapping[UnitKey, MapUnit], placed: set[UnitKey]
) -> list[LinkCandidate]:
    """Every accepted link between two maps of ``placed``."""
    return [
        candidate
        for verdict in accepted.pairs
        for candidate in verdict.links
        if candidate.source in placed and candidate.target in placed
    ]


def _link_edge(candidate: LinkCandidate, units: Mapping[UnitKey, MapUnit]) -> NamedEdge:
    """A link between two maps as a robust edge from its keyframe to its place's centre."""
    x, y, theta = (float(v) for v in candidate.T_keyframe_centre)
    return NamedEdge(
        (candidate.target, int(candidate.keyframe)),
        (candidate.source, int(candidate.centre)),
        (x, y, theta),
        candidate.information,
        robust=True,
    )


def _rigid_placements(
    ref_unit: UnitKey,
    accepted: Accepted,
    units: Mapping[UnitKey, MapUnit],
    members: set[UnitKey],
) -> dict[UnitKey, FloatArray]:
    """Each map of ``members`` joined to the reference placed rigidly through the accepted
    pairs' best links (breadth first: the placing order)."""
    placed: dict[UnitKey, FloatArray] = {ref_unit: np.eye(3)}
    queue = [ref_unit]
    while queue:
        key = queue.pop(0)
        for other, verdict in sorted(accepted.tree[key], key=lambda item: item[0]):
            if other in placed or other not in members:
                continue
            placed[other] = placed[key] @ placement(verdict, key, units)
            queue.append(other)
    return placed


def _intra_pairs(unit: MapUnit, radius: float) -> list[tuple[int, int]]:
    """Rows of a map's keyframes joined by an edge: consecutive ones, and each keyframe with up
    to three earlier ones within ``radius`` (not already consecutive)."""
    pairs = [(row, row + 1) for row in range(len(unit.index) - 1)]
    if radius > 0.0 and len(unit.index) > 2:
        xy = unit.poses[:, :2]
        for row in range(2, len(xy)):
            gap = np.hypot(*(xy[: row - 1] - xy[row]).T)
            near = np.flatnonzero(gap <= radius)
            for other in near[np.argsort(gap[near], kind="stable")][:3]:
                pairs.append((int(other), row))
    return pairs


# JointGraphConfig's radius, sigma, drift, angle_sigma, angle_drift
_EdgeModel = tuple[float, float, float, float, float]


class GraphModel(NamedTuple):
    """What the joint graph reads of its config (``merge.graph``): the scale of the links'
    robust kernel, and what the edges inside a map read (:data:`_EdgeModel`)."""

    link_robust_scale: float
    edges: _EdgeModel


def graph_model(graph: JointGraphConfig) -> GraphModel:
    """The joint graph's settings of ``graph``."""
    edges = (graph.radius, graph.sigma, graph.drift, graph.angle_sigma, graph.angle_drift)
    return GraphModel(graph.link_robust_scale, edges)


def _intra_edges(unit: MapUnit, model: _EdgeModel, kept: OrderedDict[Any, Any]) -> list[NamedEdge]:
    """The edges between keyframes of one map (:func:`_intra_pairs`), from their published
    poses, with a standard deviation growing with the distance between them (``model``); the
    same map seen again (most maps, most updates) reuses them."""
    content = hashlib.sha1(unit.poses.tobytes()).hexdigest()
    key = (unit.key, content, model)
    return cast(list[NamedEdge], cached(kept, key, lambda: _intra_named(unit, model)))


def _intra_named(unit: MapUnit, model: _EdgeModel) -> list[NamedEdge]:
    pairs, relative, information = _intra_arrays(unit, model)
    index = unit.index.tolist()
    return [
        NamedEdge((unit.key, index[a]), (unit.key, index[b]), (x, y, t), info, robust=False)
        for (a, b), (x, y, t), info in zip(
            pairs.tolist(), relative.tolist(), information, strict=True
        )
    ]


def _intra_arrays(unit: MapUnit, model: _EdgeModel) -> tuple[IntArray, FloatArray, FloatArray]:
    """Rows joined, their relative poses and information matrices (vectorised)."""
    radius, graph_sigma, drift, angle_sigma, angle_drift = model
    pairs = np.array(_intra_pairs(unit, radius), dtype=np.int64).reshape(-1, 2)
    a, b = unit.poses[pairs[:, 0]], unit.poses[pairs[:, 1]]
    relative = se2.between_each(a, b)
    distance = np.hypot(*(b[:, :2] - a[:, :2]).T)
    sigma = graph_sigma + drift * distance
    angle = angle_sigma + angle_drift * distance
    information = np.zeros((len(pairs), 3, 3))
    information[:, 0, 0] = information[:, 1, 1] = sigma**-2
    information[:, 2, 2] = angle**-2
    return pairs, relative, information
