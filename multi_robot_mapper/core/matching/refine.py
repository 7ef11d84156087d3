"""Point-to-line least squares of hypotheses (Cox; Wolter 5.1)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.prior import MotionPrior, add_prior, weighs
from multi_robot_mapper.core.matching.scoring import (
    PairGeometry,
    PairTolerance,
    geometry_scores,
    pair_geometry,
)
from multi_robot_mapper.core.segment_map import MapLike

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def refine(
    map1: MapLike, map2: MapLike, T_1_2: FloatArray, pairs: PairTolerance, iterations: int
) -> FloatArray:
    """Point-to-line least squares (Cox; Wolter 5.1) from ``T_1_2``; see :func:`refine_many`."""
    T = np.asarray(T_1_2, dtype=np.float64).reshape(1, 3)
    return np.asarray(refine_many(map1, map2, T, pairs, iterations)[0], dtype=np.float64)


def refine_many(
    map1: MapLike,
    map2: MapLike,
    transforms: FloatArray,
    pairs: PairTolerance,
    iterations: int,
    prior: MotionPrior | None = None,
) -> FloatArray:
    """Point-to-line least squares (Cox; Wolter 5.1) of several hypotheses at once.

    Each iteration pairs the segments that match under the current estimate (the matching
    pairs of Alg. 4 l. 5-19) and pulls the part of each S2 segment that projects onto its S1
    segment onto that segment's line. The squared point-to-line residual and its Jacobian are
    linear along a segment, so two Gauss points per pair integrate the normal equations
    exactly (before weighting); a Cauchy weight (scale ``pairs.point_tolerance``) lets the
    nearer of two parallel candidate lines win. A damped Gauss-Newton step solves each 3x3
    system, so the offset along a bare corridor (not observable) stays where it was; with a
    motion ``prior`` it goes where the prior puts it (:func:`~core.matching.prior.add_prior`:
    along the least constrained direction only). At most ``iterations`` steps; 0 returns the
    hypotheses unchanged (INTEGRATE's ``refine_iterations``).
    """
    T = np.array(transforms, dtype=np.float64).reshape(-1, 3)
    count = len(T)
    if count == 0 or len(map1) == 0 or len(map2) == 0 or iterations == 0:
        return T
    geometry = pair_geometry(map1, map2)
    active = np.ones(count, dtype=bool)
    for _ in range(iterations):
        live = np.flatnonzero(active)
        if live.size == 0:
            break
        system = _normal_equations(geometry, T[live], *pairs)
        if system is None:
            break
        H, g = system if prior is None else add_prior(*system, T[live], prior)
        # Levenberg damping: a direction no matched line constrains gets no step.
        damping = 1e-6 + 1e-4 * np.trace(H, axis1=1, axis2=2)
        H += damping[:, None, None] * np.eye(3)[None, :, :]
        step = -np.linalg.solve(H, g[:, :, None])[:, :, 0]
        T[live] += step
        small = (np.abs(step[:, 0]) < 1e-5) & (np.hypot(step[:, 1], step[:, 2]) < 1e-4)
        active[live[small]] = False
    T[:, 0] = se2.wrap_angle(T[:, 0])
    return T


def prior_weighs(
    map1: MapLike,
    map2: MapLike,
    transforms: FloatArray,
    pairs: PairTolerance,
    prior: MotionPrior | None,
) -> BoolArray:
    """Where ``prior`` counts for each of ``transforms`` (:func:`~core.matching.prior.
    weighs`, on the walls' Gauss-Newton matrix there)."""
    system = None if prior is None else normal_equations(map1, map2, transforms, pairs)
    if system is None:
        return np.zeros(len(transforms), dtype=bool)
    return weighs(prior, system[0])


_GAUSS = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])


def normal_equations(
    map1: MapLike, map2: MapLike, transforms: FloatArray, pairs: PairTolerance
) -> tuple[FloatArray, FloatArray] | None:
    """``(H, g)``: the Gauss-Newton system ``sum w J J^T``, ``sum w J r`` of each hypothesis
    (``(T, 3, 3)`` and ``(T, 3)``, in (theta, tx, ty)), None when no segment pair matches.

    The pairs that match under each hypothesis (Alg. 4 l. 5-19) pull the part of each S2
    segment that projects onto its S1 segment onto that segment's line. The squared
    point-to-line residual and its Jacobian are linear along a segment, so two Gauss points
    per pair integrate the normal equations exactly (before weighting): ``w`` is metres of
    overlapping segment, times a Cauchy weight (scale ``point_distance_tolerance``).
    """
    return _normal_equations(pair_geometry(map1, map2), transforms, *pairs)


