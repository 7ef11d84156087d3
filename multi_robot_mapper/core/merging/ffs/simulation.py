"""Force Field Simulation (Lakaemper et al. 2007, Sec. 3, Algorithm 1): every body moves at
once, down the gradient of a Gaussian potential between the points of different bodies.

Per iteration (Algorithm 1, lines 4-14):

- **correspondence strength** (Eq. 2) of points p, q of different bodies:
  ``w = m_p m_q |cos ∠(d_p, d_q)| exp(-|p - q|² / 2σ²)``: orthogonal structures do not attract;
  pairs farther than ``cutoff``·σ are left out (a KD-tree finds the rest);
- **force** on p (Eq. 3), the potential's negative gradient: ``F(p) = Σ_q w (q - p) / σ²``;
  the potential ``P = -Σ w`` is recorded every iteration;
- each body's **translational and rotational acceleration** (Eq. 6-7): the sum of its
  points' forces, and the torque ``Σ (p - c) × F(p)`` about the rotation centre c, which moves
  from the body's centre of mass to its sensor origin as σ cools (the paper's choice: a body
  first turns about its middle, at the end about where it was seen from). Both are divided by
  the body's mass and moment of inertia times the kernel's weight of a point lying on a wall
  of another body, so ½·a·Δt² with Δt = 1 is the step a body lying fully on others' walls
  needs, and a body touching them at a few points moves that much less (module :mod:`.config`);
- steps ``½·a·Δt²``; velocities are reset every iteration (the paper's damping);
- **cooling**: Δt shrinks exponentially, σ linearly; the simulation ends once σ has cooled
  and the mean relocation falls below ``stop_relocation`` (line 15, read with ``<``).

Bodies marked ``fixed`` never move (one is enough to hold the map frame still).

**Chain springs** (issue 14 item 2, :class:`ChainSprings`): pairs of bodies (a robot's
consecutive bodies) are pulled toward their relative pose at rest (the robot's own map, as the
pre-alignment placed it), each by its partner's prediction of it, with an acceleration of
``FfsConfig.chain_stiffness`` times its deviation, in the field's units (a body lying fully on
other bodies' walls is held with stiffness 1). The field then moves a robot's map as a whole
more freely than it bends it.

**Warm start** (issue 14 item 4): ``resume`` continues the cooling of an earlier run (its
result's ``sigma`` and ``dt``) from given poses, so that a merger bounded in time per update
cools across updates instead of starting hot at each."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging.ffs.bodies import Bodies, placed
from multi_robot_mapper.core.merging.ffs.config import FfsConfig

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]


@dataclasses.dataclass(frozen=True)
class FfsResult:
    """The bodies' poses after the simulation and how it went."""

    poses: FloatArray  # (K, 3) x, y, theta of each body in `map`
    potentials: list[float]  # P(g) at each iteration (FFS Eq. 4), before its step
    relocations: list[float]  # mean point relocation of the moving bodies per iteration (m)
    iterations: int
    converged: bool  # stopped by Algorithm 1 line 15, not by the iteration or time limit
    seconds: float
    sigma: float  # the field's width (m) and step width the next iteration would have used:
    dt: float  # where a warm-started run resumes cooling


@dataclasses.dataclass(frozen=True)
class FieldStep:
    """One evaluation of the force field: every body's force, torque and the potential."""

    force: FloatArray  # (K, 2) sum of the forces on the body's points (Eq. 3)
    torque: FloatArray  # (K,) sum of (p - c) x F(p) about the body's rotation centre
    potential: float
    pairs: int  # point pairs within the cut-off, of different bodies


