"""Fusion of aligned segment sets (Amigoni Alg. 5): known answers on synthetic walls."""

from __future__ import annotations

import numpy as np
import pytest

from multi_robot_mapper.core.fusion import chain_polyline, fuse, matching_chains
from multi_robot_mapper.core.matching import IntegrateConfig
from multi_robot_mapper.core.matching.scoring import pair_tolerance

CONFIG = IntegrateConfig()


def _max_distance_to(pieces: np.ndarray, segment: np.ndarray) -> float:
    """Largest distance of the segment's two end points to the polyline pieces."""
    worst = 0.0
    for point in segment.reshape(2, 2):
        a, b = pieces[:, :2], pieces[:, 2:]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", point - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        worst = max(worst, float(np.min(np.hypot(*(a + t[:, None] * ab - point).T))))
    return worst


def test_a_wall_seen_twice_becomes_one_polyline_and_unmatched_walls_stay() -> None:
    map_segments = np.array([[0.0, 0.0, 4.0, 0.0], [4.0, 0.0, 4.0, 3.0]])
    scan = np.array([[1.0, 0.005, 6.0, 0.005], [10.0, 10.0, 11.0, 10.0]])
    fused, owner = fuse(
        map_segments, np.array([0, 0]), scan, np.array([1, 1]), pair_tolerance(CONFIG), 0.02
    )
    # The two collinear pieces of y = 0 are one segment from x = 0 to x = 6; the corner wall
    # and the far wall are kept as they were, with their owners.
    assert len(fused) == 3
    wall = fused[np.isclose(fused[:, 1], 0.0, atol=0.01) & np.isclose(fused[:, 3], 0.0, atol=0.01)]
    assert len(wall) == 1
    assert sorted([wall[0, 0], wall[0, 2]]) == pytest.approx([0.0, 6.0], abs=1e-3)
    assert owner[(fused[:, 0] == 10.0)].tolist() == [1]
    assert set(owner.tolist()) == {0, 1}


def test_every_fused_segment_stays_within_the_tolerance_of_its_polyline() -> None:
    rng = np.random.default_rng(3)
    members = []
    for start in np.arange(0.0, 8.0, 1.0):
        offset = rng.normal(0.0, 0.01, 2)
        members.append([start, offset[0], start + 1.5, offset[1]])
    pieces = chain_polyline(np.asarray(members), tolerance=0.015)
    assert len(pieces) >= 1
    for member in members:
        assert _max_distance_to(pieces, np.asarray(member)) <= 0.015 + 1e-9


def test_pieces_of_one_wall_fuse_to_one_line_within_tolerance_of_every_member() -> None:
    # Two scans of one wall, 1.5 cm apart (noise within FUSIONTOLERANCE): one straight
    # segment spanning both, not a zig-zag.
    members = np.array([[0.0, 0.0, 2.0, 0.0], [0.5, 0.015, 2.5, 0.015]])
    pieces = chain_polyline(members, tolerance=0.02)
    assert len(pieces) == 1
    for member in members:
        assert _max_distance_to(pieces, member) <= 0.02


def test_a_curved_wall_seen_all_around_is_not_cut_by_chords() -> None:
    # A round wall of radius 7 m in 0.6 m pieces, seen twice (second copy 1 cm out): pieces
    # chain around the whole circle; no fused segment may cut across the room.
    angles = np.arange(0.0, 2 * np.pi, 0.6 / 7.0)
    ring = np.column_stack((np.cos(angles), np.sin(angles)))
    pieces = np.hstack((7.0 * ring, 7.0 * np.roll(ring, -1, axis=0)))
    again = np.hstack((7.01 * ring, 7.01 * np.roll(ring, -1, axis=0)))
    owners = np.zeros(len(pieces), dtype=np.int64)
    fused, _ = fuse(pieces, owners, again, owners + 1, pair_tolerance(CONFIG), 0.02)
    middle = 0.5 * (fused[:, :2] + fused[:, 2:])
    assert np.hypot(middle[:, 0], middle[:, 1]).min() > 6.9
    length = np.hypot(fused[:, 2] - fused[:, 0], fused[:, 3] - fused[:, 1]).sum()
    assert length < 2.2 * 2 * np.pi * 7.0


def test_parallel_walls_apart_are_not_fused() -> None:
    # Both sides of a corridor 1 m wide, and a cupboard 0.2 m in front of a wall: no chain.
    walls = np.array([[0.0, 0.0, 5.0, 0.0], [0.0, 1.0, 5.0, 1.0]])
    cupboard = np.array([[1.0, 0.2, 2.0, 0.2]])
    chain1, chain2, count = matching_chains(
        walls, cupboard, pair_tolerance(CONFIG), max_distance=0.06
    )
    assert count == 0
    assert (chain1 == -1).all() and (chain2 == -1).all()


def test_fusing_a_set_with_itself_changes_nothing_but_duplicates() -> None:
    room = np.array([[0.0, 0.0, 5.0, 0.0], [5.0, 0.0, 5.0, 4.0], [5.0, 4.0, 0.0, 4.0]])
    fused, _ = fuse(
        room,
        np.zeros(3, dtype=np.int64),
        room,
        np.ones(3, dtype=np.int64),
        pair_tolerance(CONFIG),
        0.02,
    )
    assert len(fused) == 3
    total = np.hypot(fused[:, 2] - fused[:, 0], fused[:, 3] - fused[:, 1]).sum()
    assert np.isclose(total, 14.0)
