"""Runs through generated buildings: glass that returns nothing, culled ray casting bitwise equal
to casting against everything, routes with a chosen overlap, sparse drives, scans of the truth
with the laser model's noise."""

from __future__ import annotations

import numpy as np
import pytest
from test_buildings import CLEARANCE_M, nearest_obstacle

from multi_robot_mapper.core.building_runs import (
    OVERLAP_LEVELS,
    BuildingScanner,
    SparseSpacing,
    drive_routes,
    keep_sparse,
    plan_routes,
    scan_drives,
    shared_ground,
    simulate_building,
)
from multi_robot_mapper.core.buildings import (
    PLAN_KINDS,
    generate_building,
)
from multi_robot_mapper.core.floor_plans import CORRIDOR
from multi_robot_mapper.core.simulation import (
    LASERS,
    SIM_START_S,
    LaserModel,
    people_at,
    raycast,
)


def polyline_legs(points: np.ndarray) -> np.ndarray:
    return np.hstack((points[:-1, :2], points[1:, :2]))


def ray_hit(segments: np.ndarray, x: float, y: float, bearing: float) -> float:
    """Range along one ray to the nearest of ``segments`` (2 x 2 solves, ``inf`` if none)."""
    u = np.array([np.cos(bearing), np.sin(bearing)])
    best = np.inf
    for wall in segments:
        a, e = wall[:2], wall[2:] - wall[:2]
        matrix = np.column_stack((u, -e))
        if abs(np.linalg.det(matrix)) < 1e-12:
            continue
        t, s = np.linalg.solve(matrix, a - (x, y))
        if t > 0 and 0 <= s <= 1:
            best = min(best, t)
    return best


def test_glass_returns_nothing_and_hides_the_wall_behind_it() -> None:
    """Beams from a corridor into rooms with glass fronts: where the glass is nearer than any
    wall the reading is no return (inf), never the room's back wall behind the pane; every
    other beam reads the nearest wall. The same plan without glass sees the walls there."""
    with_glass = generate_building(2, kind="room_row", size=40.0, glass=True)
    plain = generate_building(2, kind="room_row", size=40.0, glass=False)
    assert len(with_glass.glass) > 0 and len(plain.glass) == 0
    laser = LaserModel(beams=361, field_of_view=np.pi, range_noise=0.0, dropout=0.0)
    corridor = with_glass.spaces[with_glass.space_kinds == CORRIDOR][0]
    middle = 0.5 * (corridor[1] + corridor[3])
    panes, hidden = 0, 0
    for x in np.linspace(corridor[0] + 2.0, corridor[2] - 2.0, 3):
        for heading in (np.pi / 2, -np.pi / 2):
            pose = (float(x), float(middle), heading)
            seen = BuildingScanner.of(with_glass, laser).ranges(pose)
            bare = BuildingScanner.of(plain, laser).ranges(pose)
            for beam in range(0, laser.beams, 4):
                bearing = heading + laser.angles[beam]
                wall = ray_hit(with_glass.walls, pose[0], pose[1], bearing)
                pane = ray_hit(with_glass.glass, pose[0], pose[1], bearing)
                if pane < wall and pane <= laser.range_max:
                    assert seen[beam] == np.inf
                    assert bare[beam] == pytest.approx(pane, abs=1e-9)  # a wall there instead
                    panes += 1
                    hidden += int(wall < np.inf)
                elif wall <= laser.range_max:
                    assert seen[beam] == pytest.approx(wall, abs=1e-9)
    assert panes > 20 and hidden > 5  # hidden: beams whose wall behind the pane stayed unseen


@pytest.mark.parametrize("laser_name", list(LASERS))
def test_culled_ranges_are_bitwise_those_of_casting_against_everything(laser_name: str) -> None:
    building = generate_building(7, kind="mixed", size=150.0, glass=True, clutter=0.01, people=8)
    laser = LASERS[laser_name]
    scanner = BuildingScanner.of(building, laser)
    rng = np.random.default_rng(1)
    angles = laser.angles
    for _ in range(12):
        x, y = building.nodes[rng.integers(len(building.nodes))] + rng.normal(0, 0.1, 2)
        pose = (float(x), float(y), float(rng.uniform(-4, 4)))
        seconds = float(rng.uniform(0, 60))
        everything = np.vstack(
            [building.walls, building.clutter.static, *people_at(building.clutter.walkers, seconds)]
        )
        solid = raycast(everything, pose, angles, laser.range_max)
        glass = raycast(building.glass, pose, angles, laser.range_max)
        expected = np.where(solid <= glass, solid, np.inf)
        np.testing.assert_array_equal(scanner.ranges(pose, seconds), expected)


@pytest.mark.parametrize("kind", list(PLAN_KINDS))
def test_routes_have_their_length_and_keep_clear_of_walls_glass_and_furniture(kind: str) -> None:
    building = generate_building(3, kind=kind, size=60.0, glass=True, clutter=0.1)
    headings = set()
    for overlap in (0.0, 0.3, 1.0):
        paths = plan_routes(building, 3, 80.0, overlap, seed=5)
        for path in paths:
            legs = polyline_legs(path)
            assert np.hypot(legs[:, 2] - legs[:, 0], legs[:, 3] - legs[:, 1]).sum() == (
                pytest.approx(80.0)
            )
            assert nearest_obstacle(legs, building.obstacles).min() >= CLEARANCE_M - 1e-9
        assert len({tuple(np.round(p[0], 6)) for p in paths}) == 3  # random starts
        headings |= {round(float(np.arctan2(*(p[1] - p[0])[::-1])), 6) for p in paths}
    assert len(headings) >= 2


