"""SE(2) helpers shared by every stage.

A pose is an ``(x, y, theta)`` triple; ``T_a_b`` is the 3x3 homogeneous matrix that maps
coordinates expressed in frame ``b`` into frame ``a``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Wrap angles to [-pi, pi)."""
    a = np.asarray(angle, dtype=np.float64)
    return np.asarray((a + np.pi) % (2.0 * np.pi) - np.pi)


def matrix_from_pose(x: float, y: float, theta: float) -> FloatArray:
    """The 3x3 matrix T_a_b of the pose (x, y, theta) of frame b in frame a."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def pose_from_matrix(T: FloatArray) -> tuple[float, float, float]:
    """Inverse of :func:`matrix_from_pose`."""
    return float(T[0, 2]), float(T[1, 2]), float(np.arctan2(T[1, 0], T[0, 0]))


def invert(T: FloatArray) -> FloatArray:
    """T_b_a from T_a_b, without a general matrix inverse."""
    R = T[:2, :2]
    out = np.eye(3)
    out[:2, :2] = R.T
    out[:2, 2] = -R.T @ T[:2, 2]
    return out


def transform_points(T: FloatArray, points: FloatArray) -> FloatArray:
    """Map an (N, 2) array of points from frame b to frame a with T_a_b."""
    return np.asarray(points @ T[:2, :2].T + T[:2, 2])


def transform_segments(T: FloatArray, segments: FloatArray) -> FloatArray:
    """Map an (N, 4) segment set ``[x1, y1, x2, y2]`` from frame b to frame a with T_a_b."""
    ends = transform_points(T, segments.reshape(-1, 2))
    return ends.reshape(-1, 4)
