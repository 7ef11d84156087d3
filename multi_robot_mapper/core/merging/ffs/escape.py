"""Weak bodies brought out of a wrong minimum together (issue 51): after the re-seating rounds
(:func:`~multi_robot_mapper.core.merging.ffs.reseat.run_ffs_reseated`), the bodies the field
holds least firmly are tried again from the peaks of their fans, their weak neighbours free to
follow, and the map is kept only where Eq. 5 finds it deeper.

Why: on csail a tail of small keyframes (53-56) ends turned 23-60° together, 1.55 % shallower
than R0 by Eq. 5: a real wrong minimum, held together by its own members' walls, so re-seating
one body at a time does not leave it, and R0's tail is not a rigid move of the wrong one (its
members turned by up to 37° against each other: 54 by 23°, 55-56 by 54-60° together).

- **Which bodies** (field information only): each body's depth per unit mass, Eq. 4's
  potential of its own points against every other body at the cooled width σ_end, over every
  point (:func:`depth`). A body is weak below _WEAK of the median free body's. Weak bodies
  that pull on one another at σ_end are one group; the group with the weakest body first.
- **Where from**: each member alone and each pair of members that pull on one another (a
  unit), moved rigidly by ESCAPE_FAN about its weaker member's sensor; reseat's score (Eq. 3-4
  against the others' field on a grid), its local maxima deepest first, _PEAKS of them.
- **How**: from each peak, Algorithm 1 again (lines 3-15) from reseat's narrow width with the
  group free and every other body held, screened after the cooling and _SETTLE iterations;
  the deepest candidate by Eq. 5 over every point is taken if deeper than the map as it
  stands, and the group's pass repeats from there (a wrong tail may need two moves: csail's
  55-56 together, then 54), until no candidate is deeper; then the next group. A map already
  in its deepest reachable minimum is returned unchanged: nothing shallower is ever kept.
  The candidate runs see the group and the bodies within its fan's reach only (the others are
  held and out of reach: they add nothing to the steps)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from multi_robot_mapper.core.merging.ffs.bodies import Bodies, placed
from multi_robot_mapper.core.merging.ffs.config import FfsConfig
from multi_robot_mapper.core.merging.ffs.far import _SETTLE, coarser, run_ffs_far, wall_pulls
from multi_robot_mapper.core.merging.ffs.reseat import (
    _SHIFT_STEP,
    _WIDTH,
    BODY_FAN,
    Fan,
    fan_scores,
    run_ffs_reseated,
    seated,
)
from multi_robot_mapper.core.merging.ffs.simulation import FfsResult

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

# A body is weak below this share of the median free body's depth per unit mass (csail: the
# strayed tail 0.09-0.12 against a median of 0.35 at 0.05 m; R0's own tail 0.16-0.22).
_WEAK = 0.5
# Turns of ±60° by 3°: the strayed keyframes were found 23-60° off R0 (the body fan's ±30° is
# the first rounds'); shifts as the body fan's.
ESCAPE_FAN = Fan(np.radians(np.arange(-60.0, 60.01, 3.0)), BODY_FAN.shifts)
# Relative depth differences below this are the sums' rounding, not a deeper map.
_ROUNDING = 1e-9
# Peaks of a unit's fan tried, deepest first (csail seed 0: 55-56's 10th and 12th the
# deepest candidates, the pass that needed them).
_PEAKS = 12


@dataclasses.dataclass(frozen=True)
class Depth:
    """Eq. 5's fitness over every point at the cooled width (the potential's sign turned):
    the whole map's, each body's own points' per unit mass, and the pulls between bodies."""

    total: float
    per_mass: FloatArray  # (K,)
    links: BoolArray  # (K, K): body a's points pulled by body b's walls


def depth(bodies: Bodies, poses: FloatArray, config: FfsConfig) -> Depth:
    """:class:`Depth` of ``bodies`` at ``poses``: Eq. 4 at ``config.sigma_end``, every point
    pulled (far.wall_pulls with no budget)."""
    points, directions = placed(bodies, poses)
    pulls = wall_pulls(
        points, directions, bodies, config.sigma_end, config.spacing, config.cutoff, len(points)
    )
    count = bodies.count
    own = np.bincount(pulls.owner, pulls.weight, count)
    mass = np.bincount(bodies.body, bodies.masses, count)
    pair = np.bincount(pulls.owner * count + pulls.other, pulls.weight, count * count)
    links = pair.reshape(count, count) > 0.0
    return Depth(float(pulls.weight.sum()), own / np.maximum(mass, 1e-12), links)


