"""K robots driving through a generated building (:mod:`core.buildings`) and scanning it.

The steps, each usable on its own (a benchmark draws its scenarios from them):

1. :func:`plan_routes`: each robot's path along the building's waypoint graph, from a random
   start, with a chosen ``overlap``: the share of each robot's drive on ground the others
   drive too, from 0 (each robot in its own part of the building, none within a waypoint of
   another's) to 1 (all robots on the same ground).
2. :func:`drive_routes`: the laser's true poses along the paths at the laser's rate (a
   walking pace, headings turning smoothly: :func:`~core.simulation.drive_path`), all robots
   from the same first stamp; with ``sparse``, only a pose every 0.5 m or 15 degrees is kept
   (as in the CARMEN "corrected" logs), before any ray is cast.
3. :func:`scan_drives`: a noisy scan at every kept pose, ray cast against only the walls,
   furniture, people and glass within the laser's range (:class:`BuildingScanner`).

:func:`simulate_building` runs all three. Randomness comes from the seed's own streams: routes
from one, robot ``k``'s laser noise from ``SeedSequence(seed, spawn_key=(k,))`` as in
:func:`~core.simulation.simulate_robots`, so the same arguments give the same scans bit for
bit.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from multi_robot_mapper.core.buildings import Building
from multi_robot_mapper.core.geometry import point_segment_distance
from multi_robot_mapper.core.segment_grid import SegmentGrid, segment_grid
from multi_robot_mapper.core.simulation import (
    SIM_START_S,
    LaserModel,
    SimulatedRobot,
    drive_path,
    people_at,
    raycast_fan,
    scan_from_ranges,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

OVERLAP_LEVELS = MappingProxyType({"none": 0.0, "small": 0.1, "large": 0.6})
"""Named overlaps (``mrm simulate --overlap``): the share of each route driven in the shared
part. Robots also meet on their way to and from it, so the ground they really share is more:
over drawn buildings, 3 robots and 80 m routes, a mean of 0 (none), about a third (small) and
three quarters (large) of each route (``bench/route_overlap.py``)."""
# The shared part of a building holds this share of one robot's shared driving: each robot
# then drives all of it, about twice over.
_SHARED_AREA = 0.5
_ROUTE_STREAM = 2000
# With a shared part, the robots' own parts may grow from any waypoint this close to it.
_SEED_REACH_M = 8.0
_PERSON_REACH_M = 0.4  # a walking person's legs stay this close to their line


@dataclasses.dataclass(frozen=True)
class SparseSpacing:
    """Keep a scan only after this much driving or turning since the last one kept."""

    distance: float = 0.5  # m
    turn: float = float(np.radians(15.0))  # rad


@dataclasses.dataclass(frozen=True)
class Drive:
    """One robot's laser poses in the ``world`` frame and their stamps."""

    stamps: FloatArray  # (N,) s
    T_world_laser: FloatArray  # (N, 3) x, y, theta


# ---------------------------------------------------------------------------------------------
# Routes.
# ---------------------------------------------------------------------------------------------


