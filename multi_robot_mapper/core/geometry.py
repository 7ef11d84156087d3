"""Small geometric kernels shared by the pipeline stages, the simulator and the evaluator.

Also the two conversions every layer needs: ROS stamps <-> seconds, and yaw <-> the quaternion
of a planar rotation. Pure numpy; the hot-path kernels avoid numpy's Python-level wrappers (see
the cost model in ``extraction``).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_TINY, _ZERO, _ONE = np.array(1e-18), np.array(0.0), np.array(1.0)


@functools.lru_cache(maxsize=8)
def _counting(size: int) -> IntArray:
    """``np.arange(size)``, read-only (memoised: a pure function of ``size``)."""
    counting = np.arange(size, dtype=np.int64)
    counting.flags.writeable = False
    return counting


def arange_view(n: int) -> IntArray:
    """``np.arange(n)`` as a read-only view of a cached array (one per power of two from
    4096 up, so that every call does not allocate)."""
    return _counting(max(4096, 1 << max(n - 1, 0).bit_length()))[:n]


def ranges_index(first: IntArray, stop: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """Concatenated ``arange(first[k], stop[k])`` for all k, the k of each entry, and the offset
    at which each range starts (for ``np.ufunc.reduceat``). No range is empty."""
    length = stop - first
    end = np.add.accumulate(length)  # np.cumsum
    start = end - length
    entries = arange_view(int(end[-1]))
    owner = end.searchsorted(entries, side="right")
    index = (first - start)[owner]
    index += entries
    return index, owner, start


def point_segment_distance(
    px: FloatArray, py: FloatArray, ax: FloatArray, ay: FloatArray, bx: FloatArray, by: FloatArray
) -> FloatArray:
    """Element-wise distance from points (px, py) to segments (ax, ay)-(bx, by).

    Coordinates come as separate arrays (any shapes that broadcast together): on the few
    hundred points of a scan this is several times faster than (K, 2) arrays with einsum.
    """
    arrays = np.broadcast_arrays(px, py, ax, ay, bx, by)
    flat = [np.array(a, dtype=np.float64).ravel() for a in arrays]
    return segment_distance_1d(*flat).reshape(arrays[0].shape)


def segment_distance_1d(
    px: FloatArray, py: FloatArray, ax: FloatArray, ay: FloatArray, bx: FloatArray, by: FloatArray
) -> FloatArray:
    """``point_segment_distance`` of 1-D float arrays of one length, as the front end calls it.

    It works in place on its temporaries: on small arrays allocating them is a good part of
    the cost.
    """
    abx, aby = bx - ax, by - ay
    apx, apy = px - ax, py - ay
    t = apx * abx
    t += apy * aby
    denom = abx * abx
    denom += aby * aby
    t /= np.maximum(denom, _TINY, out=denom)
    np.minimum(np.maximum(t, _ZERO, out=t), _ONE, out=t)  # np.clip(t, 0, 1), cheaper
    abx *= t
    aby *= t
    apx -= abx
    apy -= aby
    dist: FloatArray = np.hypot(apx, apy, out=apx)
    return dist


def split_stamp(seconds: float) -> tuple[int, int]:
    """``(sec, nanosec)`` of a time in seconds, nanoseconds rounded with the carry kept.

    Split before scaling: at ~1e9 s (epoch stamps) ``seconds * 1e9`` would lose the
    sub-microsecond digits that the fraction still has.
    """
    sec = math.floor(seconds)
    nanosec = round((seconds - sec) * 1e9)
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return int(sec), int(nanosec)


def stamp_seconds(sec: int, nanosec: int) -> float:
    """Seconds of a ``(sec, nanosec)`` stamp."""
    return sec + nanosec * 1e-9


def yaw_from_quaternion(x: ArrayLike, y: ArrayLike, z: ArrayLike, w: ArrayLike) -> FloatArray:
    """Rotation about z of quaternions (element-wise; other axes ignored). Quaternions need
    not be unit: each is scaled by its largest component first (the yaw does not change, and
    a sender's 1e300 components do not overflow), and the cosine term is w² + x² - y² - z²,
    which equals 1 - 2(y² + z²) only for unit quaternions."""
    x, y, z, w = (np.asarray(v, dtype=np.float64) for v in (x, y, z, w))
    with np.errstate(invalid="ignore"):  # inf / inf: a NaN yaw, refused by the callers
        scale = np.maximum.reduce([np.abs(x), np.abs(y), np.abs(z), np.abs(w)])
        scale = np.where(scale > 0.0, scale, 1.0)
        x, y, z, w = x / scale, y / scale, z / scale, w / scale
    return np.asarray(np.arctan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z))


def quaternion_from_yaw(yaw: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``(x, y, z, w)`` of rotations by ``yaw`` about z (element-wise)."""
    half = 0.5 * np.asarray(yaw, dtype=np.float64)
    zero = np.zeros_like(half)
    return zero, zero.copy(), np.sin(half), np.cos(half)


__all__ = [
    "arange_view",
    "point_segment_distance",
    "quaternion_from_yaw",
    "ranges_index",
    "segment_distance_1d",
    "split_stamp",
    "stamp_seconds",
    "yaw_from_quaternion",
]


@dataclasses.dataclass(frozen=True)
class Lines:
    """Per-segment geometry used everywhere below."""

    direction: FloatArray  # (N, 2) unit vectors
    angle: FloatArray  # (N,) direction angle in [-pi, pi)
    length: FloatArray  # (N,)
    normal_offset: FloatArray  # (N,) c in n . p = c, with n = (-uy, ux)


def lines_of(segments: FloatArray) -> Lines:
    d = segments[:, 2:] - segments[:, :2]
    length = np.hypot(d[:, 0], d[:, 1])
    direction = d / np.maximum(length, 1e-12)[:, None]
    normal_offset = -direction[:, 1] * segments[:, 0] + direction[:, 0] * segments[:, 1]
    return Lines(direction, np.arctan2(direction[:, 1], direction[:, 0]), length, normal_offset)


def sample_segments(segments: FloatArray, spacing: float) -> tuple[FloatArray, IntArray]:
    """Points every ``spacing`` metres along each segment (ends included) and their segment."""
    length = lines_of(segments).length
    count = np.maximum(2, np.ceil(length / spacing).astype(np.int64) + 1)
    owner = np.repeat(np.arange(len(segments)), count)
    start = np.repeat(np.cumsum(count) - count, count)
    t = (np.arange(owner.size) - start) / (count[owner] - 1)
    pts = segments[owner, :2] + t[:, None] * (segments[owner, 2:] - segments[owner, :2])
    return pts, owner.astype(np.int64)
