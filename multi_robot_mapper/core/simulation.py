"""A 2-D laser simulator: vectorised ray casting in the built-in worlds (:mod:`core.worlds`),
robots driving their routes, and clutter (furniture, walking people). Generated buildings
(:mod:`core.buildings`, :mod:`core.building_runs`) reuse its lasers, noise, drives and clutter.

Worlds are ``(W, 4)`` segment sets in the ``world`` frame. A scan is every beam intersected with
every wall at once (beams x walls arrays), with Gaussian range noise and random dropouts, all
drawn from a seeded generator so a seed always gives the same scans.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.geometry import point_segment_distance, ranges_index
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.worlds import ROUTES, WORLDS, arc, box

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclasses.dataclass(frozen=True)
class LaserModel:
    """Beam geometry and noise; defaults are a Hokuyo UTM-30LX (40 Hz, 1081 beams, 270 deg)."""

    beams: int = 1081
    field_of_view: float = np.radians(270.0)  # rad
    range_min: float = 0.1  # m
    range_max: float = 30.0  # m
    range_noise: float = 0.01  # m, standard deviation
    dropout: float = 0.005  # probability that a beam returns nothing (NaN)
    rate: float = 40.0  # Hz

    @property
    def angles(self) -> FloatArray:
        """Bearing of each beam in the laser frame, rad."""
        return self.angle_min + self.angle_increment * np.arange(self.beams, dtype=np.float64)

    @property
    def angle_min(self) -> float:
        return -0.5 * self.field_of_view

    @property
    def angle_increment(self) -> float:
        return self.field_of_view / (self.beams - 1)


LASERS: Mapping[str, LaserModel] = MappingProxyType(
    {
        "utm30lx": LaserModel(),
        # The SICK LMS 200/291 of the CARMEN logs: 181 beams over 180 deg, 1 deg apart, 80 m.
        "lms": LaserModel(beams=181, field_of_view=np.pi, range_max=80.0, rate=10.0),
    }
)
"""The simulated lasers by name (``mrm simulate --laser``); they share the noise model."""


def _ray_wall_hits(
    dx: FloatArray,
    dy: FloatArray,
    ax: FloatArray,
    ay: FloatArray,
    ex: FloatArray,
    ey: FloatArray,
    max_range: float,
) -> tuple[FloatArray, BoolArray]:
    """Range ``t`` of each (beam, wall) pair and whether the beam hits the wall there.

    Beam directions ``(dx, dy)``, wall starts ``(ax, ay)`` relative to the laser and wall
    vectors ``(ex, ey)``, element-wise (any shapes that broadcast). The one place the
    intersection is solved, so :func:`raycast` and :func:`raycast_fan` agree bitwise.
    """
    # Solve t * d = a + s * e for range t >= 0 and wall parameter 0 <= s <= 1.
    denom = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = (ax * ey - ay * ex) / denom
        s = (ax * dy - ay * dx) / denom
    hit = (np.abs(denom) > 1e-12) & (t > 1e-9) & (s >= 0.0) & (s <= 1.0) & (t <= max_range)
    return t, hit


def raycast(
    walls: FloatArray, pose: tuple[float, float, float], angles: FloatArray, max_range: float
) -> FloatArray:
    """Exact range along each beam to the nearest wall (``inf`` where nothing is hit)."""
    x, y, theta = pose
    dx = np.cos(theta + angles)[:, None]
    dy = np.sin(theta + angles)[:, None]
    ax, ay = walls[:, 0][None, :] - x, walls[:, 1][None, :] - y
    ex, ey = (walls[:, 2] - walls[:, 0])[None, :], (walls[:, 3] - walls[:, 1])[None, :]
    t, hit = _ray_wall_hits(dx, dy, ax, ay, ex, ey, max_range)
    return np.asarray(np.where(hit, t, np.inf).min(axis=1))


def raycast_fan(
    walls: FloatArray,
    pose: tuple[float, float, float],
    angle_min: float,
    angle_increment: float,
    beams: int,
    max_range: float,
) -> FloatArray:
    """:func:`raycast` for the evenly spaced beams of a laser, about ten times faster.

    Each wall can only be hit by the beams between the bearings of its two ends, so only those
    (beam, wall) pairs are solved, with one beam of slack either side; each pair uses exactly
    the arithmetic of :func:`raycast`, so the ranges are bitwise the same (test_simulation).
    """
    poses = np.asarray(pose, dtype=np.float64).reshape(1, 3)
    return np.asarray(raycast_fans(walls, poses, angle_min, angle_increment, beams, max_range)[0])


def raycast_fans(
    walls: FloatArray,
    poses: FloatArray,
    angle_min: float,
    angle_increment: float,
    beams: int,
    max_range: float,
) -> FloatArray:
    """:func:`raycast_fan` from each of the ``(K, 3)`` laser poses at once: ``(K, beams)``."""
    angles = angle_min + angle_increment * np.arange(beams, dtype=np.float64)
    count = len(poses)
    if len(walls) == 0 or count == 0:
        return np.full((count, beams), np.inf)  # nothing to hit (or nobody to look)
    if beams < 2 or angle_increment == 0.0:
        return np.array([raycast(walls, (p[0], p[1], p[2]), angles, max_range) for p in poses])
    x, y, theta = (poses[:, i, None] for i in range(3))  # (K, 1) against (N,) walls
    ax, ay = walls[:, 0] - x, walls[:, 1] - y
    ex, ey = walls[:, 2] - walls[:, 0], walls[:, 3] - walls[:, 1]
    turn = 2.0 * np.pi
    step = abs(angle_increment)
    # Bearings counted counter-clockwise from the lowest beam, in [0, 2 pi).
    lowest = angle_min if angle_increment > 0 else angle_min + angle_increment * (beams - 1)
    phi_a = np.mod(np.arctan2(ay, ax) - theta - lowest, turn)
    phi_b = np.mod(np.arctan2(walls[:, 3] - y, walls[:, 2] - x) - theta - lowest, turn)
    ccw = np.mod(phi_b - phi_a, turn)
    # A segment not through the laser subtends less than half a turn: the short way round.
    short = ccw <= np.pi
    lo = np.where(short, phi_a, phi_b)
    hi = lo + np.where(short, ccw, turn - ccw)
    # Beam index ranges [start, stop) per (pose, wall); the second copy catches sectors past
    # 2 pi.
    first = np.ceil(np.hstack((lo, lo - turn)) / step).astype(np.int64) - 1
    last = np.floor(np.hstack((hi, hi - turn)) / step).astype(np.int64) + 1
    start = np.clip(first, 0, beams).ravel()
    stop = np.clip(last + 1, 0, beams).ravel()
    ranges = np.full((count, beams), np.inf)
    # ranges_index takes no empty ranges; a wall farther than max_range from the laser is hit
    # by no beam (t >= that distance), so its beams are not solved (a global map's far walls
    # were most of the pairs; 1e-9 of slack for the rounding of the two distances).
    within = point_segment_distance(x, y, walls[:, 0], walls[:, 1], walls[:, 2], walls[:, 3])
    seen = (stop > start) & np.tile(within <= max_range + 1e-9, 2).ravel()
    if not seen.any():
        return ranges
    beam, owner, _ = ranges_index(start[seen], stop[seen])
    pair = np.flatnonzero(seen)[owner]  # index into the (K, 2N) grid
    row, wall = np.divmod(pair, 2 * len(walls))
    wall = wall % len(walls)
    if angle_increment < 0:
        beam = beams - 1 - beam  # counted from the lowest beam, which is the last one
    heading = poses[row, 2] + angles[beam]
    dx, dy = np.cos(heading), np.sin(heading)
    t, hit = _ray_wall_hits(dx, dy, ax[row, wall], ay[row, wall], ex[wall], ey[wall], max_range)
    flat = ranges.ravel()
    np.minimum.at(flat, (row * beams + beam)[hit], t[hit])
    return flat.reshape(count, beams)


def simulate_scan(
    walls: FloatArray,
    pose: tuple[float, float, float],
    laser: LaserModel,
    rng: np.random.Generator,
) -> LaserScanData:
    """One noisy scan of ``walls`` from the laser pose ``pose`` (world frame)."""
    ranges = raycast_fan(
        walls, pose, laser.angle_min, laser.angle_increment, laser.beams, laser.range_max
    )
    return scan_from_ranges(ranges, laser, rng)


def scan_from_ranges(
    ranges: FloatArray, laser: LaserModel, rng: np.random.Generator
) -> LaserScanData:
    """The laser's noisy scan of exact ``ranges`` (``inf`` where nothing returns): Gaussian
    range noise, then dropouts (NaN), drawn from ``rng`` in that order."""
    noisy = ranges + rng.normal(0.0, laser.range_noise, size=ranges.shape)
    noisy[rng.random(ranges.shape) < laser.dropout] = np.nan
    noisy[~np.isfinite(ranges)] = np.inf  # no return (REP-117)
    return LaserScanData(
        ranges=noisy,
        angle_min=laser.angle_min,
        angle_max=laser.angle_min + laser.angle_increment * (laser.beams - 1),
        angle_increment=laser.angle_increment,
        range_min=laser.range_min,
        range_max=laser.range_max,
    )


# ---------------------------------------------------------------------------------------------
# ---------------------------------------------------------------------------------------------
# Multi-robot runs through the worlds (``mrm simulate``).
# ---------------------------------------------------------------------------------------------


# Stamp of the first simulated scan, s. Not 0: ROS tools read a zero stamp as "unset" (tf2
# answers "latest" for time 0), so simulated bags start at a plain non-zero epoch.
SIM_START_S = 1_000_000_000.0


def _closed(route: FloatArray) -> FloatArray:
    """The route's vertices with the first repeated at the end (a closed tour)."""
    if np.array_equal(route[0], route[-1]):
        return route
    return np.vstack((route, route[:1]))


