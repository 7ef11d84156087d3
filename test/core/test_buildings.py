"""Generated buildings: plans of every kind and size, their symmetry, glass that returns
nothing, clear and connected waypoint graphs, routes with a chosen overlap, sparse drives,
culled ray casting bitwise equal to casting against everything, and ``mrm simulate --world
generated`` writing a bag that ``mrm replay`` reads."""

from __future__ import annotations

import json
from collections import deque
from pathlib import Path

import numpy as np
import pytest

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
    MAX_SIZE_M,
    MIN_SIZE_M,
    PLAN_KINDS,
    Building,
    generate_building,
)
from multi_robot_mapper.core.floor_plans import CORRIDOR, ROOM, layout, walls_and_glass
from multi_robot_mapper.core.segment_grid import segment_grid
from multi_robot_mapper.core.simulation import (
    LASERS,
    SIM_START_S,
    LaserModel,
    people_at,
    raycast,
)
from multi_robot_mapper.io.bags import read_recordings

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


def segment_set(segments: np.ndarray) -> set[tuple[float, ...]]:
    """Segments as a set, each with its ends in a fixed order, rounded to 1e-9 m."""
    out = set()
    for x1, y1, x2, y2 in np.round(segments, 9).tolist():
        a, b = (x1 + 0.0, y1 + 0.0), (x2 + 0.0, y2 + 0.0)
        out.add((*min(a, b), *max(a, b)))
    return out


def polyline_legs(points: np.ndarray) -> np.ndarray:
    return np.hstack((points[:-1, :2], points[1:, :2]))


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


# --- symmetry --------------------------------------------------------------------------------


@pytest.mark.parametrize(("seed", "size"), [(0, 20.0), (1, 45.0), (2, 90.0), (3, 200.0)])
def test_mirror_wings_are_their_own_mirror_image(seed: int, size: float) -> None:
    building = generate_building(seed, kind="mirror_wings", size=size, glass=True)
    assert building.symmetry == "mirror"
    for segments in (building.walls, building.glass):
        mirror = segments * np.array([-1.0, 1.0, -1.0, 1.0])
        assert segment_set(mirror) == segment_set(segments)
    assert len(building.glass) > 0


@pytest.mark.parametrize("seed", range(6))
def test_rotation_wings_are_their_own_turned_copy(seed: int) -> None:
    building = generate_building(seed, kind="rotation_wings", size=30.0 + 25.0 * seed)
    quarter = {"rotation_90": 1, "rotation_180": 2}[building.symmetry]
    turned = building.walls
    for _ in range(quarter):
        turned = np.column_stack((-turned[:, 1], turned[:, 0], -turned[:, 3], turned[:, 2]))
    assert segment_set(turned) == segment_set(building.walls)
    # The wing leaves the hub off-centre: the plan is not also its own mirror image.
    mirror = building.walls * np.array([-1.0, 1.0, -1.0, 1.0])
    assert segment_set(mirror) != segment_set(building.walls)


def test_a_row_of_rooms_has_equal_rooms() -> None:
    building = generate_building(4, kind="room_row", size=60.0)
    rooms = building.spaces[building.space_kinds == ROOM]
    widths = np.round(rooms[:, 2] - rooms[:, 0], 9)
    depths = np.round(rooms[:, 3] - rooms[:, 1], 9)
    assert len(rooms) >= 10 and len(set(widths)) == 1 and len(set(depths)) == 1


# --- walls from rectangles: a known answer ---------------------------------------------------


def test_two_rooms_with_a_door_and_a_glass_front_give_known_walls() -> None:
    plan = layout(
        [(0, 0, 4, 3), (4, 0, 8, 3)],
        [ROOM, ROOM],
        openings=[(4, 1, 4, 2)],
        glass=[(0, 3, 4, 3)],
    )
    walls, glass = walls_and_glass(plan)
    assert segment_set(walls) == segment_set(
        np.array(
            [
                [0, 0, 8, 0],  # the two rooms' south walls: one run
                [4, 3, 8, 3],
                [0, 0, 0, 3],
                [8, 0, 8, 3],
                [4, 0, 4, 1],  # the wall between them, broken by the door
                [4, 2, 4, 3],
            ]
        )
    )
    assert segment_set(glass) == {(0.0, 3.0, 4.0, 3.0)}


def test_a_corridor_opening_onto_another_has_no_wall_between() -> None:
    plan = layout([(0, 0, 10, 2), (0, 2, 2, 8)], [CORRIDOR, CORRIDOR], openings=[(0, 2, 2, 2)])
    walls, glass = walls_and_glass(plan)
    expected = [[0, 0, 10, 0], [2, 2, 10, 2], [0, 0, 0, 8], [10, 0, 10, 2], [2, 2, 2, 8]]
    assert segment_set(walls) == segment_set(np.array([*expected, [0, 8, 2, 8]]))
    assert len(glass) == 0


# --- glass -----------------------------------------------------------------------------------


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


# --- culled ray casting ----------------------------------------------------------------------


