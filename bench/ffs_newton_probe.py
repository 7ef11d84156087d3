"""A probe for issue 51, not the method in ``core/merging/ffs``: the re-convergence experiment of
``bench/ffs_bench.py`` (FFS Sec. 4.2) with every body moved at once by a joint Newton step on
the paper's potential, to tell apart what the optimiser misses from what the field itself allows.

    .venv/bin/python -m bench.ffs_newton_probe [--log intel] [--seeds 3] [--distortion 0.02,1]
        [--start-sigma 0] [--steps 44] [--iterations 150] [--body-length 0]

The potential is the paper's (Eq. 2-5): ``P = -sum m_p m_q max(cos, 0) exp(-|p - q|^2 / 2 sigma^2)``
over point pairs of different bodies, cut at 4 sigma, segments resampled every 0.05 m (at most
1.25 sigma: at the paper's 10 cm and sigma = 4 cm a resampled wall is a row of bumps, a ripple of
exp(-2 pi^2 sigma^2 / h^2), about 4 %, that holds bodies along walls at the spacing). Its gradient
and Hessian in the 3n pose parameters (the Hessian clipped to be positive semi-definite per pair)
are summed per pair of bodies; the step solves the 3n x 3n system (Levenberg-Marquardt, a step kept
only where P falls) until no body moves more than 0.02 mm. ``--start-sigma S`` first cools sigma
linearly from S to 0.04 m in ``--steps`` iterations, one damped Newton step each, no body moving
more than sigma / 2 per iteration (at its RMS radius). R0 is the same optimiser from the reference
poses at sigma = 0.04 m; the first body holds the frame. ``--body-length M`` groups consecutive
keyframes into bodies of M metres of wall, as ``ffs_bench --grouped``. Prints Markdown, one row
per seed.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from bench.ffs_bench import keyframe_scans  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.merging.ffs import Bodies, make_bodies  # noqa: E402
from multi_robot_mapper.core.merging.ffs.bodies import placed  # noqa: E402
from multi_robot_mapper.core.merging.ffs.method import body_chunks, body_segments  # noqa: E402

FloatArray = NDArray[np.float64]
SIGMA_END = 0.04
SPACINGS = (0.05, 0.1, 0.2, 0.4, 0.8)


def system(
    bodies: Bodies, poses: FloatArray, sigma: float, cutoff: float
) -> tuple[float, FloatArray, FloatArray]:
    """P, its gradient (K, 3) and Hessian (3K, 3K) in every body's (x, y, theta), theta about
    the body's origin."""
    count = len(poses)
    points, directions = placed(bodies, poses)
    pairs = cKDTree(points).query_pairs(cutoff * sigma, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    cos = np.einsum("ij,ij->i", directions[i], directions[j])
    keep = (bodies.body[i] != bodies.body[j]) & (cos > 0.0)
    i, j, cos = i[keep], j[keep], cos[keep]
    a, b = bodies.body[i], bodies.body[j]
    r = points[i] - points[j]
    d2 = np.einsum("ij,ij->i", r, r)
    c = bodies.masses[i] * bodies.masses[j] * cos * np.exp(-d2 / (2.0 * sigma**2))
    w = c / sigma**2
    # d/d(x, y, theta) of a point: [I, perp(p - origin)], perp(v) = (-v_y, v_x).
    arm_a = points[i] - poses[a, :2]
    arm_b = points[j] - poses[b, :2]
    perp_a = np.column_stack([-arm_a[:, 1], arm_a[:, 0]])
    perp_b = np.column_stack([-arm_b[:, 1], arm_b[:, 0]])
    pull = w[:, None] * r  # dP/dr, r = p_i - p_j
    gradient = np.zeros((count, 3))
    for owner, perp, sign in ((a, perp_a, 1.0), (b, perp_b, -1.0)):
        gradient[:, 0] += sign * np.bincount(owner, pull[:, 0], count)
        gradient[:, 1] += sign * np.bincount(owner, pull[:, 1], count)
        gradient[:, 2] += sign * np.bincount(owner, np.einsum("ij,ij->i", perp, pull), count)
    # d2P/dr2 = w (I - r r^T / sigma^2), its radial eigenvalue clipped at 0.
    unit = r / np.sqrt(np.maximum(d2, 1e-30))[:, None]
    bend = np.maximum(1.0 - d2 / sigma**2, 0.0) - 1.0
    curvature = (
        w * (1.0 + bend * unit[:, 0] ** 2),
        w * bend * unit[:, 0] * unit[:, 1],
        w * (1.0 + bend * unit[:, 1] ** 2),
    )
    hessian = _hessian(curvature, a, b, perp_a, perp_b, count)
    return -float(c.sum()), gradient, hessian


def _hessian(
    curvature: tuple[FloatArray, FloatArray, FloatArray],
    a: NDArray[np.int64],
    b: NDArray[np.int64],
    perp_a: FloatArray,
    perp_b: FloatArray,
    count: int,
) -> FloatArray:
    """Sum over pairs of J_1^T M J_2 into the (3K, 3K) Hessian, one bincount per entry and
    kind of block (a-a, b-b, a-b, b-a)."""
    xx, xy, yy = curvature
    blocks = np.zeros((count, count, 9))
    for first, second, p1, p2, sign in (
        (a, a, perp_a, perp_a, 1.0),
        (b, b, perp_b, perp_b, 1.0),
        (a, b, perp_a, perp_b, -1.0),
        (b, a, perp_b, perp_a, -1.0),
    ):
        m2 = (xx * p2[:, 0] + xy * p2[:, 1], xy * p2[:, 0] + yy * p2[:, 1])
        m1 = (xx * p1[:, 0] + xy * p1[:, 1], xy * p1[:, 0] + yy * p1[:, 1])
        entries = (xx, xy, m2[0], xy, yy, m2[1], m1[0], m1[1], p1[:, 0] * m2[0] + p1[:, 1] * m2[1])
        key = first * count + second
        for e, value in enumerate(entries):
            blocks[:, :, e] += sign * np.bincount(key, value, count * count).reshape(count, count)
    return blocks.reshape(count, count, 3, 3).transpose(0, 2, 1, 3).reshape(3 * count, 3 * count)


def reduced(
    bodies: Bodies, poses: FloatArray, free: NDArray[np.bool_], sigma: float
) -> tuple[float, FloatArray, FloatArray]:
    """P, gradient and Hessian in the free bodies' parameters."""
    potential, gradient, hessian = system(bodies, poses, sigma, 4.0)
    index = np.flatnonzero(np.repeat(free, 3))
    return potential, gradient.reshape(-1)[index], hessian[np.ix_(index, index)]


def solved(
    poses: FloatArray,
    free: NDArray[np.bool_],
    gradient: FloatArray,
    hessian: FloatArray,
    damping: float,
) -> FloatArray:
    """The damped Newton step (K, 3) of the free bodies (Levenberg-Marquardt)."""
    diagonal = np.diag(hessian) + 1e-9 * (np.diag(hessian).mean() + 1e-12)
    step = np.zeros_like(poses)
    step[free] = -np.linalg.solve(hessian + damping * np.diag(diagonal), gradient).reshape(-1, 3)
    return step


def settle(
    bodies: Bodies, poses: FloatArray, free: NDArray[np.bool_], radius: FloatArray, iterations: int
) -> tuple[FloatArray, float, int]:
    """Levenberg-Marquardt at sigma_end, a step kept where P falls, until no body moves 0.02 mm:
    poses, P, iterations."""
    damping = 1e-3
    potential, gradient, hessian = reduced(bodies, poses, free, SIGMA_END)
    for iteration in range(1, iterations + 1):
        step = solved(poses, free, gradient, hessian, damping)
        moved = float((np.hypot(step[:, 0], step[:, 1]) + np.abs(step[:, 2]) * radius).max())
        trial = reduced(bodies, poses + step, free, SIGMA_END)
        if trial[0] <= potential:
            poses = poses + step
            potential, gradient, hessian = trial
            damping = max(damping / 4.0, 1e-9)
        else:
            damping *= 5.0
        if moved < 2e-5:
            return poses, potential, iteration
    return poses, potential, iterations


def cool(
    levels: dict[float, Bodies],
    poses: FloatArray,
    free: NDArray[np.bool_],
    radius: FloatArray,
    start_sigma: float,
    steps: int,
) -> FloatArray:
    """sigma from ``start_sigma`` down to sigma_end (linear, FFS 3.2), one damped Newton step per
    iteration, no body moving more than sigma / 2 at its RMS radius."""
    poses = poses.copy()
    for sigma in np.linspace(start_sigma, SIGMA_END, steps + 1)[:-1]:
        spacing = max(s for s in SPACINGS if s <= max(SPACINGS[0], 1.25 * sigma))
        _, gradient, hessian = reduced(levels[spacing], poses, free, float(sigma))
        step = solved(poses, free, gradient, hessian, 1e-2)
        moved = np.hypot(step[:, 0], step[:, 1]) + np.abs(step[:, 2]) * radius
        poses += step * np.minimum(1.0, 0.5 * sigma / np.maximum(moved, 1e-12))[:, None]
    return poses


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--log", default="intel")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--distortion", default="0.02,1", help="METRES,DEGREES (uniform +-)")
    parser.add_argument("--start-sigma", type=float, default=0.0, help="m; 0: settle only")
    parser.add_argument("--steps", type=int, default=44)
    parser.add_argument("--iterations", type=int, default=150)
    parser.add_argument("--body-length", type=float, default=0.0, help="m of wall per body")
    args = parser.parse_args()
    shift, turn = (float(v) for v in args.distortion.split(","))
    sets, reference, _ = keyframe_scans(args.log, 60)
    if args.body_length > 0.0:  # consecutive keyframes grouped as ffs_bench --grouped does
        views = {args.log: [(k, reference[k], segments) for k, segments in enumerate(sets)]}
        chunks = body_chunks(views, [(args.log, k) for k in range(len(sets))], args.body_length)
        reference, sets = body_segments(chunks, reference, sets)
    levels = {s: make_bodies(sets, s, 0.05, 3.0) for s in SPACINGS}
    fine = levels[SPACINGS[0]]
    count = len(sets)
    radius = np.sqrt(
        np.bincount(fine.body, np.sum(fine.points**2, axis=1), count)
        / np.maximum(np.bincount(fine.body, minlength=count), 1)
    )
    free = np.ones(count, dtype=bool)
    free[0] = False
    r0, r0_potential, r0_iterations = settle(fine, reference, free, radius, args.iterations)
    gaps = np.hypot(*(r0[:, :2] - reference[:, :2]).T)
    print(
        f"{args.log}: {count} bodies, {len(fine.points)} points at {SPACINGS[0]} m; R0 after "
        f"{r0_iterations} iterations, P {r0_potential:.1f}, max {gaps.max() * 100:.1f} cm from "
        f"the reference poses; distortion +-{shift} m, +-{turn} deg; start sigma "
        f"{args.start_sigma} m\n\n| seed | max deviation (cm) | max deviation (deg) | median "
        "deviation (cm) | bodies back within 1 cm, 0.5 deg | P (R0's: above) | settle "
        "iterations | s |\n| --- | --- | --- | --- | --- | --- | --- | --- |"
    )
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        start = r0.copy()
        noise = np.column_stack(
            [rng.uniform(-shift, shift, (count, 2)), rng.uniform(-1, 1, count) * np.radians(turn)]
        )
        start[free] += noise[free]
        started = time.perf_counter()
        if args.start_sigma > SIGMA_END:
            start = cool(levels, start, free, radius, args.start_sigma, args.steps)
        poses, potential, iterations = settle(fine, start, free, radius, args.iterations)
        gaps = np.hypot(*(poses[:, :2] - r0[:, :2]).T)
        turns = np.degrees(np.abs(se2.wrap_angle(poses[:, 2] - r0[:, 2])))
        print(
            f"| {seed} | {gaps.max() * 100:.2f} | {turns.max():.3f} | "
            f"{np.median(gaps[free]) * 100:.2f} | {int(np.sum((gaps <= 0.01) & (turns <= 0.5)))}"
            f"/{count} | {potential:.1f} | {iterations} | {time.perf_counter() - started:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