def _arc_length(vertices: FloatArray) -> FloatArray:
    """Distance along a polyline at each vertex (starts at 0)."""
    return np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(vertices, axis=0).T))))


def route_section(route: FloatArray, start: float, length: float) -> FloatArray:
    """The ``(M, 2)`` waypoints from ``start`` to ``start + length`` metres along a closed tour.

    Distances wrap round the tour, so a section may run through the starting vertex.
    """
    loop = _closed(np.asarray(route, dtype=np.float64))
    total = _arc_length(loop)[-1]
    twice = np.vstack((loop, loop[1:]))  # walking past the end continues on the next lap
    s_twice = _arc_length(twice)
    s0 = start % total
    s1 = s0 + min(length, total)
    inner = s_twice[(s_twice > s0) & (s_twice < s1)]
    s = np.concatenate(([s0], inner, [s1]))
    return np.column_stack((np.interp(s, s_twice, twice[:, 0]), np.interp(s, s_twice, twice[:, 1])))


def plan_paths(
    route: Sequence[tuple[float, float]] | FloatArray,
    robots: int,
    distance: float,
    overlap: float = 0.3,
) -> list[FloatArray]:
    """Waypoints ``(M, 2)`` for each of ``robots`` robots: sections of one closed tour.

    Each robot gets its own stretch of the tour, ``distance`` metres long at most; consecutive
    robots start ``1 - overlap`` of a stretch apart, so neighbours share the last/first
    ``overlap`` of their stretches and nobody else's (the place a map merger can match), while
    every robot also sees ground of its own. With many robots or long drives the stretches are
    shortened so that together they still cover the tour only once plus the shared parts.
    """
    if robots < 1:
        raise ValueError(f"robots must be >= 1, got {robots}")
    if not 0.0 < overlap < 0.5:
        # Below 0.5 a stretch never reaches past its neighbour's into the next robot's.
        raise ValueError(f"overlap must be in (0, 0.5), got {overlap}")
    if distance <= 0.0:
        raise ValueError(f"distance must be > 0 m, got {distance}")
    loop = _closed(np.asarray(route, dtype=np.float64))
    total = float(_arc_length(loop)[-1])
    longest = total if robots == 1 else total * (1.0 + overlap) / robots
    length = min(distance, longest)
    spacing = min(total / robots, (1.0 - overlap) * length)
    return [route_section(loop, k * spacing, length) for k in range(robots)]