def weak_groups(measured: Depth, free: BoolArray) -> list[IntArray]:
    """The free bodies below _WEAK of the median free body's depth per unit mass, grouped by
    the pulls between them (either way), the group with the weakest body first."""
    if not free.any():
        return []
    per_mass = measured.per_mass
    weak = free & (per_mass < _WEAK * np.median(per_mass[free]))
    index = np.flatnonzero(weak)
    if len(index) == 0:
        return []
    linked = measured.links[np.ix_(index, index)]
    graph = coo_matrix(linked | linked.T)
    _, label = connected_components(graph, directed=False)
    groups = [index[label == g] for g in range(int(label.max()) + 1)]
    return sorted(groups, key=lambda group: float(per_mass[group].min()))


def fan_peaks(
    bodies: Bodies, poses: FloatArray, unit: IntArray, about: int
) -> list[tuple[float, float, float]]:
    """The local maxima of the fan scores of ``unit``'s bodies, moved rigidly by ESCAPE_FAN
    about ``about``'s sensor, against the other bodies (reseat's grid potential, Eq. 3-4),
    deepest first, _PEAKS of them, the pose it lies at left out: each as (turn (rad), shift x,
    shift y (m))."""
    level = coarser(bodies, _SHIFT_STEP)
    own = np.isin(level.body, unit)
    if not own.any():
        return []
    centre = poses[about, :2].copy()
    scores = fan_scores(level, placed(level, poses), own, centre, ESCAPE_FAN)
    peaks = np.flatnonzero((scores == maximum_filter(scores, size=3)).ravel())
    order = peaks[np.argsort(-scores.ravel()[peaks], kind="stable")]
    middle = np.ravel_multi_index(
        (len(ESCAPE_FAN.turns) // 2, len(ESCAPE_FAN.shifts) // 2, len(ESCAPE_FAN.shifts) // 2),
        scores.shape,
    )
    out = []
    for flat in order[order != middle][:_PEAKS]:
        t, a, b = np.unravel_index(int(flat), scores.shape)
        shift = _SHIFT_STEP * ESCAPE_FAN.shifts[[a, b]]
        out.append((float(ESCAPE_FAN.turns[t]), float(shift[0]), float(shift[1])))
    return out


def units(group: IntArray, measured: Depth) -> list[IntArray]:
    """What is seated at a fan's peaks: each member of ``group`` alone, then each pair of
    members that pull on one another (a wrong minimum's bodies may have moved together)."""
    linked = measured.links[np.ix_(group, group)]
    a, b = np.nonzero(np.triu(linked | linked.T, 1))
    return [group[[k]] for k in range(len(group))] + [
        group[[i, j]] for i, j in zip(a, b, strict=True)
    ]


def neighbourhood(bodies: Bodies, poses: FloatArray, group: IntArray, reach: float) -> BoolArray:
    """The bodies with a point within ``reach`` of a point of ``group`` at ``poses``, plus the
    group (the only bodies whose walls a candidate's run can meet)."""
    points, _ = placed(bodies, poses)
    own = np.isin(bodies.body, group)
    near = cKDTree(points[own]).query_ball_point(points[~own], reach, return_length=True) > 0
    inside = np.zeros(bodies.count, dtype=bool)
    inside[group] = True
    inside[np.unique(bodies.body[~own][near])] = True
    return inside


def subset(bodies: Bodies, inside: BoolArray) -> Bodies:
    """``bodies`` with only those ``inside``, renumbered in order."""
    keep = inside[bodies.body]
    number = np.cumsum(inside) - 1
    return Bodies(
        bodies.points[keep],
        bodies.directions[keep],
        bodies.masses[keep],
        number[bodies.body[keep]],
        int(inside.sum()),
    )


def best_candidate(
    bodies: Bodies, poses: FloatArray, group: IntArray, measured: Depth, narrow: FfsConfig
) -> tuple[FloatArray, float, list[FfsResult]]:
    """The deepest map by Eq. 5 (and its depth) over every unit of ``group`` seated at each of
    its fan's peaks, then run from ``narrow`` with the group free and every other body held;
    the runs. A run sees the group and the bodies its fan can reach only (the rest are held
    and out of reach: they add nothing to its steps)."""
    reach = (
        _SHIFT_STEP * float(np.abs(ESCAPE_FAN.shifts).max()) + narrow.cutoff * narrow.sigma_start
    )
    # A candidate is screened after the schedule's cooling and _SETTLE more iterations (far's
    # stop rule needs those anyway); the kept one is run to the end by run_ffs_escaped.
    cooling = np.log(narrow.sigma_end / narrow.sigma_start) / np.log(narrow.dt_factor)
    screen = dataclasses.replace(narrow, max_iterations=int(np.ceil(cooling)) + _SETTLE + 1)
    runs: list[FfsResult] = []
    best, deepest = poses, -np.inf
    for unit in units(group, measured):
        about = int(unit[np.argmin(measured.per_mass[unit])])
        for peak in fan_peaks(bodies, poses, unit, about):
            start = seated(poses, unit, about, peak)
            inside = neighbourhood(bodies, start, group, reach)
            held = ~np.isin(np.flatnonzero(inside), group)
            run = run_ffs_far(subset(bodies, inside), start[inside], screen, held)
            runs.append(run)
            candidate = np.array(start)
            candidate[inside] = run.poses
            found = depth(bodies, candidate, narrow).total
            if found > deepest:
                best, deepest = candidate, found
    return best, deepest, runs


def escape(
    bodies: Bodies, poses: FloatArray, free: BoolArray, config: FfsConfig, narrow: FfsConfig
) -> tuple[FloatArray, list[FfsResult]]:
    """``poses`` with the weakest weak group (:func:`weak_groups`) moved to its deepest
    candidate (:func:`best_candidate`) while that is deeper by Eq. 5 than the map as it stands,
    then the next group (module doc); the candidates' runs, for their iterations.
    ``narrow``: the config the candidates' runs start from."""
    current = np.array(poses, dtype=np.float64)
    runs: list[FfsResult] = []
    tried: set[tuple[int, ...]] = set()
    for _ in range(int(free.sum())):
        measured = depth(bodies, current, config)
        groups = [g for g in weak_groups(measured, free) if tuple(g) not in tried]
        if not groups:
            break
        candidate, found, more = best_candidate(bodies, current, groups[0], measured, narrow)
        runs += more
        # Deeper beyond rounding only (a candidate that settles where the map lies differs from
        # it by the sums' rounding, ~1e-12 relative).
        if found > measured.total * (1.0 + _ROUNDING):
            current = candidate
        else:
            tried.add(tuple(groups[0]))
    return current, runs


def run_ffs_escaped(
    bodies: Bodies,
    poses: FloatArray,
    config: FfsConfig | None = None,
    fixed: BoolArray | None = None,
) -> FfsResult:
    """:func:`run_ffs_reseated`, then :func:`escape`; where a group moved, Algorithm 1 again
    from the narrow width with every body free, kept only if Eq. 5 over every point finds the
    map deeper than the rounds left it (module doc). Every run's iterations are counted."""
    config = config or FfsConfig()
    started = time.perf_counter()
    free = np.ones(len(poses), dtype=bool) if fixed is None else ~np.asarray(fixed, dtype=bool)
    result = run_ffs_reseated(bodies, poses, config, fixed)
    narrow = dataclasses.replace(config, sigma_start=min(_WIDTH, config.sigma_start))
    moved, runs = escape(bodies, result.poses, free, config, narrow)
    if not np.array_equal(moved, result.poses):
        again = run_ffs_far(bodies, moved, narrow, fixed)
        runs.append(again)
        if depth(bodies, again.poses, config).total > depth(bodies, result.poses, config).total:
            result = dataclasses.replace(result, poses=again.poses, converged=again.converged)
    return dataclasses.replace(
        result,
        potentials=result.potentials + [p for run in runs for p in run.potentials],
        relocations=result.relocations + [r for run in runs for r in run.relocations],
        iterations=result.iterations + sum(run.iterations for run in runs),
        seconds=time.perf_counter() - started,
    )
