"""The laser simulator: collision-free partly overlapping paths, exact ray casting and
determinism. The worlds: `test_worlds.py`; ``mrm simulate``: test/cli/test_simulate.py."""

from __future__ import annotations

import numpy as np
import pytest

from multi_robot_mapper.core.simulation import (
    SIM_START_S,
    LaserModel,
    drive_path,
    plan_paths,
    raycast,
    raycast_fan,
    route_section,
    simulate_robots,
    simulate_scan,
)
from multi_robot_mapper.core.worlds import ROUTES, WORLDS, polygon

CLEARANCE_M = 0.3


# --- independent geometry (no code shared with the simulator) --------------------------------


def segments_cross(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(P, Q)`` booleans: segment ``p[i]`` and segment ``q[j]`` share a point.

    Orientation signs of each segment's ends with respect to the other (touching counts).
    """

    def orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        return np.sign(
            (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
            - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])
        )

    a, b = p[:, None, :2], p[:, None, 2:]
    c, d = q[None, :, :2], q[None, :, 2:]
    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)

    def on(a: np.ndarray, b: np.ndarray, c: np.ndarray, o: np.ndarray) -> np.ndarray:
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        return (o == 0) & np.all((c >= lo) & (c <= hi), axis=-1)

    touching = on(a, b, c, o1) | on(a, b, d, o2) | on(c, d, a, o3) | on(c, d, b, o4)
    return np.asarray(proper | touching)


def point_wall_distance(points: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """``(P,)`` distance of each point to the nearest wall segment."""
    a, b = walls[None, :, :2], walls[None, :, 2:]
    ab = b - a
    t = np.clip(np.sum((points[:, None] - a) * ab, axis=-1) / np.sum(ab * ab, axis=-1), 0, 1)
    return np.asarray(np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1).min(1))


def ray_range(walls: np.ndarray, x: float, y: float, bearing: float) -> float:
    """Range along one ray by solving o + t u = a + s (b - a) for each wall (2 x 2 systems)."""
    u = np.array([np.cos(bearing), np.sin(bearing)])
    best = np.inf
    for wall in walls:
        a, e = wall[:2], wall[2:] - wall[:2]
        matrix = np.column_stack((u, -e))
        if abs(np.linalg.det(matrix)) < 1e-12:
            continue
        t, s = np.linalg.solve(matrix, a - (x, y))
        if t > 0 and 0 <= s <= 1:
            best = min(best, t)
    return best


def path_segments(poses: np.ndarray) -> np.ndarray:
    return np.hstack((poses[:-1, :2], poses[1:, :2]))


# --- worlds and routes ------------------------------------------------------------------------


def test_segment_cross_check_finds_crossings() -> None:
    """The checker itself: a known crossing, a touch and a miss."""
    walls = np.array([[0.0, 0.0, 2.0, 0.0]])
    legs = np.array([[1.0, -1.0, 1.0, 1.0], [2.0, 0.0, 3.0, 1.0], [0.0, 0.5, 2.0, 0.5]])
    np.testing.assert_array_equal(segments_cross(legs, walls)[:, 0], [True, True, False])


def test_route_section_wraps_round_the_tour() -> None:
    square = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]  # 16 m round
    np.testing.assert_allclose(route_section(square, 14.0, 4.0), [[0, 2], [0, 0], [2, 0]])
    np.testing.assert_allclose(route_section(square, 1.0, 2.0), [[1, 0], [3, 0]])


# --- paths ------------------------------------------------------------------------------------


@pytest.mark.parametrize("world", ["office", "corridors", "rooms"])
@pytest.mark.parametrize("robots", [1, 2, 3, 5])
@pytest.mark.parametrize("duration", [20.0, 300.0])  # 300 s: patrols turn round
def test_driven_paths_never_cross_walls(world: str, robots: int, duration: float) -> None:
    walls = WORLDS[world]()
    for waypoints in plan_paths(ROUTES[world], robots, 0.8 * duration):
        poses = drive_path(waypoints, 0.8, 10.0, duration)
        assert len(poses) == round(10.0 * duration)
        assert not segments_cross(path_segments(poses), walls).any()
        assert point_wall_distance(poses[:, :2], walls).min() >= CLEARANCE_M


def test_paths_overlap_only_between_neighbours() -> None:
    """Four robots in the corridors: each shares ground with the next, not with the one after,
    and each has ground of its own."""
    paths = [drive_path(w, 0.8, 10.0, 20.0) for w in plan_paths(ROUTES["corridors"], 4, 16.0)]

    def near(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """For each pose of a: is some pose of b within 0.1 m?"""
        d = np.linalg.norm(a[:, None, :2] - b[None, :, :2], axis=-1)
        return np.asarray(d.min(axis=1) < 0.1)

    for k in range(3):
        shared = near(paths[k], paths[k + 1]).mean()
        assert 0.2 < shared < 0.4  # overlap = 0.3 of a stretch
    assert not near(paths[0], paths[2]).any()
    for k in range(4):
        others = np.vstack([p for j, p in enumerate(paths) if j != k])
        assert not near(paths[k], others).all()


def test_drive_path_patrols_at_constant_speed() -> None:
    poses = drive_path(np.array([[0.0, 0.0], [2.0, 0.0]]), speed=1.0, rate=10.0, duration=6.0)
    assert len(poses) == 60
    np.testing.assert_allclose(poses[[0, 10, 20, 30, 40], 0], [0.0, 1.0, 2.0, 1.0, 0.0])
    np.testing.assert_allclose(np.abs(np.diff(poses[:, 0])), 0.1, atol=1e-12)
    assert poses[5, 2] == pytest.approx(0.0)  # heading east going out
    assert abs(poses[30, 2]) == pytest.approx(np.pi)  # heading west coming back


def test_plan_paths_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="robots"):
        plan_paths(ROUTES["rooms"], 0, 10.0)
    with pytest.raises(ValueError, match="overlap"):
        plan_paths(ROUTES["rooms"], 2, 10.0, overlap=0.6)


# --- ray casting ------------------------------------------------------------------------------


def test_noise_free_scan_matches_independent_ray_segment_solutions() -> None:
    walls = WORLDS["corridors"]()
    laser = LaserModel(range_noise=0.0, dropout=0.0)
    pose = (16.0, 14.0, 0.7)
    scan = simulate_scan(walls, pose, laser, np.random.default_rng(0))
    for beam in (0, 137, 540, 541, 900, 1080):
        bearing = pose[2] + laser.angle_min + beam * laser.angle_increment
        expected = ray_range(walls, pose[0], pose[1], bearing)
        assert scan.ranges[beam] == pytest.approx(expected, abs=1e-9)
    assert scan.angle_max == pytest.approx(np.radians(135.0))


def test_range_along_a_beam_in_a_known_room() -> None:
    """A 4 x 2 m room, laser at (1, 1) facing +x: 3 m ahead, 1 m left and right."""
    room = polygon([(0, 0), (4, 0), (4, 2), (0, 2)])
    laser = LaserModel(beams=3, field_of_view=np.pi, range_noise=0.0, dropout=0.0)
    scan = simulate_scan(room, (1.0, 1.0, 0.0), laser, np.random.default_rng(0))
    np.testing.assert_allclose(scan.ranges, [1.0, 3.0, 1.0])


def test_fan_raycast_is_bitwise_the_full_raycast() -> None:
    rng = np.random.default_rng(3)
    for world in WORLDS:
        walls = WORLDS[world]()
        for _ in range(60):
            pose = (rng.uniform(-2, 34), rng.uniform(-2, 22), rng.uniform(-7, 7))
            beams = int(rng.integers(2, 1200))
            increment = rng.uniform(0.001, 2 * np.pi / (beams - 1)) * rng.choice([-1, 1])
            angle_min = rng.uniform(-4, 4)
            angles = angle_min + increment * np.arange(beams)
            fast = raycast_fan(walls, pose, angle_min, increment, beams, 30.0)
            np.testing.assert_array_equal(fast, raycast(walls, pose, angles, 30.0))


# --- runs ---------------------------------------------------------------------------------------


def small_laser() -> LaserModel:
    return LaserModel(beams=181, rate=10.0)


def test_same_seed_same_ranges_byte_for_byte() -> None:
    a = simulate_robots("rooms", 2, small_laser(), seed=5, duration=3.0)
    b = simulate_robots("rooms", 2, small_laser(), seed=5, duration=3.0)
    c = simulate_robots("rooms", 2, small_laser(), seed=6, duration=3.0)
    for ra, rb, rc in zip(a, b, c, strict=True):
        assert [s.ranges.tobytes() for s in ra.scans] == [s.ranges.tobytes() for s in rb.scans]
        assert [s.ranges.tobytes() for s in ra.scans] != [s.ranges.tobytes() for s in rc.scans]
        np.testing.assert_array_equal(ra.T_world_laser, rc.T_world_laser)  # noise only


def test_runs_start_together_and_have_noise_and_dropouts() -> None:
    laser = LaserModel(beams=1081, rate=40.0, range_noise=0.01, dropout=0.05)
    runs = simulate_robots("office", 3, laser, seed=1, duration=1.0)
    walls = WORLDS["office"]()
    for run in runs:
        np.testing.assert_allclose(run.stamps, SIM_START_S + np.arange(40) / 40.0)
        scan = run.scans[0]
        x, y, theta = run.T_world_laser[0]
        angles = laser.angle_min + laser.angle_increment * np.arange(laser.beams)
        exact = raycast(walls, (x, y, theta), angles, laser.range_max)
        error = scan.ranges - exact
        kept = np.isfinite(error)
        assert 0.02 < np.isnan(scan.ranges).mean() < 0.09  # 5 % dropouts
        assert np.std(error[kept]) == pytest.approx(0.01, rel=0.15)
    assert len({tuple(r.T_world_laser[0]) for r in runs}) == 3  # different places
