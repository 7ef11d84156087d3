"""The joint graph kept between merge updates (core/merging/kept_graph.py): brought up to date
with keyframes added and edges changed, it reaches the optimum the same graph reaches solved
afresh; a change the increment cannot carry is refused (the caller starts again); a pickled
slot is empty."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.kept_graph import GraphSlot, GraphSpec, KeptGraph, NamedEdge

A, B = ("a", 0), ("b", 0)
INFO = np.diag([100.0, 100.0, 400.0])


def spec_of(keyframes: int, bent: float = 0.0, link_to: int = 3) -> GraphSpec:
    """Two maps of ``keyframes`` keyframes each along a line 1 m apart, map b 2 m beside map
    a; edges between consecutive keyframes (map a's last one bent by ``bent`` rad), a loop
    edge from each map's last keyframe to its first that disagrees with the chain by 0.2 m
    (the optimum spreads it), and one robust link from a's keyframe ``link_to`` to b's."""
    line = np.column_stack(
        (np.arange(keyframes, dtype=float), np.zeros(keyframes), np.zeros(keyframes))
    )
    nodes = [(A, k) for k in range(keyframes)] + [(B, k) for k in range(keyframes)]
    published = np.vstack((line, line))
    start = np.vstack((line, line + np.array([0.0, 2.0, 0.0])))
    edges = []
    for unit in (A, B):
        for k in range(keyframes - 1):
            turn = bent if (unit == A and k == keyframes - 2) else 0.0
            edges.append(NamedEdge((unit, k), (unit, k + 1), (1.0, 0.0, turn), INFO, False))
        loop = (-(keyframes - 1) + 0.2, 0.0, 0.0)
        edges.append(NamedEdge((unit, keyframes - 1), (unit, 0), loop, INFO, False))
    edges.append(NamedEdge((A, link_to), (B, link_to), (0.0, 2.0, 0.0), INFO, True))
    return GraphSpec(nodes, start, published, (A, 0), edges, 1.0)


def near(kept: KeptGraph, fresh: KeptGraph, nodes: list, metres: float, radians: float) -> None:
    got, want = kept.poses(nodes), fresh.poses(nodes)
    assert np.hypot(*(got[:, :2] - want[:, :2]).T).max() < metres
    assert np.abs(se2.wrap_angle(got[:, 2] - want[:, 2])).max() < radians


def test_a_kept_graph_grown_and_changed_reaches_the_fresh_graphs_optimum() -> None:
    kept = KeptGraph(spec_of(5))
    for grown in (spec_of(6), spec_of(8), spec_of(8, bent=0.05), spec_of(9, link_to=5)):
        assert kept.carries(grown)
        keys = dict(kept.keys)
        kept.update(grown)
        # Nodes keep their keys; new ones are added; edges follow the spec exactly.
        assert all(kept.keys[name] == key for name, key in keys.items())
        assert set(kept.keys) == set(grown.nodes)
        assert set(kept.edge_ids) == {edge.identity() for edge in grown.edges}
        assert len(kept.graph.edges) == len(grown.edges)
        fresh = KeptGraph(grown)
        near(kept, fresh, grown.nodes, 1e-4, 1e-4)
        assert kept.graph.objective() <= fresh.graph.objective() * (1 + 1e-6)


def test_what_the_increment_cannot_carry_is_refused() -> None:
    kept = KeptGraph(spec_of(6))
    shorter = spec_of(5)  # a keyframe gone
    assert not kept.carries(shorter)
    assert not kept.carries(dataclasses.replace(spec_of(6), anchor=(B, 0)))
    assert not kept.carries(dataclasses.replace(spec_of(6), robust_scale=2.0))
    grown = spec_of(7)
    with_new_map = dataclasses.replace(
        grown,
        nodes=[*grown.nodes, (("c", 0), 0)],
        start=np.vstack((grown.start, [[0.0, 4.0, 0.0]])),
        published=np.vstack((grown.published, [[0.0, 0.0, 0.0]])),
    )
    assert not kept.carries(with_new_map)  # a map the graph never held starts rigidly placed
    assert kept.carries(grown)


def test_new_keyframes_start_where_their_map_lies_in_the_graph() -> None:
    # Map b's keyframes were put 2 m beside a's; a keyframe added to b starts there too (its
    # map's frame fitted to the graph), not at its published pose near a's.
    kept = KeptGraph(spec_of(5))
    grown = spec_of(6)
    start = kept._placed_new(grown, [grown.nodes.index((B, 5))])
    np.testing.assert_allclose(start[0, 1], kept.poses([(B, 4)])[0, 1], atol=0.05)
    assert abs(start[0, 1] - 2.0) < 0.1


def test_a_pickled_slot_is_empty() -> None:
    slot = GraphSlot(KeptGraph(spec_of(4)))
    again = pickle.loads(pickle.dumps(slot))
    assert again.kept is None and slot.kept is not None