def plan_routes(
    building: Building, robots: int, length: float, overlap: float, seed: int = 0
) -> list[FloatArray]:
    """Waypoints ``(M, 2)`` of a path ``length`` m long for each of ``robots`` robots.

    With ``overlap`` > 0, a part of the building round a random waypoint is shared: each
    robot drives ``overlap`` of its length there (starting at a random place in it) and the
    rest in its own part, next to the shared part where the building allows (a robot whose
    part lies beyond another's drives through it); half the robots, drawn at random, drive
    their own part first. With ``overlap`` = 0 the parts are those of robots spread as far
    apart as the graph allows, and none includes a waypoint next to another's. Each own part
    is a Voronoi cell of the waypoint graph, driven by a walk that takes the least-driven
    edge at each waypoint (ties at random), so it covers its part before it repeats itself.
    A path starts at a random point of its first edge, so starts and headings are random.
    """
    if robots < 1:
        raise ValueError(f"robots must be >= 1, got {robots}")
    if not 0.0 <= overlap <= 1.0:
        raise ValueError(f"overlap must be in [0, 1], got {overlap}")
    if not length > 0.0:
        raise ValueError(f"length must be > 0 m, got {length}")
    if robots > len(building.nodes):
        raise ValueError(
            f"a building with {len(building.nodes)} waypoints cannot give {robots} robots "
            f"parts of their own; use fewer robots or a larger building"
        )
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_ROUTE_STREAM,)))
    graph = _Graph.of(building)
    spare = graph.longest_edge  # walks reach this much past the length: room for the start
    shared = np.zeros(graph.size, dtype=bool)
    if overlap > 0.0:
        shared = graph.ball(int(rng.integers(graph.size)), _SHARED_AREA * overlap * length)
    owner = graph.territories(robots, shared, (1.0 - overlap) * length, rng)
    paths = []
    for k in range(robots):
        own = owner == k
        if overlap == 0.0:
            own = graph.inner(own, owner)
        reverse = False
        if shared.any():
            together = overlap * length + (spare if overlap == 1.0 else 0.0)
            walk = graph.walk(int(rng.choice(np.flatnonzero(shared))), shared, together, rng)
            if overlap < 1.0:
                walk += graph.route(walk[-1], np.flatnonzero(own))[1:]
                rest = (1.0 - overlap) * length + spare
                walk += graph.walk(walk[-1], own, rest, rng)[1:]
            reverse = bool(rng.random() < 0.5)
        else:
            walk = graph.walk(int(rng.choice(np.flatnonzero(own))), own, length + spare, rng)
        points = graph.nodes[walk]
        first = float(np.hypot(*(points[1] - points[0]))) if len(points) > 1 else 0.0
        path = _stretch(points, rng.random() * first, length)
        # Reversed after the cut: the robot starts where its own part was cut, ends shared.
        paths.append(np.ascontiguousarray(path[::-1]) if reverse else path)
    return paths


