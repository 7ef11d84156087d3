"""Force Field Simulation from afar (issue 51): every body brought back from a start as far off
as the paper's experiment 4.2 (±0.30 m, ±20°), with a field as wide as that distortion cooled
to the paper's width.

:func:`run_ffs_far` is Algorithm 1 with three changes, each for a reason measured on the shared
logs' keyframes (docs/decisions.md, "FFS from afar"):

- **The field of a wall, not of its points.** A point p of one body is pulled by each other
  body b once, towards b's wall nearest to p (the soft nearest of b's points within
  ``cutoff``·σ, Sec. 3.5.1's neighbourhood found by a KD-tree), with the strength of Eq. 2
  integrated along that wall (Eq. 4's ∫ dz): ``w = m_p cos∠(d_p, d_q) exp(-r²/2σ²)``, r the
  distance from p to the wall's line. Summed over every point of b (Eq. 3) a metre-wide field
  pulls a body towards the middle of all walls in reach and the map contracts; one wall per
  body and point does not (an EM / ICP reading of the same potential).
- **One step for all bodies at once.** Eq. 6-9's step ½·a·Δt² (force over mass, torque over
  moment of inertia, each body on its own) leaves a chain of keyframes bent along its
  corridor, where the field barely resists; here the step is the one that minimises the
  potential's quadratic model over all bodies' poses together (Gauss-Newton on the weighted
  point-to-wall distances, frozen weights: the iteratively reweighted form of Eq. 4), the
  fixed bodies held. It is bounded per body (below) as Δt bounds the paper's. While σ is
  wider than _JOINT_WIDTH (0.2 m) each body takes its own Newton step instead, the others
  held: a wide field matches a few walls at the wrong place, and a joint step slides whole
  runs of keyframes along their corridor by those few pulls (issue 51, docs/decisions.md).
- **Bounded steps.** A body moves at most σ per iteration and turns at most σ / its radius
  of gyration: rotation from far-away points cannot throw a body further than the field's
  width (the issue's "rotation must not dominate").

Cooling (Sec. 3.2, Algorithm 1 line 14): σ shrinks geometrically from ``sigma_start`` to
``sigma_end`` by ``dt_factor`` per iteration (the paper's Δt factor 0.96: its σ 15 → 4 cm and
Δt 5 → 1 both take about 40 iterations; a metre to 4 cm by 0.96 takes 79); the step's share
(Δt / Δt_0)², Δt cooled by the same factor, never below _FINAL_STEP_SHARE. While σ is wide the
bodies are resampled coarser (one mass-weighted point per cell of at most σ, Sec. 3.3's
optional resampling and 3.5.1's approximation) and at most _PULLED points are pulled per
iteration, fewer where bodies overlap so that about _PAIRS point pairs are examined (the
budget follows the last iteration's count), so that a wide field stays fast. The run ends
(line 15, read with ``<``) once σ has cooled and the largest relocation of a moving body is
below ``stop_relocation`` (the largest, not the average: a chain's end still creeping while the
rest stands still is not settled), and so is its net relocation over the last _SETTLE
iterations (a body creeping by less than that per iteration is not settled either).

Uses :class:`FfsConfig`'s ``sigma_start``, ``sigma_end``, ``dt_factor``, ``cutoff``,
``stop_relocation``, ``max_iterations``, ``time_budget``; ``sigma_start`` is the caller's: the
scale of the start's misalignment (the merger's refinement starts within centimetres and runs
:func:`~multi_robot_mapper.core.merging.ffs.simulation.run_ffs` instead)."""

from __future__ import annotations

import dataclasses
import time
from collections import deque

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.ffs.bodies import Bodies, placed
from multi_robot_mapper.core.merging.ffs.config import FfsConfig
from multi_robot_mapper.core.merging.ffs.simulation import FfsResult

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

