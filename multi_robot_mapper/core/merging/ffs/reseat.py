"""Bodies left in a wrong minimum, re-seated (issue 51): after :func:`run_ffs_far` has cooled,
each body's potential is evaluated over a fan of turns and shifts against the field of all the
other bodies, sampled on a grid; a body that lies clearly deeper elsewhere is moved there, and
the field runs again from a narrow width.

Why: from the paper's ±20° the wide field brings back all but a few bodies, and those few keep
the turn they started with (intel's keyframes at the corridor's bend stay 16-27° off: their
own walls hold them). The paper says as much of its Fig. 4: "one single initially strongly
misaligned scan ... stays in its incorrect position". The score is the paper's potential of
one body (Eq. 3-4: Σ m_p m_q cos∠ exp(-|p - q|²/2σ²) over the body's points p and the other
bodies' points q), with the other bodies' Gaussians summed once on a grid (Sec. 3.5.1: the
field need only be evaluated to a certain accuracy) in four direction channels (Eq. 2's
cosine, positive part). The fan turns a body about its sensor, not its centre of mass (the
paper's other rotation centre, Sec. 3.5: a keyframe left turned at the bend sits 11-53 cm from
its place at the sensor, metres at its centre of mass). The run after a re-seat is Algorithm 1
again (lines 3-15) from a narrow width, and the round is kept only if the whole map's
potential at the cooled width is deeper than before (Eq. 5's fitness): in clutter a body may
find a deeper place for itself that pulls its neighbours off theirs.

Re-seating runs of consecutive bodies together (``group`` > 1, shifts of ±1.2 m for intel's
tail slid a door's pitch) moved R0 itself 1.2 m along its corridor: not used (decisions.md)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter

from multi_robot_mapper.core.merging.ffs.bodies import Bodies, placed
from multi_robot_mapper.core.merging.ffs.config import FfsConfig
from multi_robot_mapper.core.merging.ffs.far import coarser, run_ffs_far
from multi_robot_mapper.core.merging.ffs.simulation import FfsResult

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

# The fan's shift step (m): a few grid cells, within the field's width.
_SHIFT_STEP = 0.15
# The grid's cell (m) and the field's width on it (m): the fan's step is covered by σ.
_CELL = 0.05
_WIDTH = 0.15
# A body is moved only if its potential there is deeper by this share; whether the move stays
# is the round's Eq. 5 check (run_ffs_reseated). 0.3 left csail's keyframes at the far end of
# the excerpt, which the other bodies barely see, turned 24-33 deg with their place in R0 only
# 16-20 % deeper (seeds 2, 4); 0.1 brings them back and changes no seed of intel or
# freiburg-079 (issue 51, docs/decisions.md).
_GAIN = 0.1
# Rounds of re-seating (each followed by a run of the field from _WIDTH).
_ROUNDS = 2


@dataclasses.dataclass(frozen=True)
class Fan:
    """Poses tried about a sensor: turns (rad) and shifts (in _SHIFT_STEP, both axes)."""

    turns: FloatArray
    shifts: IntArray


# A body alone: turns of ±30° by 3° (wider than the paper's ±20°), shifts of ±0.6 m by 0.15 m.
BODY_FAN = Fan(np.radians(np.arange(-30.0, 30.01, 3.0)), np.arange(-4, 5))


def _channels(directions: FloatArray) -> FloatArray:
    """(N, 4) each direction's share in the channels about 0°, 90°, 180°, 270°: max(0, cos)."""
    angle = np.arctan2(directions[:, 1], directions[:, 0])
    share = np.cos(angle[:, None] - np.arange(4)[None, :] * np.pi / 2.0)
    return np.asarray(np.maximum(0.0, share), dtype=np.float64)


def _field(
    points: FloatArray,
    directions: FloatArray,
    masses: FloatArray,
    lo: FloatArray,
    shape: tuple[int, int],
) -> FloatArray:
    """(4, nx, ny) the points' masses per channel, blurred by _WIDTH."""
    cells = np.floor((points - lo) / _CELL).astype(np.int64)
    inside = (cells >= 0).all(axis=1) & (cells[:, 0] < shape[0]) & (cells[:, 1] < shape[1])
    share = _channels(directions[inside]) * masses[inside, None]
    flat = cells[inside, 0] * shape[1] + cells[inside, 1]
    grid = np.stack(
        [np.bincount(flat, share[:, c], shape[0] * shape[1]).reshape(shape) for c in range(4)]
    ).astype(np.float32)
    blurred = gaussian_filter(grid, (0.0, _WIDTH / _CELL, _WIDTH / _CELL), truncate=2.5)
    return np.asarray(blurred, dtype=np.float64)


def _turned(
    points: FloatArray, directions: FloatArray, centre: FloatArray, fan: Fan
) -> tuple[FloatArray, FloatArray]:
    """Every fan turn's points (T, P, 2) before the shift, and channel shares (T, P, 4)."""
    c, s = np.cos(fan.turns)[:, None], np.sin(fan.turns)[:, None]
    arm = points - centre
    turned = np.stack([c * arm[:, 0] - s * arm[:, 1], s * arm[:, 0] + c * arm[:, 1]], axis=-1)
    faces = np.stack(
        [c * directions[:, 0] - s * directions[:, 1], s * directions[:, 0] + c * directions[:, 1]],
        axis=-1,
    )
    return turned + centre, _channels(faces.reshape(-1, 2)).reshape(len(fan.turns), -1, 4)


