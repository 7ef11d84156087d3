"""The joint graph kept between merge updates (issue 50: "ISAM2 kept between updates"). An
update names its graph by what it is made of (:class:`GraphSpec`: each node a map's keyframe,
each edge by its two keyframes and its measurement), not by rows; the graph of the last update
(:class:`KeptGraph`, gtsam's ISAM2 under :class:`~multi_robot_mapper.core.pose_graph.
PoseGraph`) takes the difference: the keyframes added, their edges, the edges whose
measurement changed (a keyframe a local mapper moved, a link re-matched) or that are gone, then
relinearising steps until none relinearises a keyframe. While 8 robots drive, an update adds
a keyframe or two per map to a graph of 1 000; solved again from the maps placed rigidly, it
took 0.17 s of each update (gtsam's Levenberg-Marquardt 70 %, the Python build of 4 000
factors the rest).

A change the increment cannot carry starts the graph again from the rigid placements, solved
in one batch (:meth:`~multi_robot_mapper.core.pose_graph.PoseGraph.solve`): another reference
or anchor keyframe, a keyframe gone, a map joined that the last graph did not hold, another
robust scale. Both reach the same optimum of the same factors; the kept graph to within
ISAM2's relinearisation threshold (measured along the live bench: docs/decisions.md "The joint
graph kept between updates")."""

from __future__ import annotations

import dataclasses
from collections.abc import Hashable, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.places import UnitKey
from multi_robot_mapper.core.pose_graph import Edge, PoseGraph

FloatArray = NDArray[np.float64]
NodeName = tuple[UnitKey, int]  # (the map, a keyframe's index in it)
# ISAM2's relinearisation threshold (m, rad) here, a hundredth of the local mapper's 0.01: the
# links' DCS weights are those of the last linearisation, and the estimate's cost stayed 0.5 %
# above the optimum's at 0.01 (0.1 % at 0.001); at 1e-4 every keyframe of 134 live updates of
# intel cut into 8 lay within 1.0 mm of the optimum (Levenberg-Marquardt from the rigid start:
# 3.0 mm), at 0.04 s of CPU an update against 0.15 s (docs/decisions.md).
_RELINEARIZE = 1e-4


@dataclasses.dataclass(frozen=True)
class NamedEdge:
    """An edge of the joint graph between two keyframes named by map and index."""

    first: NodeName
    second: NodeName
    T_first_second: tuple[float, float, float]
    information: FloatArray  # (3, 3)
    robust: bool

    def identity(self) -> Hashable:
        """What the edge says: an edge with the same identity is the same factor."""
        return (
            self.first,
            self.second,
            self.T_first_second,
            self.information.tobytes(),
            self.robust,
        )


@dataclasses.dataclass(frozen=True)
class GraphSpec:
    """One update's joint graph: its nodes in order, where each starts (the maps placed
    rigidly) and where it lies in its own map (its published pose), the anchored node, the
    edges and the robust kernel's scale."""

    nodes: list[NodeName]
    start: FloatArray  # (N, 3) T_map_keyframe, the rigid placement
    published: FloatArray  # (N, 3) T_unit_keyframe
    anchor: NodeName
    edges: list[NamedEdge]
    robust_scale: float


