"""FFS's rigid bodies: each keyframe's segments resampled into points with directions and
masses (FFS Sec. 3.3-3.4).

A point's direction is its segment's, and it says which face of the wall was seen: segments
run with the sensor that saw them on their left (:func:`facing_sensor`). The field then pulls
only faces seen from the same side together (``simulation.force_field``): the two faces of one
wall, seen from the rooms on either side a wall's thickness apart, are not one surface."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Supporting lines meeting at 80-100 deg make a corner (FFS 3.4).
_CORNER_COS = float(np.cos(np.radians(80.0)))


@dataclasses.dataclass(frozen=True)
class Bodies:
    """Every body's points in its own frame, stacked: ``body[i]`` owns point ``i``."""

    points: FloatArray  # (P, 2) in the owning body's frame
    directions: FloatArray  # (P, 2) unit direction of each point's supporting segment
    masses: FloatArray  # (P,) 1, or FfsConfig.roi_mass in a region of interest
    body: IntArray  # (P,) index of the owning body
    count: int  # bodies (some may own no point)


def resample(segments: FloatArray, spacing: float) -> tuple[FloatArray, FloatArray, IntArray]:
    """Points every ``spacing`` metres along each segment, ends included (FFS 3.3), with the
    segment's unit direction and index: (points (P, 2), directions (P, 2), segment (P,))."""
    segments = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    start, end = segments[:, :2], segments[:, 2:]
    length = np.hypot(*(end - start).T)
    steps = np.maximum(np.ceil(length / spacing).astype(np.int64), 1)
    owner = np.repeat(np.arange(len(segments)), steps + 1)
    # position of each point along its segment, 0..1 (the first point of each run at 0)
    first = np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)
    fraction = (np.arange(len(owner)) - first) / steps[owner]
    points = start[owner] + fraction[:, None] * (end - start)[owner]
    direction = (end - start) / np.maximum(length, 1e-12)[:, None]
    return points, direction[owner], owner


def facing_sensor(segments: FloatArray) -> FloatArray:
    """``segments`` (N, 4), in the frame of the sensor that saw them, each turned to run with
    the sensor (the origin) on its left: the face that was seen. (A laser's scan order already
    gives this; fused map segments need not.)"""
    segments = np.array(segments, dtype=np.float64).reshape(-1, 4)
    start, end = segments[:, :2], segments[:, 2:]
    # (end - start) x (origin - start) < 0: the origin lies on the right.
    right = (end[:, 0] - start[:, 0]) * -start[:, 1] - (end[:, 1] - start[:, 1]) * -start[:, 0] < 0
    segments[right] = segments[right][:, [2, 3, 0, 1]]
    return segments


def corner_points(
    segments: FloatArray, points: FloatArray, owner: IntArray, radius: float
) -> NDArray[np.bool_]:
    """Which points lie in a region of interest (FFS 3.4): within ``radius`` of where the
    supporting lines of two segments meet at 80-100 deg, that meeting point being within
    ``radius`` of both segments."""
    segments = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    inside = np.zeros(len(points), dtype=bool)
    if len(segments) < 2 or radius <= 0.0:
        return inside
    start, end = segments[:, :2], segments[:, 2:]
    d = end - start
    length = np.maximum(np.hypot(*d.T), 1e-12)
    u = d / length[:, None]
    i, j = np.triu_indices(len(segments), 1)
    cos = np.abs(np.einsum("ij,ij->i", u[i], u[j]))
    i, j = i[cos <= _CORNER_COS], j[cos <= _CORNER_COS]
    if len(i) == 0:
        return inside
    # The supporting lines' intersection: start_i + s u_i = start_j + t u_j.
    cross = u[i, 0] * u[j, 1] - u[i, 1] * u[j, 0]
    gap = start[j] - start[i]
    s = (gap[:, 0] * u[j, 1] - gap[:, 1] * u[j, 0]) / cross
    t = (gap[:, 0] * u[i, 1] - gap[:, 1] * u[i, 0]) / cross
    near_i = (s >= -radius) & (s <= length[i] + radius)
    near_j = (t >= -radius) & (t <= length[j] + radius)
    corners = (start[i] + s[:, None] * u[i])[near_i & near_j]
    if len(corners) == 0:
        return inside
    gaps = np.hypot(*(points[:, None, :] - corners[None, :, :]).transpose(2, 0, 1))
    return np.asarray((gaps <= radius).any(axis=1))


def make_bodies(
    segment_sets: Sequence[FloatArray], spacing: float, roi_radius: float, roi_mass: float
) -> Bodies:
    """One body per segment set (each in its own frame). Regions of interest are found on
    each body's own segments: a corner seen by one keyframe."""
    points, directions, masses, body = [], [], [], []
    for k, segments in enumerate(segment_sets):
        p, d, owner = resample(segments, spacing)
        mass = np.where(corner_points(segments, p, owner, roi_radius), roi_mass, 1.0)
        points.append(p)
        directions.append(d)
        masses.append(mass)
        body.append(np.full(len(p), k, dtype=np.int64))
    if not points:
        empty = np.zeros((0, 2))
        return Bodies(empty, empty, np.zeros(0), np.zeros(0, dtype=np.int64), 0)
    return Bodies(
        np.vstack(points),
        np.vstack(directions),
        np.concatenate(masses),
        np.concatenate(body),
        len(segment_sets),
    )


def placed(bodies: Bodies, poses: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Every point and direction in ``map`` with each body at ``poses[k]`` (x, y, theta)."""
    pose = np.asarray(poses, dtype=np.float64)[bodies.body]
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    x, y = bodies.points[:, 0], bodies.points[:, 1]
    points = np.column_stack([c * x - s * y + pose[:, 0], s * x + c * y + pose[:, 1]])
    dx, dy = bodies.directions[:, 0], bodies.directions[:, 1]
    return points, np.column_stack([c * dx - s * dy, s * dx + c * dy])