@dataclasses.dataclass(frozen=True)
class _Graph:
    """The waypoint graph: positions, neighbour lists with edge lengths, and both as a
    sparse matrix for shortest paths."""

    nodes: FloatArray
    ends: IntArray  # (E, 2)
    lengths: FloatArray  # (E,) m
    neighbours: list[list[int]]
    weights: list[list[float]]

    @property
    def size(self) -> int:
        return len(self.nodes)

    @property
    def longest_edge(self) -> float:
        return float(self.lengths.max(initial=0.0))

    @staticmethod
    def of(building: Building) -> _Graph:
        ends = building.edges
        lengths = np.hypot(*(building.nodes[ends[:, 0]] - building.nodes[ends[:, 1]]).T)
        neighbours: list[list[int]] = [[] for _ in building.nodes]
        weights: list[list[float]] = [[] for _ in building.nodes]
        for (a, b), w in zip(ends.tolist(), lengths.tolist(), strict=True):
            neighbours[a].append(b)
            neighbours[b].append(a)
            weights[a].append(w)
            weights[b].append(w)
        return _Graph(building.nodes, ends, lengths, neighbours, weights)

    def matrix(self, keep: BoolArray | None = None) -> csr_matrix:
        """Edge lengths as a symmetric sparse matrix (only edges between ``keep`` waypoints)."""
        ends, lengths = self.ends, self.lengths
        if keep is not None:
            inside = keep[ends[:, 0]] & keep[ends[:, 1]]
            ends, lengths = ends[inside], lengths[inside]
        rows, cols = np.r_[ends[:, 0], ends[:, 1]], np.r_[ends[:, 1], ends[:, 0]]
        return csr_matrix((np.r_[lengths, lengths], (rows, cols)), shape=(self.size, self.size))

    def ball(self, centre: int, edge_length: float) -> BoolArray:
        """The waypoints nearest ``centre`` (along edges) whose edges among them add up to
        about ``edge_length`` m: at least one edge."""
        distance = dijkstra(self.matrix(), indices=centre)
        return self.nearest_holding(distance, np.ones(self.size, dtype=bool), edge_length, 2)

    def nearest_holding(
        self, distance: FloatArray, allowed: BoolArray, edge_length: float, least: int = 1
    ) -> BoolArray:
        """The ``allowed`` waypoints of smallest ``distance`` whose edges among them add up
        to about ``edge_length`` m (at least ``least`` waypoints)."""
        inside = np.zeros(self.size, dtype=bool)
        total, count = 0.0, 0
        for node in np.argsort(distance, kind="stable").tolist():
            if not allowed[node]:
                continue
            if (total >= edge_length and count >= least) or not np.isfinite(distance[node]):
                break
            inside[node] = True
            count += 1
            links = zip(self.neighbours[node], self.weights[node], strict=True)
            total += sum(w for j, w in links if inside[j])
        return inside

    def territories(
        self, count: int, shared: BoolArray, own_length: float, rng: np.random.Generator
    ) -> IntArray:
        """Owner (0..count-1, or -1) of each waypoint outside ``shared``: the Voronoi cells
        (along edges, not through the shared part) of ``count`` seeds spread far apart by
        farthest-point sampling. With a shared part, the seeds are drawn among the waypoints
        nearest it that hold every robot's ``own_length`` m of driving (or are within
        _SEED_REACH_M of it), so each robot's part is near the shared one, yet large enough
        to drive in where the building allows."""
        free = ~shared if np.count_nonzero(~shared) >= count else np.ones(self.size, bool)
        candidates = np.flatnonzero(free)
        if shared.any():
            to_shared = dijkstra(self.matrix(), indices=np.flatnonzero(shared), min_only=True)
            near = self.nearest_holding(to_shared, free, count * own_length, count)
            near |= free & (to_shared <= _SEED_REACH_M)
            candidates = np.flatnonzero(near)
        full = self.matrix()
        seeds = [int(rng.choice(candidates))]
        nearest = dijkstra(full, indices=seeds[0])
        while len(seeds) < count:
            score = np.where(np.isin(candidates, seeds), -1.0, nearest[candidates])
            seeds.append(int(candidates[int(np.argmax(score))]))
            nearest = np.minimum(nearest, dijkstra(full, indices=seeds[-1]))
        _, _, source = dijkstra(
            self.matrix(free), indices=seeds, min_only=True, return_predecessors=True
        )
        owner = np.full(self.size, -1, dtype=np.int64)
        index = {s: k for k, s in enumerate(seeds)}
        for node in np.flatnonzero(free & (source >= 0)).tolist():
            owner[node] = index[int(source[node])]
        return owner

    def inner(self, own: BoolArray, owner: IntArray) -> BoolArray:
        """``own`` without its waypoints next to another part's (all of ``own`` when that
        would leave no edge to drive)."""
        inner = own.copy()
        for i in np.flatnonzero(own).tolist():
            if any(owner[j] != owner[i] for j in self.neighbours[i]):
                inner[i] = False
        drivable = any(inner[j] for i in np.flatnonzero(inner).tolist() for j in self.neighbours[i])
        return inner if drivable else own

    def route(self, start: int, targets: IntArray) -> list[int]:
        """The shortest path from ``start`` to the nearest of ``targets``."""
        if targets.size == 0:
            return [start]
        distance, previous = dijkstra(self.matrix(), indices=start, return_predecessors=True)
        node = int(targets[np.argmin(distance[targets])])
        path = [node]
        while node != start and previous[node] >= 0:
            node = int(previous[node])
            path.append(node)
        return path[::-1]

    def walk(
        self, start: int, allowed: BoolArray, length: float, rng: np.random.Generator
    ) -> list[int]:
        """Waypoints of a walk of at least ``length`` m from ``start`` inside ``allowed``
        (where it can), taking the least-driven edge at each waypoint (ties at random) and
        turning back only at a dead end."""
        driven: dict[tuple[int, int], int] = {}
        path, travelled, previous = [start], 0.0, -1
        while travelled < length:
            here = path[-1]
            links = list(zip(self.neighbours[here], self.weights[here], strict=True))
            options = [(j, w) for j, w in links if allowed[j]] or links
            if not options:
                break  # a waypoint without edges: the robot stands still
            if len(options) > 1:
                options = [(j, w) for j, w in options if j != previous] or options
            counts = [driven.get((min(here, j), max(here, j)), 0) for j, _ in options]
            ties = [o for o, c in zip(options, counts, strict=True) if c == min(counts)]
            nxt, step = ties[int(rng.integers(len(ties)))]
            key = (min(here, nxt), max(here, nxt))
            driven[key] = driven.get(key, 0) + 1
            travelled += step
            previous = here
            path.append(nxt)
        return path