def test_segment_grid_finds_exactly_the_segments_within_reach() -> None:
    rng = np.random.default_rng(4)
    starts = rng.uniform(-50, 50, (400, 2))
    segments = np.hstack((starts, starts + rng.normal(0, 3, (400, 2))))
    grid = segment_grid(segments, 12.0)
    for x, y in rng.uniform(-70, 70, (50, 2)):
        distance = segment_distance(np.array([[x, y, x, y]]), segments)[0]
        expected = np.flatnonzero(distance <= 12.0)
        assert set(grid.within(float(x), float(y)).tolist()) >= set(expected.tolist())
        assert np.all(distance[grid.within(float(x), float(y))] <= 12.0 + 1e-6)


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


# --- routes ----------------------------------------------------------------------------------


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


# --- drives and scans ------------------------------------------------------------------------


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


def test_lasers_share_the_noise_model() -> None:
    lms = LASERS["lms"]
    assert (lms.beams, lms.range_max) == (181, 80.0)
    assert np.degrees(lms.angle_increment) == pytest.approx(1.0)
    assert (lms.range_noise, lms.dropout) == (LASERS["utm30lx"].range_noise, 0.005)


# --- mrm simulate --world generated ----------------------------------------------------------


def test_mrm_simulate_generated_writes_a_bag_that_replay_reads(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "gen"
    args = ["--world", "generated", "--seed", "4", "--kind", "room_row", "--size", "40"]
    more = ["--laser", "lms", "--duration", "3", "--glass", "--people", "2", "--sparse"]
    assert mrm(["simulate", "--robots", "2", "--out", str(bag), *args, *more]) == 0
    said = capsys.readouterr().out
    assert "generated room_row building (seed 4, 40 m" in said and "overlap small" in said
    recordings = read_recordings(bag)
    assert list(recordings) == ["robot1", "robot2"]
    for rec in recordings.values():
        # 2.4 m at a scan per 0.5 m, and one per 15 degrees of turning (into rooms and out)
        assert 5 <= len(rec.scans) == len(rec.ground_truth) < 40
        assert rec.scans[0].scan.ranges.size == 181
    out = tmp_path / "local"
    assert mrm(["replay", str(bag), "--out", str(out), "--method", "local"]) == 0
    stats = json.loads((out / "stats.json").read_text())
    assert stats["method"] == "local" and set(stats["robots"]) == {"robot1", "robot2"}
    assert stats["scans_total"] == sum(len(r.scans) for r in recordings.values())


def test_mrm_simulate_generated_is_the_core_simulation(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "gen"
    args = ["--world", "generated", "--seed", "2", "--size", "30", "--overlap", "large"]
    more = ["--beams", "91", "--rate", "10", "--duration", "2"]
    assert mrm(["simulate", "--robots", "2", "--out", str(bag), *args, *more]) == 0
    capsys.readouterr()
    laser = LaserModel(beams=91, rate=10.0)
    runs = simulate_building(
        generate_building(2, size=30.0), 2, laser, seed=2, duration=2.0, overlap=0.6
    )
    recordings = read_recordings(bag)
    for run, rec in zip(runs, recordings.values(), strict=True):
        assert len(rec.scans) == len(run.scans) == 20
        for written, simulated in zip(rec.scans, run.scans, strict=True):
            as_sent = simulated.ranges.astype(np.float32)  # LaserScan ranges are float32
            np.testing.assert_array_equal(written.scan.ranges, as_sent)


def test_mrm_simulate_random_overlap_is_drawn_from_the_seed(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    said = []
    for name in ("a", "b"):
        args = ["--world", "generated", "--seed", "9", "--size", "25", "--overlap", "random"]
        more = ["--beams", "31", "--rate", "10", "--duration", "1"]
        assert mrm(["simulate", "--robots", "2", "--out", str(tmp_path / name), *args, *more]) == 0
        said.append(capsys.readouterr().out)
    assert said[0].replace("/a ", "/b ") == said[1]
    drawn = float(said[0].split("overlap random ")[1].split(",")[0])
    assert 0.0 <= drawn <= 0.9


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--size", "10"], "--size must be in [20, 200] m, got 10"),
        (["--people", "-1"], "--people must be in [0, 1000]"),
        (["--sparse", "0"], "--sparse must be in [0.05, 100] m"),
        (["--world", "office", "--glass"], "--glass only with --world generated"),
        (["--world", "rooms", "--kind", "mixed", "--overlap", "none"], "--kind, --overlap only"),
        (["--robots", "100", "--kind", "bare_corridors", "--size", "20"], "waypoints"),
    ],
)
def test_mrm_simulate_generated_errors_are_one_line(
    mrm, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], words: str
) -> None:
    base = ["simulate", "--robots", "2", "--out", str(tmp_path / "bag"), "--world", "generated"]
    assert mrm([*base, *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mrm simulate: error: ") and words in err
    assert not (tmp_path / "bag").exists()


def test_building_fields_describe_the_plan() -> None:
    building: Building = generate_building(1, kind="pillar_hall", size=50.0, clutter=0.1)
    assert building.obstacles.shape[1] == 4
    assert len(building.obstacles) == (
        len(building.walls) + len(building.glass) + len(building.clutter.static)
    )
    assert building.edge_segments.shape == (len(building.edges), 4)
    assert set(building.node_kinds.tolist()) <= {0, 1, 2, 3}