def _moving_average(values: FloatArray, window: int) -> FloatArray:
    """Centred moving average, the ends padded with the first/last value."""
    kernel = np.ones(window) / window
    padded = np.concatenate((np.full(window, values[0]), values, np.full(window, values[-1])))
    return np.asarray(np.convolve(padded, kernel, mode="same")[window:-window])


def drive_path(waypoints: FloatArray, speed: float, rate: float, duration: float) -> FloatArray:
    """Poses ``(x, y, theta)`` at ``rate`` Hz for ``duration`` s along ``waypoints`` at ``speed``.

    At the last waypoint the robot turns round and drives back, and so on (a patrol), so any
    duration fits any path. The heading follows the direction of travel and turns smoothly (a
    moving average over about one second), as a differential-drive robot would.
    """
    wp = np.asarray(waypoints, dtype=np.float64)
    s_wp = _arc_length(wp)
    length = float(s_wp[-1])
    count = max(1, int(np.floor(duration * rate + 1e-9)))
    travelled = speed * np.arange(count, dtype=np.float64) / rate
    if length <= 0.0:
        return np.column_stack(
            (np.full(count, wp[0, 0]), np.full(count, wp[0, 1]), np.zeros(count))
        )
    phase = np.mod(travelled, 2.0 * length)
    forward = phase < length
    s = np.where(forward, phase, 2.0 * length - phase)
    xy = np.column_stack((np.interp(s, s_wp, wp[:, 0]), np.interp(s, s_wp, wp[:, 1])))
    leg_heading = np.arctan2(*np.diff(wp, axis=0)[:, ::-1].T)
    # The leg being driven: ahead of s going forward, behind it coming back.
    leg = np.where(
        forward,
        np.searchsorted(s_wp, s, side="right") - 1,
        np.searchsorted(s_wp, s, side="left") - 1,
    )
    leg = np.clip(leg, 0, len(leg_heading) - 1)
    heading = np.unwrap(leg_heading[leg] + np.where(forward, 0.0, np.pi))
    smooth = _moving_average(heading, max(1, int(rate)))
    return np.column_stack((xy, smooth))


