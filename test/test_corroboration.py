"""Joins that agree (core/merging/corroboration.py): a map's probability of being placed right
from every independent path of joins, and sets short of the threshold that join only when
two or more of them agree."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_joint_merging import certain, line_units, link, weighed

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.consistency import PairVerdict, accept_pairs
from multi_robot_mapper.core.merging.corroboration import chain_probabilities, corroborate
from multi_robot_mapper.core.merging.places import units_of

A, B, C, D = ("a", 0), ("b", 0), ("c", 0), ("d", 0)
CONFIG = MergeConfig()  # join_probability 0.99, the default


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


# --- sets short of the threshold ------------------------------------------------------------


def corridor_of_three(c_b_error: float) -> tuple[dict, list[PairVerdict]]:  # type: ignore[type-arg]
    """Robots a, b, c in one corridor: a-b a join (P 0.999); c-a and c-b sets each short of
    the threshold (P 0.95, as equal rooms or a slid corridor leave them); c-b ``c_b_error``
    metres off along the corridor."""
    names = ["a", "b", "c"]
    poses = [(0.0, 0.0, 0.0), (2.0, 0.3, 0.1), (4.0, -0.2, -0.1)]
    frames = {n: se2.matrix_from_pose(*p) for n, p in zip(names, poses, strict=True)}
    units = units_of(line_units(names, [frames[n] for n in names]))

    def verdict(source: str, target: str, error: float, probability: float) -> PairVerdict:
        links = [
            link(units, frames, source, k, target, k + 1, 0.95, (error, 0.0, 0.0)) for k in (3, 9)
        ]
        found = weighed(((target, 0), (source, 0)), links, units)
        shy = probability < CONFIG.join_probability
        reason = f"P {probability:.3f} < {CONFIG.join_probability:g}" if shy else ""
        return dataclasses.replace(found, probability=probability, accepted=not shy, reason=reason)

    verdicts = [verdict("b", "a", 0.0, 0.999), verdict("c", "a", 0.0, 0.95)]
    verdicts.append(verdict("c", "b", c_b_error, 0.95))
    return units, verdicts


def test_two_sets_short_of_the_threshold_that_agree_join_their_map() -> None:
    units, verdicts = corridor_of_three(0.0)
    accepted = accept_pairs(verdicts, units, CONFIG, certain())
    assert accepted.groups == [[A, B], [C]]  # each set alone falls short
    joined = corroborate(accepted, verdicts, units, CONFIG, certain())
    assert joined.groups == [[A, B, C]]
    assert {v.pair for v in joined.pairs} == {v.pair for v in verdicts}
    chains = chain_probabilities(A, [(*v.pair, v.probability) for v in joined.pairs])
    # c wrong only when a-c is wrong and a-b-c is too
    expected = 1.0 - 0.05 * (1.0 - 0.999 * 0.95)
    assert chains[C] == pytest.approx(expected)
    assert chains[C] >= CONFIG.join_probability
    # c placed as the sets place it: at the truth, from either group's side
    T_a_c = joined.placed[A][C] if A in joined.placed else None
    assert T_a_c is not None
    T_truth = se2.invert(se2.matrix_from_pose(0.0, 0.0, 0.0)) @ se2.matrix_from_pose(
        4.0, -0.2, -0.1
    )
    np.testing.assert_allclose(
        se2.pose_from_matrix(T_a_c), se2.pose_from_matrix(T_truth), atol=1e-6
    )


def test_two_sets_that_disagree_join_nothing() -> None:
    # c-b places c 2 m along the corridor from where c-a does: one of them is wrong.
    units, verdicts = corridor_of_three(2.0)
    accepted = accept_pairs(verdicts, units, CONFIG, certain())
    joined = corroborate(accepted, verdicts, units, CONFIG, certain())
    assert joined.groups == [[A, B], [C]]
    assert {v.pair for v in joined.pairs} == {(A, B)}


def test_one_set_short_of_the_threshold_joins_nothing() -> None:
    units, verdicts = corridor_of_three(0.0)
    alone = verdicts[:2]
    accepted = accept_pairs(alone, units, CONFIG, certain())
    joined = corroborate(accepted, alone, units, CONFIG, certain())
    assert joined.groups == [[A, B], [C]]


def test_sets_more_likely_wrong_than_right_never_count() -> None:
    units, verdicts = corridor_of_three(0.0)
    doubtful = [verdicts[0], *(dataclasses.replace(v, probability=0.45) for v in verdicts[1:])]
    accepted = accept_pairs(doubtful, units, CONFIG, certain())
    joined = corroborate(accepted, doubtful, units, CONFIG, certain())
    assert joined.groups == [[A, B], [C]]
