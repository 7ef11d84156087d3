"""Point-to-line least squares of hypotheses (Cox; Wolter 5.1)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import lines_of
from multi_robot_mapper.core.matching.config import IntegrateConfig
from multi_robot_mapper.core.matching.scoring import score_pairs

FloatArray = NDArray[np.float64]


def refine(
    segments1: FloatArray, segments2: FloatArray, T_1_2: FloatArray, config: IntegrateConfig
) -> FloatArray:
    """Point-to-line least squares (Cox; Wolter 5.1) from ``T_1_2``; see :func:`refine_many`."""
    T = np.asarray(T_1_2, dtype=np.float64).reshape(1, 3)
    return np.asarray(refine_many(segments1, segments2, T, config)[0], dtype=np.float64)


def refine_many(
    segments1: FloatArray, segments2: FloatArray, transforms: FloatArray, config: IntegrateConfig
) -> FloatArray:
    """Point-to-line least squares (Cox; Wolter 5.1) of several hypotheses at once.

    Each iteration pairs the segments that match under the current estimate (the matching
    pairs of Alg. 4 l. 5-19) and pulls the part of each S2 segment that projects onto its S1
    segment onto that segment's line. The squared point-to-line residual and its Jacobian are
    linear along a segment, so two Gauss points per pair integrate the normal equations
    exactly (before weighting); a Cauchy weight (scale ``point_distance_tolerance``) lets the
    nearer of two parallel candidate lines win. A damped Gauss-Newton step solves each 3x3
    system, so the offset along a bare corridor (not observable) stays where it was.
    ``refine_iterations`` 0 returns the hypotheses unchanged.
    """
    T = np.array(transforms, dtype=np.float64).reshape(-1, 3)
    count = len(T)
    if count == 0 or len(segments1) == 0 or len(segments2) == 0 or config.refine_iterations == 0:
        return T
    lines1, lines2 = lines_of(segments1), lines_of(segments2)
    gauss = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])
    active = np.ones(count, dtype=bool)
    for _ in range(config.refine_iterations):
        live = np.flatnonzero(active)
        if live.size == 0:
            break
        scores = score_pairs(segments1, segments2, T[live], config)
        if scores.first.size == 0:
            break
        h, a, b = scores.hypothesis, scores.first, scores.second
        c, s = np.cos(T[live[h], 0]), np.sin(T[live[h], 0])
        tx, ty = T[live[h], 1], T[live[h], 2]
        ux, uy = lines1.direction[a, 0], lines1.direction[a, 1]
        # Where S2's end points fall along S1's line: the part of s2 over s1.
        p1, p2 = segments2[b, :2], segments2[b, 2:]
        t1 = ux * (c * p1[:, 0] - s * p1[:, 1] + tx - segments1[a, 0]) + uy * (
            s * p1[:, 0] + c * p1[:, 1] + ty - segments1[a, 1]
        )
        t2 = ux * (c * p2[:, 0] - s * p2[:, 1] + tx - segments1[a, 0]) + uy * (
            s * p2[:, 0] + c * p2[:, 1] + ty - segments1[a, 1]
        )
        span = np.where(np.abs(t2 - t1) > 1e-9, t2 - t1, 1e-9)
        lo = np.clip(np.minimum(-t1 / span, (lines1.length[a] - t1) / span), 0.0, 1.0)
        hi = np.clip(np.maximum(-t1 / span, (lines1.length[a] - t1) / span), 0.0, 1.0)
        weight = 0.5 * (hi - lo) * lines2.length[b]
        # Two Gauss points per pair on the overlapping part of s2 (in S2's frame).
        lam = lo[:, None] + (hi - lo)[:, None] * gauss[None, :]
        px = (p1[:, 0, None] + lam * (p2[:, 0] - p1[:, 0])[:, None]).ravel()
        py = (p1[:, 1, None] + lam * (p2[:, 1] - p1[:, 1])[:, None]).ravel()
        hh = np.repeat(h, 2)
        aa = np.repeat(a, 2)
        cc, ss = np.repeat(c, 2), np.repeat(s, 2)
        qx = cc * px - ss * py + np.repeat(tx, 2)
        qy = ss * px + cc * py + np.repeat(ty, 2)
        nx, ny = -lines1.direction[aa, 1], lines1.direction[aa, 0]
        r = nx * qx + ny * qy - lines1.normal_offset[aa]
        w = np.repeat(weight, 2) / (1.0 + (r / config.point_distance_tolerance) ** 2)
        # d q / d theta = (-(s px + c py), c px - s py)
        j0 = nx * -(ss * px + cc * py) + ny * (cc * px - ss * py)
        J = (j0, nx, ny)
        H = np.empty((live.size, 3, 3))
        g = np.empty((live.size, 3))
        for i in range(3):
            g[:, i] = np.bincount(hh, weights=w * J[i] * r, minlength=live.size)
            for j in range(i, 3):
                H[:, i, j] = H[:, j, i] = np.bincount(
                    hh, weights=w * J[i] * J[j], minlength=live.size
                )
        # Levenberg damping: a direction no matched line constrains gets no step.
        damping = 1e-6 + 1e-4 * np.trace(H, axis1=1, axis2=2)
        H += damping[:, None, None] * np.eye(3)[None, :, :]
        step = -np.linalg.solve(H, g[:, :, None])[:, :, 0]
        T[live] += step
        small = (np.abs(step[:, 0]) < 1e-5) & (np.hypot(step[:, 1], step[:, 2]) < 1e-4)
        active[live[small]] = False
    T[:, 0] = se2.wrap_angle(T[:, 0])
    return T