@dataclasses.dataclass(frozen=True)
class SimulatedRobot:
    """One robot's simulated run: the laser's true pose and its scan at each stamp."""

    stamps: FloatArray  # (N,) s
    T_world_laser: FloatArray  # (N, 3) x, y, theta of the laser in the world frame
    scans: list[LaserScanData]


def simulate_robots(
    world: str,
    robots: int,
    laser: LaserModel,
    seed: int = 0,
    duration: float = 20.0,
    speed: float = 0.8,
    overlap: float = 0.3,
    start: float = SIM_START_S,
    clutter: Clutter | None = None,
) -> list[SimulatedRobot]:
    """Simulate ``robots`` robots driving partly overlapping stretches of a built-in world.

    All robots scan at ``laser.rate`` from the same first stamp ``start``. Robot ``k`` draws its
    noise from its own stream of ``seed`` (``SeedSequence(seed, spawn_key=(k,))``), so a seed
    gives the same scans for a robot however many robots are simulated. ``clutter``
    (:func:`clutter_for`) adds furniture and walking people (where they are at each stamp).
    """
    if world not in WORLDS or world not in ROUTES:
        raise ValueError(f"unknown world {world!r}; known: {', '.join(sorted(ROUTES))}")
    if duration <= 0.0 or speed <= 0.0 or laser.rate <= 0.0:
        raise ValueError(
            f"duration ({duration} s), speed ({speed} m/s) and rate ({laser.rate} Hz) must be > 0"
        )
    walls = WORLDS[world]()
    paths = plan_paths(ROUTES[world], robots, speed * duration, overlap)
    runs = []
    for k, waypoints in enumerate(paths):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(k,)))
        poses = drive_path(waypoints, speed, laser.rate, duration)
        stamps = start + np.arange(len(poses), dtype=np.float64) / laser.rate
        if clutter is None:
            scans = [simulate_scan(walls, (p[0], p[1], p[2]), laser, rng) for p in poses]
        else:
            scans = [
                simulate_scan(clutter.walls_at(walls, t - start), (p[0], p[1], p[2]), laser, rng)
                for p, t in zip(poses, stamps, strict=True)
            ]
        runs.append(SimulatedRobot(stamps=stamps, T_world_laser=poses, scans=scans))
    return runs


# ---------------------------------------------------------------------------------------------
# Clutter: chair and table legs, pillars and walking people (``mrm simulate --clutter``).
# ---------------------------------------------------------------------------------------------

_LEG = 0.04  # m, side of a chair or table leg
_PERSON_LEG = 0.06  # m, radius of a walking person's leg
_PERSON_SPEED = 1.0  # m/s
_EXTENT = 0.7  # m, the farthest an object reaches from where it is placed (a table's corner)


@dataclasses.dataclass(frozen=True)
class Clutter:
    """What a crowded place adds to a world: furniture that stays put and people who walk.

    ``static`` are small objects (chair and table legs, pillars) that make clusters of a few
    returns, too small for a segment; ``walkers`` are people walking to and fro along a line,
    each two legs that a laser at knee height sees as two small arcs.
    """

    static: FloatArray  # (N, 4) segments
    walkers: FloatArray  # (W, 4) x1, y1, x2, y2 of each person's line of walking

    def walls_at(self, walls: FloatArray, seconds: float) -> FloatArray:
        """The world's walls, the furniture and every person where they are at ``seconds``."""
        return np.vstack([walls, self.static, *people_at(self.walkers, seconds)])