class KeptGraph:
    """The last update's graph, solved, with the name of each node and edge in it."""

    def __init__(self, spec: GraphSpec) -> None:
        """The graph of ``spec`` from its rigid start, solved in one batch."""
        self.graph = PoseGraph(spec.robust_scale, "dcs", _RELINEARIZE)
        self.anchor = spec.anchor
        self.robust_scale = spec.robust_scale
        self.keys: dict[NodeName, int] = {}
        self.edge_ids: dict[Hashable, list[int]] = {}  # the graph's edges of each identity
        self._add_nodes(spec, range(len(spec.nodes)), spec.start)
        self._add_edges(spec.edges)
        self.iterations = self.graph.solve()

    def carries(self, spec: GraphSpec) -> bool:
        """True when ``spec`` is this graph with nodes added and edges changed: the same
        anchor and scale, every node still there, and every map with a node already here."""
        if (spec.anchor, spec.robust_scale) != (self.anchor, self.robust_scale):
            return False
        wanted = set(spec.nodes)
        if not wanted.issuperset(self.keys):
            return False
        held_maps = {unit for unit, _ in self.keys}
        return all(unit in held_maps for unit, _ in spec.nodes)

    def update(self, spec: GraphSpec) -> None:
        """Take ``spec`` (which :meth:`carries`): its new keyframes placed by their map's frame
        as the graph holds it now, edges gone removed, new ones added, then ISAM2 steps until
        none relinearises a keyframe."""
        new_rows = [row for row, name in enumerate(spec.nodes) if name not in self.keys]
        if new_rows:
            self._add_nodes(spec, new_rows, self._placed_new(spec, new_rows))
        wanted: dict[Hashable, list[NamedEdge]] = {}
        for edge in spec.edges:  # the same edge twice (two verdicts' links) counts twice
            wanted.setdefault(edge.identity(), []).append(edge)
        for identity in list(self.edge_ids):
            ids = self.edge_ids[identity]
            while len(ids) > len(wanted.get(identity, ())):
                self.graph.remove_edge(ids.pop())
            if not ids:
                del self.edge_ids[identity]
        added = [e for i, es in wanted.items() for e in es[len(self.edge_ids.get(i, ())) :]]
        self._add_edges(added)
        self.iterations = self.graph.settle()

    def poses(self, nodes: list[NodeName]) -> FloatArray:
        """(len(nodes), 3) the estimate of each node."""
        estimate = self.graph.poses()
        return np.array([estimate[self.keys[name]] for name in nodes]).reshape(-1, 3)

    def _placed_new(self, spec: GraphSpec, new_rows: list[int]) -> FloatArray:
        """Where new keyframes start: each map's frame fitted to where the graph holds its
        keyframes now (:func:`~multi_robot_mapper.core.se2.rigid_fit`), applied to their
        published poses."""
        estimate = self.graph.poses()
        held: dict[UnitKey, list[int]] = {}
        for row, (unit, index) in enumerate(spec.nodes):
            if (unit, index) in self.keys:
                held.setdefault(unit, []).append(row)
        frames: dict[UnitKey, FloatArray] = {}
        for unit, rows in held.items():
            now = np.array([estimate[self.keys[spec.nodes[row]]] for row in rows])
            frames[unit] = se2.rigid_fit(spec.published[rows], now)
        start = np.zeros((len(new_rows), 3))
        for position, row in enumerate(new_rows):
            T = frames[spec.nodes[row][0]] @ se2.matrix_from_pose(*spec.published[row])
            start[position] = se2.pose_from_matrix(T)
        return start

    def _add_nodes(self, spec: GraphSpec, rows: Sequence[int], start: FloatArray) -> None:
        for position, row in enumerate(rows):
            name = spec.nodes[row]
            key = len(self.keys)
            self.keys[name] = key
            x, y, theta = (float(v) for v in start[position])
            self.graph.add_node(key, (x, y, theta), anchored=name == spec.anchor)

    def _add_edges(self, edges: list[NamedEdge]) -> None:
        for edge in edges:
            first, second = self.keys[edge.first], self.keys[edge.second]
            added = Edge(first, second, edge.T_first_second, edge.information, edge.robust)
            self.edge_ids.setdefault(edge.identity(), []).append(self.graph.add_edge(added))


@dataclasses.dataclass
class GraphSlot:
    """Where a merger's state keeps its :class:`KeptGraph` (None: the next update builds
    one). gtsam's solver does not pickle: a state pickled (a result saved, a worker's answer)
    carries an empty slot, and the next update builds the graph again."""

    kept: KeptGraph | None = None

    def __getstate__(self) -> dict[str, None]:
        return {"kept": None}

    def __setstate__(self, state: dict[str, None]) -> None:
        self.kept = None
