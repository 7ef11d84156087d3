"""The probability that a map joined to the reference is placed right, from its paths of joins
(issue 46).

A map is placed right when every join along some path of joins from the reference is right.
Every join of a group agrees with every other (a join inside a group is taken only when its
cycle closes: :func:`~core.merging.consistency.accept_pairs`), so two paths to a map put it in
the same place, and the map is wrong only when *every* path holds a wrong join: wrong joins that
agree by chance are counted as if they always did. With the joins' evidence independent, paths
that share no join fail together with the product of their failing alone, and
``1 - prod(1 - P(path))`` over edge-disjoint paths (taken greedily, the most probable first) is a
lower bound on the map's probability of being right. One path gives the product of its joins'
probabilities. Only joins that reach ``join_probability`` on their own are paths: sets short of
it that agree with each other are not independent evidence (robots that see the same row of
equal rooms agree on the same wrong room; docs/decisions.md).
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence

from multi_robot_mapper.core.merging.places import UnitKey

Edge = tuple[UnitKey, UnitKey, float]  # two maps and the probability of the join between them

# Edge-disjoint paths counted per map: with joins of P >= 0.99 a fourth path changes P by less
# than 1e-6.
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
