"""The global map: placed maps fused (Amigoni Alg. 5)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.merging.config import MergeConfig

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def fuse_maps(
    segments1: FloatArray,
    owner1: IntArray,
    segments2: FloatArray,
    owner2: IntArray,
    config: MergeConfig,
) -> tuple[FloatArray, IntArray]:
    """S1 fused with S2 (already in S1's frame), Amigoni Alg. 5 (core.fusion)."""
    if len(segments1) == 0 or len(segments2) == 0:
        return (
            np.vstack((segments1.reshape(-1, 4), segments2.reshape(-1, 4))),
            np.concatenate((owner1, owner2)).astype(np.int64),
        )
    return fuse(segments1, owner1, segments2, owner2, config.integrate, config.fusion_tolerance)


def as_map(segments: FloatArray) -> FloatArray:
    array = np.asarray(segments, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 4:
        if array.size == 0:
            return np.zeros((0, 4))
        raise ValueError(f"a partial map must be an (N, 4) segment array, got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("a partial map holds NaN or infinite coordinates")
    return array