def _stretch(points: FloatArray, start: float, length: float) -> FloatArray:
    """The part of the polyline ``points`` from ``start`` to ``start + length`` metres along
    it (to its end if shorter)."""
    along = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))))
    s1 = min(start + length, float(along[-1]))
    inner = along[(along > start) & (along < s1)]
    s = np.concatenate(([start], inner, [s1]))
    return np.column_stack((np.interp(s, along, points[:, 0]), np.interp(s, along, points[:, 1])))


# ---------------------------------------------------------------------------------------------
# Drives and scans.
# ---------------------------------------------------------------------------------------------


def drive_routes(
    paths: Sequence[FloatArray],
    speed: float,
    rate: float,
    duration: float,
    sparse: SparseSpacing | None = None,
    start: float = SIM_START_S,
) -> list[Drive]:
    """Each path driven at ``speed`` m/s for ``duration`` s, a pose every 1/``rate`` s from
    the stamp ``start`` (:func:`~core.simulation.drive_path`: a path shorter than the drive
    is patrolled back and forth); with ``sparse``, only the poses :func:`keep_sparse` keeps."""
    if not (speed > 0.0 and rate > 0.0 and duration > 0.0):
        raise ValueError(
            f"speed ({speed} m/s), rate ({rate} Hz) and duration ({duration} s) must be > 0"
        )
    drives = []
    for path in paths:
        poses = drive_path(path, speed, rate, duration)
        stamps = start + np.arange(len(poses), dtype=np.float64) / rate
        if sparse is not None:
            keep = keep_sparse(poses, sparse)
            poses, stamps = poses[keep], stamps[keep]
        drives.append(Drive(stamps=stamps, T_world_laser=poses))
    return drives


def keep_sparse(poses: FloatArray, spacing: SparseSpacing) -> IntArray:
    """Indices of the poses ``(N, 3)`` to keep: the first, then each one that has moved
    ``spacing.distance`` m (along the way) or turned ``spacing.turn`` rad from the last kept."""
    if not (spacing.distance > 0.0 and spacing.turn > 0.0):
        raise ValueError(f"sparse spacing must be > 0, got {spacing}")
    if len(poses) == 0:
        return np.zeros(0, dtype=np.int64)
    along = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))))
    heading = np.unwrap(poses[:, 2])
    keep, last = [0], 0
    for i in range(1, len(poses)):
        moved = along[i] - along[last] >= spacing.distance
        if moved or abs(heading[i] - heading[last]) >= spacing.turn:
            keep.append(i)
            last = i
    return np.asarray(keep, dtype=np.int64)