# Coarser point sets while σ is wide: cells of at most σ / _CELLS_PER_SIGMA (a Gaussian sum over
# points σ apart along a wall ripples by about 1e-8 of its mean; measured on intel's 60
# keyframes, cells of σ/2 brought back the same seeds as cells of σ at twice the time).
_CELLS_PER_SIGMA = 1.0
# Direction octants a cell's points are kept apart by (faces of a corner stay two points).
_OCTANTS = 8
# At most this many points are pulled per iteration, every k-th of the stacked bodies' points
# (Sec. 3.5.1: the field need only be evaluated to a certain accuracy): where dozens of
# keyframes see one room a point has a pull from each, and all of them would be 5-20 times
# the 20 ms an iteration may take.
_PULLED = 1000
# Point pairs examined per iteration at most (about): where dozens of keyframes overlap
# (freiburg-079: 225 000 pairs for 1 000 points at the widest σ) fewer points are pulled.
_PAIRS = 60000
# Levenberg damping, relative to each pose parameter's own curvature: small enough that a
# chain's soft modes (a corridor's length) converge in a few steps. It does not hold a body
# whose walls all run one way (aces's corridors slid metres: docs/decisions.md).
_DAMPING = 1e-4
# The step is joint (Gauss-Newton over all bodies' poses) once σ is at most this (m); wider,
# each body takes its own Newton step, the others held. A wide field's few pulls across a
# corridor's length come from walls matched at the wrong place (aces at the reference poses:
# the pulls holding keyframes 28-59 along their corridor sit 0.46 m off on average, points
# pulled to another keyframe's wall end 1 m along the wall), and the joint step moves the whole
# run by their mean, σ per iteration, 3 m in 15 iterations; each body alone feels its own
# pulls, which cancel inside the run. Below it the joint step brings back what bodies alone do
# not (a run of 30 keyframes of intel left 15-19 cm off with the hand-over at 0.08 m).
# Screened on intel and aces at 0.08, 0.2 and 0.3 m (docs/decisions.md, issue 51).
_JOINT_WIDTH = 0.2
# The step's share of the model's at the end of the cooling: the whole step cycles by about
# half a millimetre at the end (the synthetic building of the tests), half of it settles.
_FINAL_STEP_SHARE = 0.5
# The run stops only once every moving body's net relocation over this many iterations is below
# ``stop_relocation`` too (Algorithm 1 line 15): the step cycles by about half a millimetre at
# the end (_FINAL_STEP_SHARE), so a body creeping along a corridor's soft mode at less than that
# per iteration passed the per-iteration rule short of the minimum (fhw: seeds stopped with one
# keyframe 1.2-1.3 cm off R0, and R0 itself short of its own; issue 51, docs/decisions.md).
_SETTLE = 10
# Absolute curvature floor (per unit weight): a body with no wall in reach does not move.
_FLOOR = 1e-6


@dataclasses.dataclass(frozen=True)
class _Pulls:
    """One pull per (point, other body): the point, its owner, the other body, the wall's unit
    normal and a point on it, and the pull's weight (module doc)."""

    point: IntArray
    owner: IntArray
    other: IntArray
    normal: FloatArray  # (M, 2)
    foot: FloatArray  # (M, 2) the soft-nearest point of the other body
    weight: FloatArray
    pairs: int  # point pairs examined (within the cut-off)


def coarser(bodies: Bodies, cell: float) -> Bodies:
    """``bodies`` with one point per body, ``cell``-sized grid cell and direction octant: the
    mass-weighted mean of its points, carrying their summed mass (Sec. 3.3's resampling, done
    on the points so that each body's frame and masses are kept)."""
    angle = np.arctan2(bodies.directions[:, 1], bodies.directions[:, 0])
    octant = np.floor((angle + np.pi) / (2.0 * np.pi / _OCTANTS)).astype(np.int64) % _OCTANTS
    grid = np.floor(bodies.points / cell).astype(np.int64)
    key = np.column_stack([bodies.body, grid, octant])
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.ravel()
    count = int(group.max()) + 1 if len(group) else 0
    mass = np.bincount(group, bodies.masses, count).astype(np.float64)
    points = (
        np.column_stack(
            [np.bincount(group, bodies.masses * bodies.points[:, c], count) for c in (0, 1)]
        )
        / np.maximum(mass, 1e-12)[:, None]
    )
    directions = np.column_stack(
        [np.bincount(group, bodies.masses * bodies.directions[:, c], count) for c in (0, 1)]
    ).astype(np.float64)
    directions /= np.maximum(np.hypot(*directions.T), 1e-12)[:, None]
    body = np.zeros(count, dtype=np.int64)
    body[group] = bodies.body
    return Bodies(points.astype(np.float64), directions, mass, body, bodies.count)


def levels(bodies: Bodies, spacing: float, sigma_start: float) -> list[tuple[float, Bodies]]:
    """``(cell, bodies)`` from the finest (``spacing``, the bodies as given) up to cells of
    ``sigma_start`` / _CELLS_PER_SIGMA, each twice the last."""
    out = [(spacing, bodies)]
    cell = 2.0 * spacing
    while cell <= sigma_start / _CELLS_PER_SIGMA:
        out.append((cell, coarser(bodies, cell)))
        cell *= 2.0
    return out


