"""SE(2) helpers shared by every stage.

A pose is an ``(x, y, theta)`` triple; ``T_a_b`` is the 3x3 homogeneous matrix that maps
coordinates expressed in frame ``b`` into frame ``a``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# The one pose type of the package: ``(x, y, theta)`` in metres, metres, radians. ``T_a_b``
# written as a triple is frame b's origin and heading in frame a (the pose whose
# :func:`matrix_from_pose` is the matrix ``T_a_b``). The matchers' hypothesis rows
# ``(theta, tx, ty)`` are a different layout and stay arrays, never a ``Pose``.
Pose = tuple[float, float, float]


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Wrap angles to [-pi, pi)."""
    a = np.asarray(angle, dtype=np.float64)
    return np.asarray((a + np.pi) % (2.0 * np.pi) - np.pi)


def matrix_from_pose(x: float, y: float, theta: float) -> FloatArray:
    """The 3x3 matrix T_a_b of the pose (x, y, theta) of frame b in frame a."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def matrices_from_poses(poses: ArrayLike) -> FloatArray:
    """``(n, 3, 3)`` matrices of ``(n, 3)`` poses ``(x, y, theta)`` (all at once)."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    out = np.zeros((len(p), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = c, -s, p[:, 0]
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = s, c, p[:, 1]
    out[:, 2, 2] = 1.0
    return out


def pose_from_matrix(T: FloatArray) -> Pose:
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


def transform_segments_each(poses: FloatArray, segments: FloatArray) -> FloatArray:
    """Row i of ``segments`` (M, 4) moved by pose i of ``poses`` (M, 3): each segment from its
    own frame b_i into frame a, with ``T_a_bi`` given as ``(x, y, theta)``."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    out = np.empty_like(segments)
    for k in (0, 2):
        x, y = segments[:, k], segments[:, k + 1]
        out[:, k] = c * x - s * y + poses[:, 0]
        out[:, k + 1] = s * x + c * y + poses[:, 1]
    return out


def inverse_transform_segments_each(poses: FloatArray, segments: FloatArray) -> FloatArray:
    """Inverse of :func:`transform_segments_each`: row i from frame a into frame b_i."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    out = np.empty_like(segments)
    for k in (0, 2):
        x, y = segments[:, k] - poses[:, 0], segments[:, k + 1] - poses[:, 1]
        out[:, k] = c * x + s * y
        out[:, k + 1] = -s * x + c * y
    return out


def compose(T_a_b: ArrayLike, T_b_c: ArrayLike) -> Pose:
    """``T_a_c`` of two ``(x, y, theta)`` poses."""
    ab, bc = np.asarray(T_a_b, dtype=np.float64), np.asarray(T_b_c, dtype=np.float64)
    return pose_from_matrix(matrix_from_pose(*ab) @ matrix_from_pose(*bc))


def between(T_a_b: ArrayLike, T_a_c: ArrayLike) -> Pose:
    """``T_b_c`` of two ``(x, y, theta)`` poses in the same frame a."""
    ab, ac = np.asarray(T_a_b, dtype=np.float64), np.asarray(T_a_c, dtype=np.float64)
    return pose_from_matrix(invert(matrix_from_pose(*ab)) @ matrix_from_pose(*ac))


def between_each(T_a_b: ArrayLike, T_a_c: ArrayLike) -> FloatArray:
    """``(N, 3)`` rows ``T_b_c`` of ``(N, 3)`` pose pairs in the same frame a (:func:`between`
    row by row, at once)."""
    ab, ac = np.asarray(T_a_b, dtype=np.float64), np.asarray(T_a_c, dtype=np.float64)
    c, s = np.cos(ab[:, 2]), np.sin(ab[:, 2])
    dx, dy = ac[:, 0] - ab[:, 0], ac[:, 1] - ab[:, 1]
    theta = wrap_angle(ac[:, 2] - ab[:, 2])
    return np.column_stack((c * dx + s * dy, -s * dx + c * dy, theta))


def compose_each(T_a_b: ArrayLike, T_b_c: ArrayLike) -> FloatArray:
    """``(N, 3)`` rows ``T_a_c`` of ``(N, 3)`` pose pairs (:func:`compose` row by row, at
    once)."""
    ab, bc = np.asarray(T_a_b, dtype=np.float64), np.asarray(T_b_c, dtype=np.float64)
    c, s = np.cos(ab[:, 2]), np.sin(ab[:, 2])
    return np.column_stack(
        (
            ab[:, 0] + c * bc[:, 0] - s * bc[:, 1],
            ab[:, 1] + s * bc[:, 0] + c * bc[:, 1],
            wrap_angle(ab[:, 2] + bc[:, 2]),
        )
    )


def rigid_fit(poses_from: FloatArray, poses_to: FloatArray) -> FloatArray:
    """``T_to_from`` (3x3): the rigid motion that best carries ``(K, 3)`` poses given in frame
    ``from`` onto the same poses given in frame ``to`` (least squares on their positions,
    2-D Kabsch); with one pose, exactly onto it."""
    a = np.asarray(poses_from, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(poses_to, dtype=np.float64).reshape(-1, 3)
    if len(a) == 1 or np.ptp(a[:, :2], axis=0).max() < 1e-9:
        return np.asarray(matrix_from_pose(*b[0]) @ invert(matrix_from_pose(*a[0])))
    return fit_points(a[:, :2], b[:, :2])


def fit_points(points_from: FloatArray, points_to: FloatArray) -> FloatArray:
    """``T_to_from`` (3x3): the rigid motion that best carries ``(K, 2)`` points onto their
    partners (least squares, 2-D Kabsch; K >= 2 distinct points)."""
    a = np.asarray(points_from, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(points_to, dtype=np.float64).reshape(-1, 2)
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    da, db = a - ca, b - cb
    theta = float(np.arctan2(np.sum(da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]), np.sum(da * db)))
    c, s = np.cos(theta), np.sin(theta)
    t = cb - np.array([[c, -s], [s, c]]) @ ca
    return matrix_from_pose(float(t[0]), float(t[1]), theta)
