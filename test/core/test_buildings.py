"""Generated buildings: plans of every kind and size, clear and connected waypoint graphs, and
the fields that describe a plan. The kinds' symmetry: `test_building_kinds.py`; walls from
rectangles: `test_floor_plans.py`; glass, routes, drives and scans: `test_building_runs.py`;
``mrm simulate --world generated``: test/cli/test_simulate.py."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from multi_robot_mapper.core.buildings import (
    MAX_SIZE_M,
    MIN_SIZE_M,
    PLAN_KINDS,
    Building,
    generate_building,
)
from multi_robot_mapper.core.floor_plans import CORRIDOR
from multi_robot_mapper.core.simulation import (
    LASERS,
)

CLEARANCE_M = 0.3

# --- independent geometry (no code shared with the generator) --------------------------------


def segment_distance(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(P, Q)`` distances between segments p[i] and q[j]: 0 where they cross, else the
    nearest of the four end-to-segment distances."""

    def point_to(points: np.ndarray, segs: np.ndarray) -> np.ndarray:  # (P, 2), (Q, 4)
        a, b = segs[None, :, :2], segs[None, :, 2:]
        ab = b - a
        denom = np.maximum(np.sum(ab * ab, axis=-1), 1e-18)
        t = np.clip(np.sum((points[:, None] - a) * ab, axis=-1) / denom, 0.0, 1.0)
        return np.asarray(np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1))

    ends = np.minimum.reduce(
        [
            point_to(p[:, :2], q),
            point_to(p[:, 2:], q),
            point_to(q[:, :2], p).T,
            point_to(q[:, 2:], p).T,
        ]
    )

    def orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        return np.sign(
            (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
            - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])
        )

    a, b, c, d = p[:, None, :2], p[:, None, 2:], q[None, :, :2], q[None, :, 2:]
    cross = (orient(a, b, c) * orient(a, b, d) < 0) & (orient(c, d, a) * orient(c, d, b) < 0)
    return np.asarray(np.where(cross, 0.0, ends))


def nearest_obstacle(legs: np.ndarray, obstacles: np.ndarray) -> np.ndarray:
    """``(P,)`` distance from each leg to the nearest obstacle (chunked: large plans)."""
    out = np.empty(len(legs))
    for start in range(0, len(legs), 200):
        chunk = legs[start : start + 200]
        lo = np.minimum(chunk[:, :2], chunk[:, 2:]).min(axis=0) - 1.0
        hi = np.maximum(chunk[:, :2], chunk[:, 2:]).max(axis=0) + 1.0
        inside = (np.maximum(obstacles[:, 0], obstacles[:, 2]) >= lo[0]) & (
            np.minimum(obstacles[:, 0], obstacles[:, 2]) <= hi[0]
        )
        inside &= (np.maximum(obstacles[:, 1], obstacles[:, 3]) >= lo[1]) & (
            np.minimum(obstacles[:, 1], obstacles[:, 3]) <= hi[1]
        )
        near = obstacles[inside]
        out[start : start + 200] = (
            segment_distance(chunk, near).min(axis=1) if len(near) else np.inf
        )
    return out


def reachable(count: int, edges: np.ndarray) -> int:
    """How many of ``count`` waypoints a breadth-first search from waypoint 0 reaches."""
    links: list[list[int]] = [[] for _ in range(count)]
    for a, b in edges.tolist():
        links[a].append(b)
        links[b].append(a)
    seen, queue = {0}, deque([0])
    while queue:
        for j in links[queue.popleft()]:
            if j not in seen:
                seen.add(j)
                queue.append(j)
    return len(seen)


# --- plans: kinds, sizes, determinism --------------------------------------------------------