def wall_pulls(
    points: FloatArray,
    directions: FloatArray,
    bodies: Bodies,
    sigma: float,
    cell: float,
    cutoff: float,
    pulled: int = _PULLED,
) -> _Pulls:
    """Every point's pull towards each other body's nearest wall in reach (module doc);
    ``points``, ``directions`` placed in ``map``, ``cell`` the points' spacing."""
    # Every point is a wall to pull towards; every stride-th one is pulled (module doc).
    stride = max(1, -(-len(points) // pulled))
    sources = np.arange(0, len(points), stride)
    pairs = cKDTree(points[sources]).sparse_distance_matrix(
        cKDTree(points), cutoff * sigma, output_type="ndarray"
    )
    # Columns gathered once per pair (x and y apart: no (M, 2) row gathers); a pulled point
    # is known by its rank among the sources, so the (point, body) keys span sources × bodies.
    rank, j = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    i = rank * stride
    px, py, dx, dy = (np.ascontiguousarray(c) for c in (*points.T, *directions.T))
    dxj, dyj = dx[j], dy[j]
    # Faces (bodies module): walls seen from opposite sides do not pull (Eq. 2's cosine).
    keep = (bodies.body[i] != bodies.body[j]) & (dx[i] * dxj + dy[i] * dyj > 0.0)
    rank, i, j, dxj, dyj = rank[keep], i[keep], j[keep], dxj[keep], dyj[keep]
    pxj, pyj = px[j], py[j]
    gx, gy = pxj - px[i], pyj - py[i]
    # The soft nearest of the other body's points: weights over a point spacing, summed per
    # (point, body) key; gaps are < cutoff * sigma < 2 * cutoff * cell, no underflow.
    near = bodies.masses[j] * np.exp(-(gx * gx + gy * gy) / (2.0 * cell**2))
    key = rank * bodies.count + bodies.body[j]
    total = np.bincount(key, near, len(sources) * bodies.count)
    keys = np.flatnonzero(total > 0.0)
    share = near / total[key]
    order = np.zeros(len(total), dtype=np.int64)
    order[keys] = np.arange(len(keys))
    group = order[key]
    mean = [np.bincount(group, share * v, len(keys)) for v in (pxj, pyj, dxj, dyj)]
    foot = np.column_stack(mean[:2]).astype(np.float64)
    tangent = np.column_stack(mean[2:]).astype(np.float64)
    tangent /= np.maximum(np.hypot(*tangent.T), 1e-12)[:, None]
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    point = (keys // bodies.count) * stride
    distance = normal[:, 0] * (px[point] - foot[:, 0]) + normal[:, 1] * (py[point] - foot[:, 1])
    face = dx[point] * tangent[:, 0] + dy[point] * tangent[:, 1]
    weight = bodies.masses[point] * face * np.exp(-(distance**2) / (2.0 * sigma**2))
    return _Pulls(point, bodies.body[point], keys % bodies.count, normal, foot, weight, len(pairs))


def _jacobians(pulls: _Pulls, points: FloatArray, centres: FloatArray) -> FloatArray:
    """(M, 6): each pull's distance r = n·(p - q) differentiated by its owner's pose increment
    (x, y, θ about its centre) and by the other body's (which carries the wall and turns it)."""
    n, p, q = pulls.normal, points[pulls.point], pulls.foot
    arm_p = p - centres[pulls.owner]
    arm_q = q - centres[pulls.other]
    turn_owner = -n[:, 0] * arm_p[:, 1] + n[:, 1] * arm_p[:, 0]
    # The wall turns with its body: d n/dθ = perp(n), and its point q moves by perp(q - c).
    turned = -n[:, 1] * (p - q)[:, 0] + n[:, 0] * (p - q)[:, 1]
    turn_other = turned + n[:, 0] * arm_q[:, 1] - n[:, 1] * arm_q[:, 0]
    return np.column_stack([n[:, 0], n[:, 1], turn_owner, -n[:, 0], -n[:, 1], turn_other])


def joint_step(
    pulls: _Pulls, points: FloatArray, centres: FloatArray, free: BoolArray, alone: bool = False
) -> FloatArray:
    """(K, 3) every body's pose increment (x, y, θ about its centre) minimising the weighted
    squared distances of the pulls' quadratic model at once, the fixed bodies held (module
    doc); ``alone``: each body's own Newton step, the others held where they are (its own 3×3
    block of the same system)."""
    count = len(centres)
    jac = _jacobians(pulls, points, centres)
    distance = np.einsum("ij,ij->i", pulls.normal, points[pulls.point] - pulls.foot)
    w = pulls.weight
    # Sums of w·J_u·J_v per (owner, other) pair of bodies: 21 products of the 6 columns.
    pair = pulls.owner * count + pulls.other
    u, v = np.triu_indices(6)
    sums = np.stack(
        [
            np.bincount(pair, w * jac[:, a] * jac[:, b], count * count)
            for a, b in zip(u, v, strict=True)
        ]
    )
    flat = np.zeros((6, 6, count * count))
    flat[u, v] = sums
    flat[v, u] = sums
    full = flat.reshape(6, 6, count, count)  # [u, v, owner, other]
    own = full[:3, :3].sum(axis=3) + full[3:, 3:].sum(axis=2)  # (3, 3, K) on the diagonal
    gradient = np.zeros(3 * count)
    for x, body in enumerate((pulls.owner, pulls.other)):
        for c in range(3):
            gradient[c::3] += np.bincount(body, w * distance * jac[:, 3 * x + c], count)
    if alone:
        blocks = own.transpose(2, 0, 1)
        diagonal = np.einsum("kii->ki", blocks)
        blocks = blocks + np.eye(3)[None] * (_DAMPING * diagonal + _FLOOR)[:, None, :]
        step = -np.linalg.solve(blocks, gradient.reshape(count, 3, 1))[:, :, 0]
        return np.where(free[:, None], step, 0.0)
    # The joint system only when it is solved: the blocks between bodies, then their own.
    between = full[:3, 3:].transpose(2, 0, 3, 1).reshape(3 * count, 3 * count)
    matrix = between + between.T
    index = np.arange(count)
    matrix.reshape(count, 3, count, 3)[index, :, index, :] += own.transpose(2, 0, 1)
    moving = np.repeat(free, 3)
    system = matrix[np.ix_(moving, moving)]
    system += np.diag(_DAMPING * np.diag(system) + _FLOOR)
    step = np.zeros(3 * count)
    if moving.any():
        step[moving] = np.linalg.solve(system, -gradient[moving])
    return step.reshape(count, 3)


def centres_and_radii(bodies: Bodies, points: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each body's centre of mass in ``map`` (K, 2) and radius of gyration about it (K,)."""
    count = bodies.count
    mass = np.maximum(np.bincount(bodies.body, bodies.masses, count), 1e-12)
    centres = (
        np.column_stack(
            [np.bincount(bodies.body, bodies.masses * points[:, c], count) for c in (0, 1)]
        )
        / mass[:, None]
    )
    spread = np.sum((points - centres[bodies.body]) ** 2, axis=1)
    radii = np.sqrt(np.bincount(bodies.body, bodies.masses * spread, count) / mass)
    return centres, np.maximum(radii, 1e-3)


def bounded_move(
    poses: FloatArray, step: FloatArray, centres: FloatArray, radii: FloatArray, sigma: float
) -> tuple[FloatArray, FloatArray]:
    """Move ``poses`` in place by ``step`` (x, y, θ about ``centres``), each body at most σ and
    turned at most σ at its radius of gyration; each body's relocation (m) and its centre after
    the move (the turn about the centre keeps it: only the shift moves it)."""
    shift = step[:, :2].copy()
    length = np.hypot(*shift.T)
    shift *= (np.minimum(length, sigma) / np.maximum(length, 1e-12))[:, None]
    turn = np.clip(step[:, 2], -sigma / radii, sigma / radii)
    arm = poses[:, :2] - centres
    c, s = np.cos(turn), np.sin(turn)
    poses[:, 0] = centres[:, 0] + c * arm[:, 0] - s * arm[:, 1] + shift[:, 0]
    poses[:, 1] = centres[:, 1] + s * arm[:, 0] + c * arm[:, 1] + shift[:, 1]
    poses[:, 2] = se2.wrap_angle(poses[:, 2] + turn)
    return np.asarray(np.hypot(*shift.T) + np.abs(turn) * radii), centres + shift


def _net_motion(
    track: deque[tuple[FloatArray, FloatArray]],
    poses: FloatArray,
    radii: FloatArray,
    free: BoolArray,
) -> float:
    """The largest net relocation of a moving body over the last _SETTLE iterations (m): its
    centre's shift and its turn at its radius of gyration; infinite before _SETTLE of them."""
    if len(track) <= _SETTLE or not free.any():
        return float("inf") if free.any() else 0.0
    (centres, _), (then, headings) = track[-1], track[0]
    turn = np.abs(se2.wrap_angle(poses[:, 2] - headings))
    return float((np.hypot(*(centres - then).T) + turn * radii)[free].max())


def start_width(translation: float, rotation: float, bodies: Bodies) -> float:
    """The field's start width σ_0 (m) for bodies up to ``translation`` (m) and ``rotation``
    (rad) off: half the displacement of a point at the bodies' median radius of gyration r,
    the shift and the turn's arc added as independent, ``sqrt(translation² + (rotation·r)²)
    / 2``. The paper's ratio: σ from 15 cm for its ±30 cm (Sec. 4.2), half the shift (its
    scans, a few metres across, are not turned far in its σ). For ±0.30 m / ±20° and
    r ≈ 3 m: about 0.55 m."""
    _, radii = centres_and_radii(bodies, bodies.points)
    owned = np.bincount(bodies.body, minlength=bodies.count) > 0
    radius = float(np.median(radii[owned])) if owned.any() else 0.0
    return 0.5 * float(np.hypot(translation, rotation * radius))


def run_ffs_far(
    bodies: Bodies,
    poses: FloatArray,
    config: FfsConfig | None = None,
    fixed: BoolArray | None = None,
) -> FfsResult:
    """Algorithm 1 from ``poses`` (K, 3) as far off as the field's start width
    ``config.sigma_start`` (module doc): the bodies' poses at the end. ``fixed`` bodies never
    move (one holds the map frame)."""
    config = config or FfsConfig()
    started = time.perf_counter()
    poses = np.array(poses, dtype=np.float64).reshape(-1, 3)
    free = np.ones(len(poses), dtype=bool) if fixed is None else ~np.asarray(fixed, dtype=bool)
    ladder = levels(bodies, config.spacing, config.sigma_start)
    sigma, dt = config.sigma_start, config.dt_start
    potentials: list[float] = []
    relocations: list[float] = []
    converged, iteration, pulled = False, 0, _PULLED
    # Each iteration's centres and headings, for the net motion over the last _SETTLE.
    track: deque[tuple[FloatArray, FloatArray]] = deque(maxlen=_SETTLE + 1)
    while iteration < config.max_iterations:
        if config.time_budget > 0.0 and time.perf_counter() - started > config.time_budget:
            break
        iteration += 1
        cell, level = [
            rung for rung in ladder if rung[0] <= max(sigma / _CELLS_PER_SIGMA, config.spacing)
        ][-1]
        points, directions = placed(level, poses)
        pulls = wall_pulls(points, directions, level, sigma, cell, config.cutoff, pulled)
        # Sec. 3.5.1: a budget of pairs, the pulled points thinned where bodies overlap.
        sources = -(-len(points) // max(1, -(-len(points) // pulled)))
        pulled = int(np.clip(sources * _PAIRS / max(pulls.pairs, 1), 100, _PULLED))
        potentials.append(-float(pulls.weight.sum()))
        centres, radii = centres_and_radii(level, points)
        # Eq. 8-9: the step's share (Δt / Δt_0)², Δt cooling as the paper's (5 -> 1 there).
        share = max(_FINAL_STEP_SHARE, (dt / config.dt_start) ** 2)
        # Each body on its own while σ is wider than _JOINT_WIDTH (module doc).
        alone = sigma > _JOINT_WIDTH
        step = joint_step(pulls, points, centres, free, alone) * share
        moved, after = bounded_move(poses, step, centres, radii, sigma)
        relocation = float(moved[free].max()) if free.any() else 0.0
        relocations.append(relocation)
        cooled = sigma <= config.sigma_end
        track.append((after, poses[:, 2].copy()))
        if cooled:
            relocation = max(relocation, _net_motion(track, poses, radii, free))
        sigma = max(config.sigma_end, sigma * config.dt_factor)  # Sec. 3.2, geometric
        dt = max(config.dt_end, dt * config.dt_factor)
        if cooled and relocation < config.stop_relocation:
            converged = True
            break
    seconds = time.perf_counter() - started
    return FfsResult(poses, potentials, relocations, iteration, converged, seconds, sigma, dt)
