"""The global map's fusion of placed maps (core/merging/compose.py), with known answers: a wall
seen by both maps becomes one wall spanning both, walls related to nothing in the other map are
kept as they are with their owners, and a map that is no (N, 4) array of numbers is refused."""

from __future__ import annotations

import numpy as np
import pytest

from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.merging.compose import as_map, fuse_maps

CONFIG = MergeConfig()  # fusion_tolerance 0.05 m
FUSION = (pair_tolerance(CONFIG.integrate), CONFIG.fusion_tolerance)


def test_a_wall_in_both_maps_is_fused_and_the_others_kept_with_their_owners() -> None:
    first = np.array([[0.0, 0.0, 4.0, 0.0], [0.0, 0.0, 0.0, 3.0]])
    second = np.array([[1.0, 0.01, 5.0, 0.01], [10.0, 10.0, 12.0, 10.0]])  # 1 cm beside
    segments, owner = fuse_maps(first, np.array([0, 0]), second, np.array([1, 1]), *FUSION)
    assert len(segments) == 3
    kept = {tuple(s): o for s, o in zip(segments.tolist(), owner.tolist(), strict=True)}
    assert kept.pop((0.0, 0.0, 0.0, 3.0)) == 0 and kept.pop((10.0, 10.0, 12.0, 10.0)) == 1
    ((fused, fused_owner),) = kept.items()
    xs, ys = sorted((fused[0], fused[2])), (fused[1], fused[3])
    np.testing.assert_allclose(xs, [0.0, 5.0], atol=1e-4)  # both walls' extent
    assert all(0.0 <= y <= 0.01 for y in ys)  # between them, within the tolerance
    assert fused_owner == 0


def test_fusing_with_an_empty_map_keeps_the_other_as_it_is() -> None:
    walls = np.array([[0.0, 0.0, 4.0, 0.0], [0.0, 0.0, 0.0, 3.0]])
    segments, owner = fuse_maps(walls, np.array([2, 3]), np.zeros((0, 4)), np.zeros(0), *FUSION)
    np.testing.assert_array_equal(segments, walls)
    assert owner.tolist() == [2, 3] and owner.dtype == np.int64
    segments, owner = fuse_maps(np.zeros((0, 4)), np.zeros(0), walls, np.array([1, 1]), *FUSION)
    np.testing.assert_array_equal(segments, walls)


def test_a_partial_map_must_be_finite_n_by_4() -> None:
    assert as_map([]).shape == (0, 4)
    np.testing.assert_array_equal(as_map([[0, 1, 2, 3]]), [[0.0, 1.0, 2.0, 3.0]])
    with pytest.raises(ValueError, match=r"an \(N, 4\) segment array, got \(2, 3\)"):
        as_map(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="NaN or infinite"):
        as_map([[0.0, 0.0, np.inf, 1.0]])