def people_at(walkers: FloatArray, seconds: float) -> list[FloatArray]:
    """The legs of each person walking to and fro along a line of ``walkers`` (W, 4) at
    ``seconds``: two small arcs per person, person after person."""
    pieces = []
    for x1, y1, x2, y2 in walkers:
        length = float(np.hypot(x2 - x1, y2 - y1))
        # To and fro along the line: position along it, a triangle wave in time.
        phase = (seconds * _PERSON_SPEED / max(length, 1e-9)) % 2.0
        share = phase if phase <= 1.0 else 2.0 - phase
        cx, cy = x1 + share * (x2 - x1), y1 + share * (y2 - y1)
        nx, ny = -(y2 - y1) / max(length, 1e-9), (x2 - x1) / max(length, 1e-9)
        stride = 0.15 * np.sin(2.0 * np.pi * seconds)  # legs swing while walking
        for side in (-1.0, 1.0):
            lx = cx + side * 0.12 * nx + side * stride * (x2 - x1) / max(length, 1e-9)
            ly = cy + side * 0.12 * ny + side * stride * (y2 - y1) / max(length, 1e-9)
            pieces.append(arc((lx, ly), _PERSON_LEG, 0.0, 2 * np.pi, pieces=6))
    return pieces


def clutter_for(world: str, density: float, seed: int = 0) -> Clutter:
    """Clutter for a built-in world: ``density`` objects per square metre of free floor (a
    chair, a table, a pillar or a walking person, drawn at random), kept 0.6 m from the
    world's route (where robots drive) and 0.3 m from every wall. Deterministic for a seed."""
    if world not in WORLDS or world not in ROUTES:
        raise ValueError(f"unknown world {world!r}; known: {', '.join(sorted(ROUTES))}")
    if not 0.0 <= density <= 2.0:
        raise ValueError(f"clutter density must be in [0, 2] objects per m^2, got {density}")
    walls = WORLDS[world]()
    route = _closed(np.asarray(ROUTES[world], dtype=np.float64))
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(1000,)))
    ends = walls.reshape(-1, 2)
    lo, hi = ends.min(axis=0), ends.max(axis=0)
    area = float(np.prod(hi - lo))
    wanted = round(density * area)
    static: list[FloatArray] = []
    walkers: list[tuple[float, float, float, float]] = []
    route_segments = np.hstack((route[:-1], route[1:]))
    tries = 0
    while len(static) + len(walkers) < wanted and tries < 50 * max(wanted, 1):
        tries += 1
        x, y = rng.uniform(lo, hi)
        near_wall = _distance_to(walls, x, y) < 0.3 + _EXTENT
        if near_wall or _distance_to(route_segments, x, y) < 0.6 + _EXTENT:
            continue
        kind = rng.choice(4, p=[0.4, 0.25, 0.15, 0.2])
        turn = rng.uniform(0.0, np.pi)
        if kind < 3:
            static.append(_furniture(int(kind), x, y, turn, rng))
        else:  # a person walking to and fro along 2-4 m
            reach = rng.uniform(1.0, 2.0)
            dx, dy = reach * np.cos(turn), reach * np.sin(turn)
            walkers.append((x - dx, y - dy, x + dx, y + dy))
    return Clutter(
        np.vstack(static) if static else np.zeros((0, 4)),
        np.asarray(walkers, dtype=np.float64).reshape(-1, 4),
    )


def furniture_piece(rng: np.random.Generator, x: float, y: float) -> FloatArray:
    """A chair, a table or a round pillar at ``(x, y)``, turned at random (the furniture of
    :func:`clutter_for`, without its people): segments within 0.75 m of the point."""
    kind = rng.choice(3, p=[0.5, 0.3, 0.2])
    return _furniture(int(kind), x, y, rng.uniform(0.0, np.pi), rng)


def _furniture(kind: int, x: float, y: float, turn: float, rng: np.random.Generator) -> FloatArray:
    if kind == 0:  # a chair: four legs on a 0.45 m square
        return _legs(x, y, 0.45, 0.45, turn)
    if kind == 1:  # a table: four legs on a 0.8 x 1.2 m rectangle
        return _legs(x, y, 0.8, 1.2, turn)
    return arc((x, y), rng.uniform(0.1, 0.25), 0.0, 2 * np.pi, pieces=8)  # a round pillar


def _legs(x: float, y: float, width: float, depth: float, turn: float) -> FloatArray:
    """Four small square legs at the corners of a ``width`` x ``depth`` rectangle."""
    c, s = np.cos(turn), np.sin(turn)
    legs = []
    for u, v in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        lx = x + c * u * width / 2 - s * v * depth / 2
        ly = y + s * u * width / 2 + c * v * depth / 2
        legs.append(box(lx, ly, _LEG, _LEG))
    return np.vstack(legs)


def _distance_to(segments: FloatArray, x: float, y: float) -> float:
    """Distance from ``(x, y)`` to the nearest of ``segments``."""
    n = len(segments)
    return float(
        point_segment_distance(
            np.full(n, x),
            np.full(n, y),
            segments[:, 0],
            segments[:, 1],
            segments[:, 2],
            segments[:, 3],
        ).min(initial=np.inf)
    )