def _normal_equations(
    geometry: PairGeometry,
    transforms: FloatArray,
    max_angle: float,
    match_distance: float,
    tolerance: float,
) -> tuple[FloatArray, FloatArray] | None:
    count = len(transforms)
    scores = geometry_scores(geometry, transforms, max_angle, match_distance, tolerance)
    if scores.first.size == 0:
        return None
    lines1, lines2 = geometry.lines1, geometry.lines2
    h, a, b = scores.hypothesis, scores.first, scores.second
    c, s = np.cos(transforms[h, 0]), np.sin(transforms[h, 0])
    tx, ty = transforms[h, 1], transforms[h, 2]
    ux, uy = (column[a] for column in geometry.first_direction)
    e1x, e1y = geometry.first_columns[0][a], geometry.first_columns[1][a]
    # Where S2's end points fall along S1's line: the part of s2 over s1.
    p1x, p1y, p2x, p2y = (column[b] for column in geometry.second_columns)
    t1 = ux * (c * p1x - s * p1y + tx - e1x) + uy * (s * p1x + c * p1y + ty - e1y)
    t2 = ux * (c * p2x - s * p2y + tx - e1x) + uy * (s * p2x + c * p2y + ty - e1y)
    span = np.where(np.abs(t2 - t1) > 1e-9, t2 - t1, 1e-9)
    lo = np.clip(np.minimum(-t1 / span, (lines1.length[a] - t1) / span), 0.0, 1.0)
    hi = np.clip(np.maximum(-t1 / span, (lines1.length[a] - t1) / span), 0.0, 1.0)
    weight = 0.5 * (hi - lo) * lines2.length[b]
    # Two Gauss points per pair on the overlapping part of s2 (in S2's frame).
    lam = lo[:, None] + (hi - lo)[:, None] * _GAUSS[None, :]
    px = (p1x[:, None] + lam * (p2x - p1x)[:, None]).ravel()
    py = (p1y[:, None] + lam * (p2y - p1y)[:, None]).ravel()
    hh = np.repeat(h, 2)
    cc, ss = np.repeat(c, 2), np.repeat(s, 2)
    qx = cc * px - ss * py + np.repeat(tx, 2)
    qy = ss * px + cc * py + np.repeat(ty, 2)
    nx, ny = -np.repeat(uy, 2), np.repeat(ux, 2)
    r = nx * qx + ny * qy - np.repeat(lines1.normal_offset[a], 2)
    w = np.repeat(weight, 2) / (1.0 + (r / tolerance) ** 2)
    # d q / d theta = (-(s px + c py), c px - s py)
    j0 = nx * -(ss * px + cc * py) + ny * (cc * px - ss * py)
    J = (j0, nx, ny)
    H = np.empty((count, 3, 3))
    g = np.empty((count, 3))
    for i in range(3):
        g[:, i] = np.bincount(hh, weights=w * J[i] * r, minlength=count)
        for j in range(i, 3):
            H[:, i, j] = H[:, j, i] = np.bincount(hh, weights=w * J[i] * J[j], minlength=count)
    return H, g


def match_information(
    map1: MapLike,
    map2: MapLike,
    T_1_2: FloatArray,
    pairs: PairTolerance,
    wall_sigma: float,
    sigma_floor: tuple[float, float],
    sigma_ceiling: tuple[float, float],
) -> FloatArray:
    """Information (3x3) of the placement ``T_1_2`` (theta, tx, ty) of S2 in S1, in the
    tangent space gtsam's Pose2 uses for a between measurement: ``(x, y, theta)``, the
    perturbation applied in S2's frame (``T_1_2 * Exp(xi)``).

    Each metre of matched wall is taken as one measurement of its line with standard
    deviation ``wall_sigma`` (m): ``H / wall_sigma^2`` with ``H`` the normal matrix of the
    point-to-line least squares (:func:`normal_equations`). The covariance is then held
    between ``sigma_floor`` and ``sigma_ceiling`` (metres, radians): no match is trusted to
    better than the floor (scan matching errors are not independent from one scan to the
    next), and a direction no wall constrains (along a bare corridor) keeps the ceiling.
    """
    T = np.asarray(T_1_2, dtype=np.float64).reshape(1, 3)
    system = normal_equations(map1, map2, T, pairs)
    H_thetat = np.zeros((3, 3)) if system is None else system[0][0]
    theta = float(T[0, 0])
    c, s = np.cos(theta), np.sin(theta)
    # d(theta, tx, ty) = A d(vx, vy, omega): the translation moves in S2's frame (R v).
    A = np.array([[0.0, 0.0, 1.0], [c, -s, 0.0], [s, c, 0.0]])
    information = A.T @ H_thetat @ A / wall_sigma**2
    scale = np.array([sigma_floor[0], sigma_floor[0], sigma_floor[1]])
    # Clip the eigenvalues of the information, in units where both bounds are isotropic.
    unit = information * np.outer(scale, scale)
    values, vectors = np.linalg.eigh(0.5 * (unit + unit.T))
    ratio = np.array([sigma_floor[0] / sigma_ceiling[0]] * 2 + [sigma_floor[1] / sigma_ceiling[1]])
    lowest = float(np.min(ratio)) ** 2
    values = np.clip(values, lowest, 1.0)
    clipped = (vectors * values) @ vectors.T
    return np.asarray(clipped / np.outer(scale, scale))