@dataclasses.dataclass(frozen=True)
class BuildingScanner:
    """Exact laser ranges in a building, cast only against what lies within range.

    Walls and furniture share one :class:`~core.segment_grid.SegmentGrid`, glass has its own,
    people are placed at each scan's time and kept when their line is within range. The
    ranges are bitwise those of :func:`~core.simulation.raycast_fan` on everything at once.
    """

    laser: LaserModel
    solid: SegmentGrid  # walls and furniture
    glass: SegmentGrid
    walkers: FloatArray  # (P, 4) lines people walk along

    @staticmethod
    def of(building: Building, laser: LaserModel) -> BuildingScanner:
        solid = np.vstack((building.walls, building.clutter.static))
        return BuildingScanner(
            laser,
            segment_grid(solid, laser.range_max),
            segment_grid(building.glass, laser.range_max),
            building.clutter.walkers,
        )

    def ranges(self, pose: tuple[float, float, float], seconds: float = 0.0) -> FloatArray:
        """Range along each beam from the laser pose ``pose`` (world frame) with the people
        where they are ``seconds`` after the first stamp: ``inf`` where the beam meets
        nothing within range, or meets glass first."""
        laser = self.laser
        x, y, _ = pose
        fan = (laser.angle_min, laser.angle_increment, laser.beams, laser.range_max)
        near = self.solid.segments[self.solid.near(x, y)]
        ranges = raycast_fan(near, pose, *fan)
        if len(self.walkers):
            w = self.walkers
            distance = _point_to_segments(x, y, w)
            legs = people_at(w[distance <= laser.range_max + _PERSON_REACH_M], seconds)
            if legs:
                ranges = np.minimum(ranges, raycast_fan(np.vstack(legs), pose, *fan))
        panes = self.glass.segments[self.glass.near(x, y)]
        if len(panes):
            ranges = np.where(ranges <= raycast_fan(panes, pose, *fan), ranges, np.inf)
        return ranges


def _point_to_segments(x: float, y: float, segments: FloatArray) -> FloatArray:
    s = segments
    return point_segment_distance(np.asarray(x), np.asarray(y), s[:, 0], s[:, 1], s[:, 2], s[:, 3])


def scan_drives(
    building: Building,
    drives: Sequence[Drive],
    laser: LaserModel,
    seed: int = 0,
    start: float = SIM_START_S,
) -> list[SimulatedRobot]:
    """A noisy scan (:func:`~core.simulation.scan_from_ranges`) at every pose of every drive;
    robot ``k`` draws its noise from ``SeedSequence(seed, spawn_key=(k,))``, people walk from
    the stamp ``start``."""
    scanner = BuildingScanner.of(building, laser)
    runs = []
    for k, drive in enumerate(drives):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(k,)))
        scans = [
            scan_from_ranges(scanner.ranges((p[0], p[1], p[2]), t - start), laser, rng)
            for p, t in zip(drive.T_world_laser.tolist(), drive.stamps.tolist(), strict=True)
        ]
        runs.append(
            SimulatedRobot(stamps=drive.stamps, T_world_laser=drive.T_world_laser, scans=scans)
        )
    return runs


def simulate_building(
    building: Building,
    robots: int,
    laser: LaserModel,
    seed: int = 0,
    duration: float = 60.0,
    speed: float = 0.8,
    overlap: float = OVERLAP_LEVELS["small"],
    sparse: SparseSpacing | None = None,
    start: float = SIM_START_S,
) -> list[SimulatedRobot]:
    """:func:`plan_routes` (``speed * duration`` m each), :func:`drive_routes` at the laser's
    rate and :func:`scan_drives`, in one call."""
    paths = plan_routes(building, robots, speed * duration, overlap, seed)
    drives = drive_routes(paths, speed, laser.rate, duration, sparse, start)
    return scan_drives(building, drives, laser, seed, start)


def shared_ground(tracks: Sequence[FloatArray], radius: float = 0.5) -> FloatArray:
    """``(K, K)`` share of robot ``i``'s track (its driven length) within ``radius`` m of
    robot ``j``'s, for tracks of positions ``(N, >=2)`` (poses or paths, resampled every
    0.1 m); the diagonal is 1. How much ground the robots really share."""
    samples = [_resample(np.asarray(t, dtype=np.float64)[:, :2], 0.1) for t in tracks]
    trees = [cKDTree(s) for s in samples]
    count = len(samples)
    shares = np.eye(count)
    for i in range(count):
        for j in range(count):
            if i != j:
                distance, _ = trees[j].query(samples[i], distance_upper_bound=radius)
                shares[i, j] = float(np.mean(np.isfinite(distance)))
    return shares


def _resample(points: FloatArray, step: float) -> FloatArray:
    """Points every ``step`` m along a polyline (its vertices' order)."""
    along = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))))
    s = np.append(np.arange(0.0, along[-1], step), along[-1])
    return np.column_stack((np.interp(s, along, points[:, 0]), np.interp(s, along, points[:, 1])))
