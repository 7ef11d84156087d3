"""One pair of maps (core/merging/pairwise.py), with known answers: when a pair's result is
reused (a map changed little since), the longest segments, and a map on itself overlapping
whole within the tight distance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.merging.pairwise import (
    Link,
    MapSignature,
    link_tests,
    longest,
    reuse_change,
    tight_fraction,
)
from multi_robot_mapper.core.merging.pairwise_config import PairwiseConfig

# Reused within 10 % of the segment count (at least 2 segments) and 5 % of the length.
CONFIG = MergeConfig(pairwise=PairwiseConfig(reuse_count_change=10.0, reuse_length_change=5.0))
CHANGE = reuse_change(CONFIG)  # (10 %, 5 %)


def walls(count: int, length: float = 1.0) -> np.ndarray:
    """``count`` parallel walls of ``length`` m, 1 m apart."""
    return np.array([[0.0, float(k), length, float(k)] for k in range(count)])


def test_a_map_that_changed_little_keeps_its_pair_result() -> None:
    earlier = MapSignature.of(walls(40))  # 40 segments, 40 m
    assert MapSignature.of(walls(40)).close_to(earlier, CHANGE)  # the same content
    grown = np.vstack((walls(40), walls(5, length=0.1)))  # +0.5 m, within 5 %
    assert MapSignature.of(grown[:44]).close_to(
        earlier, reuse_change(CONFIG)
    )  # +4 segments: reused
    assert not MapSignature.of(grown).close_to(
        earlier, reuse_change(CONFIG)
    )  # +5 segments: matched again
    assert not MapSignature.of(walls(44)).close_to(
        earlier, reuse_change(CONFIG)
    )  # +4 m, 10 % longer
    assert not MapSignature.of(walls(40, length=1.06)).close_to(
        earlier, reuse_change(CONFIG)
    )  # +6 % length
    assert MapSignature.of(walls(40, length=1.04)).close_to(earlier, CHANGE)
    small = MapSignature.of(walls(5))
    assert MapSignature.of(walls(5)[:3]).close_to(small, CHANGE) is False  # -40 % of the length
    assert MapSignature.of(walls(7, length=5 / 7)).close_to(
        small, reuse_change(CONFIG)
    )  # 2 segments' slack
    signature = MapSignature.of(walls(3, length=2.0))
    assert (signature.count, signature.length) == (3, pytest.approx(6.0))


def test_the_longest_segments_longest_first() -> None:
    segments = np.array([[0, 0, 1, 0], [0, 0, 0, 3], [0, 0, 2, 0], [5, 5, 5, 5.5]], dtype=float)
    np.testing.assert_array_equal(longest(segments, 2), segments[[1, 2]])
    np.testing.assert_array_equal(longest(segments, 10), segments[[1, 2, 0, 3]])
    assert longest(np.zeros((0, 4)), 3).shape == (0, 4)


def test_a_map_on_itself_overlaps_whole_within_the_tight_distance() -> None:
    room = np.array([[0, 0, 6, 0], [6, 0, 6, 4], [6, 4, 0, 4], [0, 4, 0, 0]], dtype=float)
    identity = np.zeros(3)  # INTEGRATE's row: theta, tx, ty
    assert tight_fraction(room, room, identity, link_tests(CONFIG).tight) == pytest.approx(
        1.0, abs=1e-6
    )
    shifted = np.array([0.0, 0.0, 1.0])  # one metre off: at most the walls along y overlap
    assert tight_fraction(room, room, shifted, link_tests(CONFIG).tight) < 0.5
    link = Link("a", "b", (2.0, -1.0, math.pi / 2), 20.0, 0.8, True)
    np.testing.assert_allclose(link.matrix, se2.matrix_from_pose(2.0, -1.0, math.pi / 2))