def test_same_seed_same_building_bit_for_bit() -> None:
    a = generate_building(11, glass=True, clutter=0.05, people=3)
    b = generate_building(11, glass=True, clutter=0.05, people=3)
    c = generate_building(12, glass=True, clutter=0.05, people=3)
    for name in ("walls", "glass", "nodes", "edges", "spaces"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
    assert a.clutter.static.tobytes() == b.clutter.static.tobytes()
    assert a.clutter.walkers.tobytes() == b.clutter.walkers.tobytes()
    assert (a.kind, a.size) == (b.kind, b.size)
    assert a.walls.tobytes() != c.walls.tobytes()


def test_the_seed_draws_every_kind_and_sizes_over_the_whole_range() -> None:
    drawn = [generate_building(seed) for seed in range(40)]
    assert {b.kind for b in drawn} == set(PLAN_KINDS)
    sizes = np.array([b.size for b in drawn])
    assert MIN_SIZE_M <= sizes.min() < 40.0 and 100.0 < sizes.max() <= MAX_SIZE_M


def test_a_kind_or_size_given_by_hand_leaves_the_rest_of_the_draw() -> None:
    drawn = generate_building(5)
    again = generate_building(5, kind=drawn.kind, size=drawn.size)
    assert again.walls.tobytes() == drawn.walls.tobytes()


@pytest.mark.parametrize("kind", list(PLAN_KINDS))
@pytest.mark.parametrize(("seed", "size"), [(0, 20.0), (1, 33.0), (2, 75.0), (3, 200.0)])
def test_every_kind_at_every_size_is_connected_and_keeps_clear(
    kind: str, seed: int, size: float
) -> None:
    furniture = 0.05 if size < 100.0 else 0.0  # the clearance check is slow on 20 000 legs
    building = generate_building(seed, kind=kind, size=size, glass=True, clutter=furniture)
    assert building.kind == kind
    ends = np.vstack((building.walls, building.glass)).reshape(-1, 2)
    extent = (ends.max(axis=0) - ends.min(axis=0)).max()
    assert building.size == size and extent == pytest.approx(size, abs=1e-9)
    assert len(building.walls) > 0 and len(building.nodes) >= 2
    assert reachable(len(building.nodes), building.edges) == len(building.nodes)
    clearance = nearest_obstacle(building.edge_segments, building.obstacles)
    assert clearance.min() >= CLEARANCE_M - 1e-9


@pytest.mark.parametrize("seed", range(6))
def test_plans_of_drawn_kinds_with_furniture_and_people(seed: int) -> None:
    building = generate_building(seed, size=20.0 + 5.0 * seed, glass=True, clutter=0.2, people=4)
    has_floor = bool(np.any(building.space_kinds != CORRIDOR))  # furniture: rooms and halls
    assert (len(building.clutter.static) > 0) == has_floor
    assert reachable(len(building.nodes), building.edges) == len(building.nodes)
    clearance = nearest_obstacle(building.edge_segments, building.obstacles)
    assert clearance.min() >= CLEARANCE_M - 1e-9
    assert len(building.clutter.walkers) == 4


def test_bad_arguments_are_refused_with_their_name() -> None:
    for kwargs, words in [
        ({"kind": "castle"}, "unknown plan kind 'castle'"),
        ({"size": 10.0}, "size must be in [20, 200] m"),
        ({"size": 500.0}, "size must be in [20, 200] m"),
        ({"clutter": -1.0}, "clutter must be in"),
        ({"people": -2}, "people must be in"),
    ]:
        with pytest.raises(ValueError, match=words.replace("[", r"\[").replace("]", r"\]")):
            generate_building(0, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="seed"):
        generate_building(-1)


# --- the laser model ---------------------------------------------------------------------------


def test_lasers_share_the_noise_model() -> None:
    lms = LASERS["lms"]
    assert (lms.beams, lms.range_max) == (181, 80.0)
    assert np.degrees(lms.angle_increment) == pytest.approx(1.0)
    assert (lms.range_noise, lms.dropout) == (LASERS["utm30lx"].range_noise, 0.005)


def test_building_fields_describe_the_plan() -> None:
    building: Building = generate_building(1, kind="pillar_hall", size=50.0, clutter=0.1)
    assert building.obstacles.shape[1] == 4
    assert len(building.obstacles) == (
        len(building.walls) + len(building.glass) + len(building.clutter.static)
    )
    assert building.edge_segments.shape == (len(building.edges), 4)
    assert set(building.node_kinds.tolist()) <= {0, 1, 2, 3}