def force_field(
    points: FloatArray,
    directions: FloatArray,
    bodies: Bodies,
    centres: FloatArray,
    sigma: float,
    cutoff: float,
) -> FieldStep:
    """Eq. 2 and 3 summed per body, and the torques (``points``, ``directions`` in ``map``;
    ``centres`` (K, 2) the rotation centres)."""
    count = bodies.count
    force = np.zeros((count, 2))
    torque = np.zeros(count)
    if len(points) < 2:
        return FieldStep(force, torque, 0.0, 0)
    pairs = cKDTree(points).query_pairs(cutoff * sigma, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    other = bodies.body[i] != bodies.body[j]
    i, j = i[other], j[other]
    if len(i) == 0:
        return FieldStep(force, torque, 0.0, 0)
    gap = points[j] - points[i]  # from p_i to p_j
    # Eq. 2's cosine, of faces: walls seen from opposite sides (the two faces of one wall)
    # pull no more than orthogonal ones (bodies module doc).
    cos = np.maximum(np.einsum("ij,ij->i", directions[i], directions[j]), 0.0)
    distance2 = np.einsum("ij,ij->i", gap, gap)
    w = bodies.masses[i] * bodies.masses[j] * cos * np.exp(-distance2 / (2 * sigma**2))
    pull = w[:, None] * gap / sigma**2  # on p_i; the opposite on p_j (Eq. 3)
    ends = np.concatenate([i, j])
    pulls = np.concatenate([pull, -pull])
    owner = bodies.body[ends]
    force[:, 0] = np.bincount(owner, pulls[:, 0], count)
    force[:, 1] = np.bincount(owner, pulls[:, 1], count)
    arm = points[ends] - centres[owner]
    torque[:] = np.bincount(owner, arm[:, 0] * pulls[:, 1] - arm[:, 1] * pulls[:, 0], count)
    return FieldStep(force, torque, float(-w.sum()), len(i))


def run_ffs(
    bodies: Bodies,
    poses: FloatArray,
    config: FfsConfig | None = None,
    fixed: BoolArray | None = None,
    springs: ChainSprings | None = None,
    resume: tuple[float, float] | None = None,
) -> FfsResult:
    """Algorithm 1 from ``poses`` (K, 3): the bodies' poses at the end (module doc).
    ``springs``: the chain springs between bodies (none by default); ``resume``: (σ, Δt) to
    continue cooling from (a warm start; default: the config's start values)."""
    config = config or FfsConfig()
    started = time.perf_counter()
    poses = np.array(poses, dtype=np.float64).reshape(-1, 3)
    count = len(poses)
    free = np.ones(count, dtype=bool) if fixed is None else ~np.asarray(fixed, dtype=bool)
    springs = springs or ChainSprings(poses, None, 0.0)
    moments = _BodyMoments.of(bodies, count)
    sigma, dt = resume or (config.sigma_start, config.dt_start)
    potentials: list[float] = []
    relocations: list[float] = []
    converged = False
    iteration = 0
    span = max(config.sigma_start - config.sigma_end, 1e-12)
    while iteration < config.max_iterations:
        if config.time_budget > 0.0 and time.perf_counter() - started > config.time_budget:
            break
        iteration += 1
        points, directions = placed(bodies, poses)
        # Rotation centre: centre of mass -> sensor origin as sigma cools (FFS 3.5).
        cooled = (config.sigma_start - sigma) / span
        centres = _rotation_centres(poses, moments.com_local, cooled)
        field = force_field(points, directions, bodies, centres, sigma, config.cutoff)
        spring = springs.acceleration(poses)
        potentials.append(field.potential)
        relocation = _step(
            poses, field, spring, centres, moments, free, cooled, sigma, dt, config.spacing
        )
        relocations.append(relocation)
        # Cooling (FFS 3.6): sigma linearly, dt exponentially.
        sigma = max(config.sigma_end, sigma - config.sigma_step)
        dt = max(config.dt_end, dt * config.dt_factor)
        if sigma <= config.sigma_end and relocation < config.stop_relocation:
            converged = True
            break
    seconds = time.perf_counter() - started
    return FfsResult(poses, potentials, relocations, iteration, converged, seconds, sigma, dt)


@dataclasses.dataclass(frozen=True)
class _BodyMoments:
    """Each body's mass, centre of mass in its own frame (where the sensor origin is (0, 0))
    and radius of gyration about its origin."""

    mass: FloatArray  # (K,)
    com_local: FloatArray  # (K, 2)
    radius: FloatArray  # (K,)

    @staticmethod
    def of(bodies: Bodies, count: int) -> _BodyMoments:
        """The moments of the ``count`` bodies' points."""
        # Centre of mass of each body in its own frame; the sensor origin is (0, 0) there.
        mass = np.maximum(np.bincount(bodies.body, bodies.masses, count), 1e-12)
        com_local = np.column_stack(
            [
                np.bincount(bodies.body, bodies.masses * bodies.points[:, c], count) / mass
                for c in (0, 1)
            ]
        )
        radius = np.sqrt(
            np.bincount(bodies.body, bodies.masses * np.sum(bodies.points**2, axis=1), count) / mass
        )
        return _BodyMoments(mass, com_local, radius)


def _rotation_centres(poses: FloatArray, com_local: FloatArray, cooled: float) -> FloatArray:
    """(K, 2) each body's rotation centre in ``map``: its centre of mass (``com_local`` in its
    own frame) drawn towards its sensor origin by the share ``cooled`` of the cooling."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    local = (1.0 - cooled) * com_local
    return poses[:, :2] + np.column_stack(
        [c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]]
    )


def _step(
    poses: FloatArray,
    field: FieldStep,
    spring: FloatArray,
    centres: FloatArray,
    moments: _BodyMoments,
    free: BoolArray,
    cooled: float,
    sigma: float,
    dt: float,
    spacing: float,
) -> float:
    """One step of the free bodies (``poses`` moved in place) by the field and the springs'
    accelerations: ½·a·Δt², turning about the rotation centres; the mean relocation of the
    free bodies (m)."""
    mass, com_local, radius = moments.mass, moments.com_local, moments.radius
    # Accelerations (Eq. 6-7): force over mass, torque over moment of inertia, both in
    # units of a body lying fully on another's walls (a point there has the kernel's sum
    # sqrt(2 pi) sigma / spacing of neighbours on a line): then 1/2 a dt^2 with dt = 1 is
    # the whole step such a body needs, and a body touching others at a few points only
    # moves that much less (the paper's F / m).
    contact = np.sqrt(2.0 * np.pi) * sigma / spacing / sigma**2
    # Moment of inertia about the centre a * com (a = 1 - cooled), from the body's second
    # moment: sum m |p - a com|^2 = M (r^2 - (2a - a^2) |com|^2), no pass over the points.
    a = 1.0 - cooled
    inertia = mass * (radius**2 - (2.0 * a - a * a) * np.sum(com_local**2, axis=1))
    translation = field.force / (mass[:, None] * contact)
    rotation = np.where(inertia > 1e-12, field.torque / (np.maximum(inertia, 1e-12) * contact), 0.0)
    step = 0.5 * dt**2
    shift = step * translation * free[:, None]
    turn = step * rotation * free
    # Turning about the centre moves the body's origin too.
    arm = poses[:, :2] - centres
    ct, st = np.cos(turn), np.sin(turn)
    poses[:, 0] = centres[:, 0] + ct * arm[:, 0] - st * arm[:, 1] + shift[:, 0]
    poses[:, 1] = centres[:, 1] + st * arm[:, 0] + ct * arm[:, 1] + shift[:, 1]
    # The springs pull on the bodies' origins (their prediction is of the whole pose).
    pulled = step * spring * free[:, None]
    poses[:, :2] += pulled[:, :2]
    poses[:, 2] = se2.wrap_angle(poses[:, 2] + turn + pulled[:, 2])
    # Net motion: where field and springs balance, the body stands still.
    moved = np.hypot(*(shift + pulled[:, :2]).T) + np.abs(turn + pulled[:, 2]) * radius
    return float(moved[free].mean()) if free.any() else 0.0


class ChainSprings:
    """The chain springs of :func:`run_ffs` (module doc): ``chain`` (M, 2) pairs of bodies,
    each held at its relative pose in ``rest`` (K, 3) with ``stiffness``, and every body's
    spring acceleration at given poses."""

    def __init__(self, rest: FloatArray, chain: IntArray | None, stiffness: float) -> None:
        pairs = np.zeros((0, 2), dtype=np.int64) if chain is None else np.asarray(chain)
        rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
        self.count = len(rest)
        self.stiffness = stiffness if len(pairs) else 0.0
        self.first, self.second = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
        self.T_first_second = se2.between_each(rest[self.first], rest[self.second])
        self.T_second_first = se2.between_each(rest[self.second], rest[self.first])

    def acceleration(self, poses: FloatArray) -> FloatArray:
        """(K, 3): stiffness times the sum over a body's springs of its partner's prediction
        of its pose minus its pose (x, y, theta)."""
        pull = np.zeros((self.count, 3))
        if self.stiffness == 0.0:
            return pull
        for body, partner, T_partner_body in (
            (self.second, self.first, self.T_first_second),
            (self.first, self.second, self.T_second_first),
        ):
            gap = se2.compose_each(poses[partner], T_partner_body) - poses[body]
            gap[:, 2] = se2.wrap_angle(gap[:, 2])
            np.add.at(pull, body, gap)
        return self.stiffness * pull
