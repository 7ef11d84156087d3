"""A 2-D laser simulator: built-in worlds of wall segments and vectorised ray casting.

Worlds are ``(W, 4)`` segment sets in the ``world`` frame. A scan is every beam intersected with
every wall at once (beams x walls arrays), with Gaussian range noise and random dropouts, all
drawn from a seeded generator so a seed always gives the same scans.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.scan import LaserScanData

FloatArray = NDArray[np.float64]


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
    def angle_min(self) -> float:
        return -0.5 * self.field_of_view

    @property
    def angle_increment(self) -> float:
        return self.field_of_view / (self.beams - 1)


def polygon(vertices: list[tuple[float, float]], closed: bool = True) -> FloatArray:
    """Wall segments along a polyline of vertices."""
    v = np.asarray(vertices, dtype=np.float64)
    if closed:
        v = np.vstack((v, v[:1]))
    return np.hstack((v[:-1], v[1:]))


def arc(
    centre: tuple[float, float], radius: float, start: float, stop: float, pieces: int = 24
) -> FloatArray:
    """A curved wall: the circle arc from angle ``start`` to ``stop`` (rad) in short segments."""
    t = np.linspace(start, stop, pieces + 1)
    pts = np.column_stack((centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)))
    return np.hstack((pts[:-1], pts[1:]))


def box(cx: float, cy: float, w: float, h: float) -> FloatArray:
    """An axis-aligned rectangular obstacle (furniture, a pillar)."""
    return polygon(
        [
            (cx - w / 2, cy - h / 2),
            (cx + w / 2, cy - h / 2),
            (cx + w / 2, cy + h / 2),
            (cx - w / 2, cy + h / 2),
        ]
    )


def office_world() -> FloatArray:
    """Two rooms and a corridor, with doors, furniture and a curved wall (about 24 x 14 m)."""
    walls = [
        # Outer shell with a curved end on the east side.
        polygon([(0, 0), (20, 0)], closed=False),
        polygon([(0, 0), (0, 14), (20, 14)], closed=False),
        arc((20, 7), 7.0, -np.pi / 2, np.pi / 2, pieces=32),
        # Corridor wall at y = 5 with two doors (gaps).
        polygon([(0, 5), (4, 5)], closed=False),
        polygon([(5.2, 5), (11, 5)], closed=False),
        polygon([(12.2, 5), (17, 5)], closed=False),
        # Wall between the two upper rooms, with a door.
        polygon([(9, 5), (9, 9)], closed=False),
        polygon([(9, 10.2), (9, 14)], closed=False),
        # Furniture and pillars.
        box(3.0, 11.0, 1.6, 0.8),
        box(6.5, 7.0, 0.6, 0.6),
        box(14.0, 11.5, 2.0, 1.0),
        box(10.0, 2.5, 0.4, 0.4),
        box(16.0, 2.0, 0.5, 1.2),
        polygon([(12.0, 8.0), (13.5, 7.2), (15.0, 8.4)], closed=False),
    ]
    return np.vstack(walls)


WORLDS = {"office": office_world}


def raycast(
    walls: FloatArray, pose: tuple[float, float, float], angles: FloatArray, max_range: float
) -> FloatArray:
    """Exact range along each beam to the nearest wall (``inf`` where nothing is hit)."""
    x, y, theta = pose
    dx = np.cos(theta + angles)[:, None]
    dy = np.sin(theta + angles)[:, None]
    ax, ay = walls[:, 0][None, :] - x, walls[:, 1][None, :] - y
    ex, ey = (walls[:, 2] - walls[:, 0])[None, :], (walls[:, 3] - walls[:, 1])[None, :]
    # Solve t * d = a + s * e for range t >= 0 and wall parameter 0 <= s <= 1.
    denom = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = (ax * ey - ay * ex) / denom
        s = (ax * dy - ay * dx) / denom
    hit = (np.abs(denom) > 1e-12) & (t > 1e-9) & (s >= 0.0) & (s <= 1.0) & (t <= max_range)
    return np.asarray(np.where(hit, t, np.inf).min(axis=1))


def simulate_scan(
    walls: FloatArray,
    pose: tuple[float, float, float],
    laser: LaserModel,
    rng: np.random.Generator,
) -> LaserScanData:
    """One noisy scan of ``walls`` from the laser pose ``pose`` (world frame)."""
    angles = laser.angle_min + laser.angle_increment * np.arange(laser.beams, dtype=np.float64)
    ranges = raycast(walls, pose, angles, laser.range_max)
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


def waypoint_path(waypoints: list[tuple[float, float]], speed: float, rate: float) -> FloatArray:
    """Poses ``(x, y, theta)`` at ``rate`` Hz driving at ``speed`` m/s through ``waypoints``.

    The heading follows the direction of travel and turns smoothly (a moving average over
    about one second), as a differential-drive robot would.
    """
    wp = np.asarray(waypoints, dtype=np.float64)
    leg = np.hypot(*np.diff(wp, axis=0).T)
    distance = np.concatenate(([0.0], np.cumsum(leg)))
    s = np.arange(0.0, distance[-1], speed / rate)
    xy = np.column_stack((np.interp(s, distance, wp[:, 0]), np.interp(s, distance, wp[:, 1])))
    heading = np.unwrap(
        np.arctan2(*np.diff(xy, axis=0, append=xy[-1:] + (xy[-1:] - xy[-2:-1]))[:, ::-1].T)
    )
    window = max(1, int(rate))
    kernel = np.ones(window) / window
    padded = np.concatenate((np.full(window, heading[0]), heading, np.full(window, heading[-1])))
    smooth = np.convolve(padded, kernel, mode="same")[window:-window]
    return np.column_stack((xy, smooth))