def fan_scores(
    level: Bodies,
    placed_level: tuple[FloatArray, FloatArray],
    own: BoolArray,
    centre: FloatArray,
    fan: Fan,
) -> FloatArray:
    """(T, S, S) the potential of the points ``own`` at every pose of ``fan`` about ``centre``
    against the field of all the other points (module doc)."""
    points, directions = placed_level
    turned, shares = _turned(points[own], directions[own], centre, fan)
    reach = float(np.abs(fan.shifts).max()) * _SHIFT_STEP + 3.0 * _WIDTH
    lo = turned.reshape(-1, 2).min(axis=0) - reach
    size = np.ceil((turned.reshape(-1, 2).max(axis=0) + reach - lo) / _CELL).astype(int) + 1
    shape = (int(size[0]), int(size[1]))
    others = ~own
    field = _field(points[others], directions[others], level.masses[others], lo, shape)
    cells = np.floor((turned - lo) / _CELL).astype(np.int64)  # (T, P, 2)
    step = round(_SHIFT_STEP / _CELL)
    # The window holds every shifted cell (reach), so a cell's flat index is exact; a face
    # has a share in two channels only (max(0, cos) is 0 in the others), so two look-ups per
    # point and pose, not four.
    offset = step * (fan.shifts[:, None] * shape[1] + fan.shifts[None, :])  # (S, S)
    base = (cells[..., 0] * shape[1] + cells[..., 1])[..., None, None] + offset
    flat = field.reshape(-1)
    area = shape[0] * shape[1]
    masses = level.masses[own][None, :]
    first = np.argmax(shares, axis=2)  # (T, P): the channel nearest the face, then its
    left, right = (first + 3) % 4, (first + 1) % 4  # neighbour on the face's side
    pick = np.take_along_axis(shares, np.stack([left, right], axis=2), axis=2)
    second = np.where(pick[..., 0] > pick[..., 1], left, right)
    scores = np.zeros((len(fan.turns), len(fan.shifts), len(fan.shifts)))
    for channel in (first, second):
        weight = np.take_along_axis(shares, channel[..., None], axis=2)[..., 0] * masses
        values = flat[(channel * area)[..., None, None] + base]  # (T, P, S, S)
        scores += np.einsum("tpab,tp->tab", values, weight)
    return scores


def reseat(
    bodies: Bodies, poses: FloatArray, free: BoolArray, fan: Fan, group: int
) -> tuple[FloatArray, int]:
    """``poses`` with every run of ``group`` consecutive bodies (one body: ``group`` 1; runs
    overlapping by half) whose potential is deeper by _GAIN at another pose of ``fan`` (about
    its first body's sensor) moved there, rigidly; how many runs were moved. The fixed bodies
    never move, nor a run holding one."""
    level = coarser(bodies, _SHIFT_STEP)
    moved = np.array(poses, dtype=np.float64)
    middle = (len(fan.turns) // 2, len(fan.shifts) // 2, len(fan.shifts) // 2)
    count = 0
    for first in range(0, bodies.count - group + 1, max(1, group // 2)):
        members = np.arange(first, first + group)
        own = np.isin(level.body, members)
        if not free[members].all() or not own.any():
            continue
        centre = moved[first, :2].copy()
        scores = fan_scores(level, placed(level, moved), own, centre, fan)
        t, a, b = np.unravel_index(int(np.argmax(scores)), scores.shape)
        if scores[t, a, b] <= (1.0 + _GAIN) * scores[middle]:
            continue
        shift = _SHIFT_STEP * np.array([fan.shifts[a], fan.shifts[b]], dtype=np.float64)
        moved = seated(moved, members, first, (fan.turns[t], shift[0], shift[1]))
        count += 1
    return moved, count


def seated(
    poses: FloatArray, unit: IntArray, about: int, peak: tuple[float, float, float]
) -> FloatArray:
    """``poses`` with ``unit``'s bodies turned rigidly about ``about``'s sensor and shifted as
    ``peak`` (turn (rad), shift x, shift y (m)) says: a pose of a fan."""
    moved = np.array(poses, dtype=np.float64)
    turn, dx, dy = peak
    c, s = np.cos(turn), np.sin(turn)
    arm = poses[unit, :2] - poses[about, :2]
    moved[unit, 0] = poses[about, 0] + c * arm[:, 0] - s * arm[:, 1] + dx
    moved[unit, 1] = poses[about, 1] + s * arm[:, 0] + c * arm[:, 1] + dy
    moved[unit, 2] += turn
    return moved


def run_ffs_reseated(
    bodies: Bodies,
    poses: FloatArray,
    config: FfsConfig | None = None,
    fixed: BoolArray | None = None,
) -> FfsResult:
    """:func:`run_ffs_far`, then up to _ROUNDS of :func:`reseat` each followed by the field
    again from _WIDTH (module doc)."""
    config = config or FfsConfig()
    started = time.perf_counter()
    free = np.ones(len(poses), dtype=bool) if fixed is None else ~np.asarray(fixed, dtype=bool)
    result = run_ffs_far(bodies, poses, config, fixed)
    iterations = result.iterations
    potentials, relocations = list(result.potentials), list(result.relocations)
    narrow = dataclasses.replace(config, sigma_start=min(_WIDTH, config.sigma_start))
    for _ in range(_ROUNDS):
        turned, count = reseat(bodies, result.poses, free, BODY_FAN, 1)
        if count == 0:
            break
        again = run_ffs_far(bodies, turned, narrow, fixed)
        iterations += again.iterations
        potentials += again.potentials
        relocations += again.relocations
        # Kept only if the map as a whole lies deeper (Eq. 4-5 at the cooled width): a body
        # turned onto clutter may deepen its own potential and pull its neighbours off theirs.
        if not again.potentials or again.potentials[-1] >= result.potentials[-1]:
            break
        result = again
    return dataclasses.replace(
        result,
        potentials=potentials,
        relocations=relocations,
        iterations=iterations,
        seconds=time.perf_counter() - started,
    )
