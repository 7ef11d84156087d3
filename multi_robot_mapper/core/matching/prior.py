"""A motion prior for tracking: where the robot's recent motion puts a scan, weighed only along
the direction its match cannot observe (issue 47 item 5).

Along a bare corridor the point-to-line residuals do not change when the scan slides along the
walls: the smallest eigenvalue of their normal matrix (the Hessian of the least squares, its
translation block with the rotation eliminated) is near zero, its eigenvector points along the
corridor. The matched walls fix every other direction. A robot's motion between two scans a
tenth of a second apart is known from its motion just before to a few centimetres, so along
that one direction the prediction is the better measurement; along every other the scan is.

The prior enters the least squares as a pseudo-wall: ``support`` metres of wall across the
least constrained direction, the unit of :func:`~core.matching.scoring.information` (each metre
of matched wall is one measurement of its line with standard deviation ``wall_sigma``, so a
prediction with standard deviation ``sigma`` along it is worth ``(wall_sigma / sigma)^2``
metres: :func:`prior_support`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE, SLIDE_SUPPORT

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# The prior is weighed only where the matched walls fix the weakest direction less than this
# (m of wall across it: twice the support at which a slide counts half fixed); where they fix
# it better they decide it, and measure the prediction's error instead (core.local_mapping.
# motion): no placement both uses the prior and measures it.
UNOBSERVED_SUPPORT = 2.0 * SLIDE_SUPPORT
# The prior decides a direction only where the prediction is this sure: three standard
# deviations within the correctness tolerance (a wrong prior then has odds below 0.3 %).
DECISIVE_SIGMA = RIGHT_DISTANCE / 3.0
DECISIVE_ANGLE = RIGHT_ANGLE / 3.0


@dataclasses.dataclass(frozen=True)
class MotionPrior:
    """The predicted placement ``T_1_2`` (theta, tx, ty) of the new scan in the reference's
    frame, what it is worth along the least constrained direction (metres of wall), and the
    standard deviation (m) of a metre of wall's measurement of its line."""

    T_1_2: FloatArray
    support: float
    wall_sigma: float


def prior_support(sigma: float, wall_sigma: float) -> float | None:
    """Metres of wall a prediction with standard deviation ``sigma`` (m, per axis) is worth,
    each metre of wall measuring its line to ``wall_sigma`` (m); None where the prediction is
    not decisive (:data:`DECISIVE_SIGMA`)."""
    if not np.isfinite(sigma) or sigma <= 0.0 or sigma > DECISIVE_SIGMA:
        return None
    return float((wall_sigma / sigma) ** 2)


def weakest_directions(H: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per system (``(T, 3, 3)`` in (theta, tx, ty)): the translation the residuals constrain
    least, with the rotation free (the Schur complement of the rotation), as a unit vector
    ``(T, 2)``, and its eigenvalue ``(T,)`` (the other eigenvalue is the trace less it)."""
    h_tt = H[:, 1:, 1:]
    h_rt = H[:, 0, 1:]
    h_rr = np.maximum(H[:, 0, 0], 1e-12)
    reduced = h_tt - h_rt[:, :, None] * h_rt[:, None, :] / h_rr[:, None, None]
    values, vectors = np.linalg.eigh(0.5 * (reduced + np.swapaxes(reduced, 1, 2)))
    return vectors[:, :, 0], values[:, 0]


def add_prior(
    H: FloatArray, g: FloatArray, transforms: FloatArray, prior: MotionPrior
) -> tuple[FloatArray, FloatArray]:
    """The Gauss-Newton system ``(H, g)`` of each hypothesis with the prior added along its
    least constrained direction ``u``, where it counts (:func:`weighs`): the energy
    ``support / 2 * (u . (t - t_prior))^2`` (``t`` the hypothesis' translation)."""
    u, _ = weakest_directions(H)
    offset = transforms[:, 1:] - np.asarray(prior.T_1_2, dtype=np.float64)[1:][None, :]
    along = np.sum(u * offset, axis=1)
    u = u * weighs(prior, H)[:, None]
    H = H.copy()
    g = g.copy()
    H[:, 1:, 1:] += prior.support * u[:, :, None] * u[:, None, :]
    g[:, 1:] += (prior.support * along)[:, None] * u
    return H, g


def weighs(prior: MotionPrior | None, H: FloatArray | None) -> BoolArray:
    """Does ``prior`` count for each placement whose walls give the Gauss-Newton matrix in
    ``H`` (``(T, 3, 3)`` in (theta, tx, ty), :func:`~core.matching.refine.normal_equations`)?
    Where they leave the weakest direction unobserved (:data:`UNOBSERVED_SUPPORT`) and, with
    the prior along it, decide every other as surely as the prior does its own: the rotation
    within :data:`DECISIVE_ANGLE`, the translation within :data:`DECISIVE_SIGMA` (one
    standard deviation). The prior supplies one direction, never two: a sliver of wall (a
    laser's narrow field of view) fixes its line's offset but hardly its angle."""
    if prior is None or H is None or len(H) == 0:
        return np.zeros(0 if H is None else len(H), dtype=bool)
    u, weakest = weakest_directions(H)
    information = H.copy()
    information[:, 1:, 1:] += prior.support * u[:, :, None] * u[:, None, :]
    # A singular system (no rotation observed at all) is no decision: its determinant is 0.
    determinant = np.linalg.det(information)
    usable = (
        np.abs(determinant) > 1e-12 * np.maximum(np.trace(information, axis1=1, axis2=2), 1.0) ** 3
    )
    covariance = np.zeros_like(information)
    covariance[usable] = np.linalg.inv(information[usable]) * prior.wall_sigma**2
    translation = np.linalg.eigvalsh(covariance[:, 1:, 1:])
    return np.asarray(
        usable
        & (weakest < UNOBSERVED_SUPPORT)
        & (covariance[:, 0, 0] <= DECISIVE_ANGLE**2)
        & (translation[:, 0] >= 0.0)
        & (translation[:, 1] <= DECISIVE_SIGMA**2)
    )


def excluded_by(prior: MotionPrior, transforms: FloatArray, slide: FloatArray) -> BoolArray:
    """Which of ``transforms`` (theta, tx, ty) the prior rules out: farther from its
    prediction than the correctness tolerance along ``slide`` (the least constrained
    direction, a unit vector), where the prediction is within a third of it."""
    offset = np.asarray(transforms, dtype=np.float64).reshape(-1, 3)[:, 1:] - prior.T_1_2[1:]
    return np.asarray(np.abs(offset @ np.asarray(slide, dtype=np.float64)) >= RIGHT_DISTANCE)


def support_with_prior(support: float, total: float, prior: MotionPrior | None) -> float:
    """The smallest eigenvalue of the matched walls' normal matrix (``support``, with
    ``total`` its trace) once the prior is added along its eigenvector (where the walls leave
    it unobserved: :data:`UNOBSERVED_SUPPORT`)."""
    if prior is None or support >= UNOBSERVED_SUPPORT:
        return support
    return float(min(support + prior.support, max(total - support, support)))