@pytest.mark.parametrize("seed", range(6))
def test_without_overlap_no_robot_drives_near_another(seed: int) -> None:
    building = generate_building(seed, size=120.0)
    paths = plan_routes(building, 4, 60.0, OVERLAP_LEVELS["none"], seed=seed)
    shares = shared_ground(paths, radius=0.5)
    assert np.all(shares[~np.eye(4, dtype=bool)] == 0.0)


def test_more_overlap_means_more_shared_ground() -> None:
    mean_shared = {}
    for level, overlap in OVERLAP_LEVELS.items():
        values = []
        for seed in range(5):
            building = generate_building(seed, size=80.0)
            shares = shared_ground(plan_routes(building, 3, 60.0, overlap, seed=seed))
            values.append(shares[~np.eye(3, dtype=bool)].reshape(3, 2).max(axis=1).mean())
        mean_shared[level] = float(np.mean(values))
    assert mean_shared["none"] == 0.0
    assert 0.1 < mean_shared["small"] < mean_shared["large"]
    assert mean_shared["large"] > 0.55


def test_route_arguments_are_checked() -> None:
    building = generate_building(0, kind="bare_corridors", size=20.0)
    with pytest.raises(ValueError, match="overlap"):
        plan_routes(building, 2, 10.0, 1.5)
    with pytest.raises(ValueError, match="robots"):
        plan_routes(building, 0, 10.0, 0.5)
    with pytest.raises(ValueError, match="waypoints"):
        plan_routes(building, len(building.nodes) + 1, 10.0, 0.5)


def test_sparse_spacing_keeps_a_pose_per_half_metre_or_fifteen_degrees() -> None:
    straight = np.column_stack((np.arange(50) * 0.1, np.zeros(50), np.zeros(50)))
    np.testing.assert_array_equal(keep_sparse(straight, SparseSpacing()), np.arange(0, 50, 5))
    turning = np.column_stack((np.zeros(40), np.zeros(40), np.radians(np.arange(40) * 2.0)))
    np.testing.assert_array_equal(
        keep_sparse(turning, SparseSpacing(distance=1.0)), np.arange(0, 40, 8)
    )  # every 16 deg: the first pose past 15


def test_sparse_drives_are_the_dense_drives_thinned() -> None:
    building = generate_building(6, size=50.0)
    paths = plan_routes(building, 2, 30.0, 0.5, seed=1)
    dense = drive_routes(paths, 0.8, 20.0, 37.5)
    sparse = drive_routes(paths, 0.8, 20.0, 37.5, SparseSpacing(distance=1.0))
    for d, s in zip(dense, sparse, strict=True):
        assert len(d.stamps) == 750 and 25 <= len(s.stamps) < 150
        kept = np.searchsorted(d.stamps, s.stamps)
        np.testing.assert_array_equal(d.stamps[kept], s.stamps)
        np.testing.assert_array_equal(d.T_world_laser[kept], s.T_world_laser)
        steps = np.hypot(*np.diff(s.T_world_laser[:, :2], axis=0).T)
        assert steps.max() <= 1.0 + 0.8 / 20.0 + 1e-9


def test_runs_are_deterministic_and_scan_the_truth() -> None:
    building = generate_building(8, size=40.0, glass=True, people=2)
    laser = LaserModel(beams=181, rate=10.0, range_noise=0.0, dropout=0.0)
    runs = simulate_building(building, 2, laser, seed=3, duration=3.0)
    again = simulate_building(building, 2, laser, seed=3, duration=3.0)
    scanner = BuildingScanner.of(building, laser)
    for run, other in zip(runs, again, strict=True):
        np.testing.assert_allclose(run.stamps, SIM_START_S + np.arange(30) / 10.0)
        assert [s.ranges.tobytes() for s in run.scans] == [s.ranges.tobytes() for s in other.scans]
        for stamp, pose, scan in zip(run.stamps, run.T_world_laser, run.scans, strict=True):
            exact = scanner.ranges((pose[0], pose[1], pose[2]), stamp - SIM_START_S)
            np.testing.assert_array_equal(scan.ranges, exact)


def test_noise_and_dropouts_follow_the_laser_model() -> None:
    building = generate_building(9, kind="pillar_hall", size=40.0)
    laser = LaserModel(beams=541, rate=10.0, range_noise=0.02, dropout=0.05)
    paths = plan_routes(building, 1, 8.0, 0.0, seed=0)
    drives = drive_routes(paths, 0.8, laser.rate, 2.0)
    run = scan_drives(building, drives, laser, seed=0)[0]
    scanner = BuildingScanner.of(building, laser)
    errors, dropped = [], []
    for pose, scan in zip(run.T_world_laser, run.scans, strict=True):
        exact = scanner.ranges((pose[0], pose[1], pose[2]))
        returned = np.isfinite(exact)
        assert np.all(np.isinf(scan.ranges[~returned]))  # no return stays no return
        dropped.append(np.isnan(scan.ranges[returned]))
        kept = returned & np.isfinite(scan.ranges)
        errors.append(scan.ranges[kept] - exact[kept])
    assert 0.03 < np.concatenate(dropped).mean() < 0.07
    assert np.std(np.concatenate(errors)) == pytest.approx(0.02, rel=0.1)
