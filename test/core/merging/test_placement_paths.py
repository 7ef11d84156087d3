"""A map's probability of being placed right from every independent path of joins
(core/merging/placement_paths.py)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core.merging.placement_paths import chain_probabilities

A, B, C, D = ("a", 0), ("b", 0), ("c", 0), ("d", 0)


def test_one_path_is_the_product_of_its_joins() -> None:
    chains = chain_probabilities(A, [(A, B, 0.99), (B, C, 0.98)])
    assert chains == pytest.approx({A: 1.0, B: 0.99, C: 0.99 * 0.98})


def test_paths_that_share_no_join_fail_only_together() -> None:
    # c reached by a-c and by a-b-c: wrong only when both paths hold a wrong join.
    chains = chain_probabilities(A, [(A, B, 0.9), (B, C, 0.9), (A, C, 0.9)])
    assert chains[C] == pytest.approx(1.0 - 0.1 * (1.0 - 0.81))
    # b too: a-b alone, and a-c-b
    assert chains[B] == pytest.approx(1.0 - 0.1 * (1.0 - 0.81))


def test_paths_through_one_join_count_it_once() -> None:
    # d hangs on a single join a-b: however many paths from b, d is wrong when a-b is.
    edges = [(A, B, 0.9), (B, C, 0.999), (C, D, 0.999), (B, D, 0.999)]
    assert chain_probabilities(A, edges)[D] <= 0.9
    assert chain_probabilities(None, edges) == {}


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 5), st.integers(0, 5), st.floats(0.5, 0.999)),
        min_size=1,
        max_size=12,
    )
)
def test_more_paths_never_make_a_map_less_probable_than_its_best_one(
    raw: list[tuple[int, int, float]],
) -> None:
    edges = [((f"r{a}", 0), (f"r{b}", 0), p) for a, b, p in raw if a != b]
    chains = chain_probabilities(("r0", 0), edges)
    best = _best_path_products(("r0", 0), edges)
    assert set(chains) == set(best)
    for key, probability in chains.items():
        assert best[key] - 1e-12 <= probability <= 1.0


def _best_path_products(start, edges):  # type: ignore[no-untyped-def]
    """Every reachable node's most probable path product, by Bellman-Ford (the oracle)."""
    best = {start: 1.0}
    for _ in range(len(edges) + 1):
        for a, b, p in edges:
            for x, y in ((a, b), (b, a)):
                if x in best and best[x] * p > best.get(y, 0.0):
                    best[y] = best[x] * p
    return best
