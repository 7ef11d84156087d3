"""The ``ffs`` merging method: the joint graph places every robot's keyframes
(:func:`merge_joint`, FFS Sec. 3.7's pre-alignment, found with no pose information), then
Force Field Simulation moves every merged keyframe at once to where the walls of all robots
agree best. The reference robot's keyframes, taken together, hold the ``map`` frame: after
the simulation the whole map is moved back so that their rigid fit is unchanged.

Updates are warm-started from the last where that is what the last one left to do (issue 14
item 4; :class:`FfsState` in the result's ``refinement``):
- a simulation cut short (by ``time_budget`` or ``max_iterations``) leaves the joint graph's
  placement in the result (its bodies are mid-anneal, not a map), and goes on cooling where it
  stopped, every keyframe starting where it left it relative to the joint graph's placement,
  in its own frame (a new keyframe takes the correction of its robot's nearest older one), as
  long as the same robots are merged: FFS bounded in time per update settles across updates;
- a settled simulation with the joint graph's placement unchanged (nothing new, a retry)
  settles again at once, where it was;
- otherwise FFS starts afresh from the joint graph's placement. Annealing again from the last
  result instead (measured, ``bench/merge_growth.py --method ffs``) walks further along the
  field's own bias at every update: on intel's 4 robots the keyframes ended 0.039 m from the
  reference against 0.020 m started afresh."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.ffs.bodies import facing_sensor, make_bodies
from multi_robot_mapper.core.merging.ffs.simulation import ChainSprings, FfsResult, run_ffs
from multi_robot_mapper.core.merging.joint import merge_joint
from multi_robot_mapper.core.merging.link_graph import MergeResult

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass(frozen=True)
class FfsState:
    """What one FFS refinement leaves to the next update (its warm start): per merged robot,
    its keyframes' indices and ``T_map_keyframe`` before FFS (the joint graph's) and after,
    where the cooling stopped and whether it settled."""

    keyframes: dict[str, IntArray]
    T_map_before: dict[str, FloatArray]  # (K, 3) each
    T_map_after: dict[str, FloatArray]
    sigma: float
    dt: float
    settled: bool


def merge_ffs(
    keyframes: Mapping[str, Sequence[Keyframe]],
    config: MergeConfig | None = None,
    previous: MergeResult | None = None,
    *,
    budget: float | None = None,
) -> MergeResult:
    """:func:`merge_joint`, then FFS over every merged keyframe (module doc). The result's
    ``stats`` add ``ffs_iterations`` and ``ffs_converged``, its ``timings`` ``ffs_s``.
    ``budget`` 0 (no time limit, offline) lifts FFS's ``time_budget`` too: it runs until it
    settles or ``max_iterations``."""
    config = config if config is not None else MergeConfig()
    joint = merge_joint(keyframes, config, previous=previous, budget=budget)
    if budget == 0.0:
        config = dataclasses.replace(config, ffs=dataclasses.replace(config.ffs, time_budget=0.0))
    state = None if previous is None else previous.refinement
    return refine_with_ffs(joint, config, state if isinstance(state, FfsState) else None)


def refine_with_ffs(
    result: MergeResult, config: MergeConfig, previous: FfsState | None = None
) -> MergeResult:
    """The merge ``result`` with its keyframes moved by FFS: keyframe poses, the global map
    (each segment moves with the keyframe that owns it) and every robot's frames (by the
    rigid motion that best carries its keyframes to their new poses). ``previous``: the last
    update's state, to warm-start from (module doc); the result's ``refinement`` is this
    update's."""
    robots = [r for r in result.robots if len(result.keyframe_index.get(r, ())) > 0]
    if len(robots) == 0 or result.segment_keyframe is None:
        return result
    views = {robot: result.keyframe_maps(robot) for robot in robots}
    owners = [(robot, row) for robot in robots for row in range(len(views[robot]))]
    start = np.array([views[robot][row][1] for robot, row in owners], dtype=np.float64)
    ffs = config.ffs
    chunks = body_chunks(views, owners, ffs.body_length)
    segments = [views[robot][row][2] for robot, row in owners]
    body_start, segment_sets = body_segments(chunks, start, segments)
    bodies = make_bodies(segment_sets, ffs.spacing, ffs.roi_radius, ffs.roi_mass)
    springs = ChainSprings(body_start, robot_chain(chunks, owners), ffs.chain_stiffness)
    index = {robot: np.asarray(result.keyframe_index[robot], dtype=np.int64) for robot in robots}
    rows = robot_rows(owners)
    resume = None
    warm = body_start
    if previous is not None and _resumes(previous, index, start, rows):
        warm = warm_started(previous, owners, index, start)[[members[0] for members in chunks]]
        resume = (previous.sigma, previous.dt)
    simulated = run_ffs(bodies, warm, ffs, springs=springs, resume=resume)
    poses = moved_with_bodies(chunks, start, body_start, simulated.poses)
    poses = _regauged(poses, start, owners, result.reference)
    state = FfsState(
        index,
        {robot: start[rows[robot]] for robot in robots},
        {robot: poses[rows[robot]] for robot in robots},
        simulated.sigma,
        simulated.dt,
        simulated.converged,
    )
    if not simulated.converged:
        # Cut short, the bodies are mid-anneal: not a map (freiburg-079's 4 robots, FFS cut at
        # 2 iterations per update: keyframes 0.09 m from the reference, the graph's 0.01 m).
        # The joint graph's placement stands until the next updates finish the cooling.
        poses = start
    return dataclasses.replace(
        with_keyframes_moved(result, robots, owners, start, poses, simulated), refinement=state
    )


def robot_rows(owners: list[tuple[str, int]]) -> dict[str, list[int]]:
    """Each robot's rows of ``owners`` ((robot, row in its keyframe maps) per keyframe)."""
    rows: dict[str, list[int]] = {}
    for k, (robot, _) in enumerate(owners):
        rows.setdefault(robot, []).append(k)
    return rows


def _resumes(
    previous: FfsState,
    index: Mapping[str, IntArray],
    start: FloatArray,
    rows: Mapping[str, list[int]],
) -> bool:
    """Does this update continue ``previous`` (module doc): the same robots, and either its
    cooling was cut short or the joint graph's placement is unchanged?"""
    if set(previous.keyframes) != set(index):
        return False
    if not previous.settled:
        return True
    return all(
        np.array_equal(previous.keyframes[robot], mine)
        and np.allclose(previous.T_map_before[robot], start[rows[robot]], rtol=0.0, atol=1e-9)
        for robot, mine in index.items()
    )


def warm_started(
    previous: FfsState,
    owners: list[tuple[str, int]],
    index: Mapping[str, IntArray],
    start: FloatArray,
) -> FloatArray:
    """The keyframe poses ``start`` (the joint graph's, one per row of ``owners``), each
    corrected as the ``previous`` simulation corrected it (or its robot's nearest keyframe,
    by index, that it held), in its own frame: ``T_start . T_before^-1 . T_after``. Where the
    graph moved a robot as a whole since (a placement corrected, another reference), its
    keyframes keep their correction; a map-frame correction would turn about ``map``'s
    origin. A robot it did not hold keeps its poses."""
    warm = np.array(start, dtype=np.float64)
    rows_of = robot_rows(owners)
    for robot, mine in index.items():
        held = previous.keyframes.get(robot)
        if held is None or len(held) == 0:
            continue
        rows = rows_of[robot]
        # The nearest held keyframe by index: the one at or after, or the one before.
        after = np.clip(np.searchsorted(held, mine), 0, len(held) - 1)
        before = np.clip(after - 1, 0, len(held) - 1)
        nearest = np.where(np.abs(held[before] - mine) < np.abs(held[after] - mine), before, after)
        T_before_after = se2.between_each(
            previous.T_map_before[robot][nearest], previous.T_map_after[robot][nearest]
        )
        warm[rows] = se2.compose_each(start[rows], T_before_after)
    return warm


def body_segments(
    chunks: list[list[int]], start: FloatArray, segments: Sequence[FloatArray]
) -> tuple[FloatArray, list[FloatArray]]:
    """Each body's pose (its first keyframe's, from the keyframe poses ``start``) and its
    segments in its frame: its keyframes' own ``segments``, each at its keyframe's pose."""
    body_start = np.array([start[members[0]] for members in chunks])
    segment_sets = []
    for members, T_map_body in zip(chunks, se2.matrices_from_poses(body_start), strict=True):
        T_body_map = se2.invert(T_map_body)
        # Each keyframe's walls turned to face it (the face it saw), then into the body frame.
        parts = [
            se2.transform_segments(
                T_body_map @ se2.matrix_from_pose(*start[k]), facing_sensor(segments[k])
            )
            for k in members
        ]
        segment_sets.append(np.vstack(parts) if parts else np.zeros((0, 4)))
    return body_start, segment_sets


def moved_with_bodies(
    chunks: list[list[int]], start: FloatArray, body_start: FloatArray, body_poses: FloatArray
) -> FloatArray:
    """The keyframe poses ``start``, each moved as its body moved from ``body_start`` to
    ``body_poses``."""
    poses = np.array(start, dtype=np.float64)
    moved = se2.matrices_from_poses(body_poses)
    for members, T_new, T_old in zip(
        chunks, moved, se2.matrices_from_poses(body_start), strict=True
    ):
        T_motion = T_new @ se2.invert(T_old)
        for k in members:
            poses[k] = se2.pose_from_matrix(T_motion @ se2.matrix_from_pose(*start[k]))
    return poses


def body_chunks(
    views: Mapping[str, Sequence[tuple[int, FloatArray, FloatArray]]],
    owners: list[tuple[str, int]],
    body_length: float,
) -> list[list[int]]:
    """Rows of ``owners`` grouped into bodies: a robot's consecutive keyframes until they own
    ``body_length`` of wall (a short rest joins the robot's last body)."""
    chunks: list[list[int]] = []
    current: list[int] = []
    owned = 0.0
    for k, (robot, row) in enumerate(owners):
        if current and owners[current[0]][0] != robot:
            _close_chunk(chunks, current, owners)
            current, owned = [], 0.0
        segments = views[robot][row][2]
        current.append(k)
        owned += float(np.hypot(*(segments[:, 2:] - segments[:, :2]).T).sum())
        if owned >= body_length:
            chunks.append(current)
            current, owned = [], 0.0
    if current:
        _close_chunk(chunks, current, owners)
    return chunks


def robot_chain(chunks: list[list[int]], owners: list[tuple[str, int]]) -> NDArray[np.int64]:
    """(M, 2) pairs of consecutive bodies of the same robot (the springs of FFS's chain)."""
    robot = [owners[members[0]][0] for members in chunks]
    pairs = [(b, b + 1) for b in range(len(chunks) - 1) if robot[b] == robot[b + 1]]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def _close_chunk(chunks: list[list[int]], rest: list[int], owners: list[tuple[str, int]]) -> None:
    """A robot's last keyframes, short of a body's wall: into its previous body if it has one."""
    if chunks and owners[chunks[-1][0]][0] == owners[rest[0]][0]:
        chunks[-1].extend(rest)
    else:
        chunks.append(rest)


def _regauged(
    poses: FloatArray,
    start: FloatArray,
    owners: list[tuple[str, int]],
    reference: str | None,
) -> FloatArray:
    """The simulated poses moved so that the reference robot's keyframes keep their rigid fit
    (FFS fixes no body: the whole map may drift a little while it settles)."""
    rows = [k for k, (robot, _) in enumerate(owners) if robot == reference] or list(
        range(len(owners))
    )
    T_fix = se2.rigid_fit(poses[rows], start[rows])
    moved = se2.matrices_from_poses(poses)
    return np.array([se2.pose_from_matrix(T_fix @ T) for T in moved])


def with_keyframes_moved(
    result: MergeResult,
    robots: list[str],
    owners: list[tuple[str, int]],
    start: FloatArray,
    poses: FloatArray,
    simulated: FfsResult | None = None,
) -> MergeResult:
    """``result`` with the keyframes of ``owners`` (rows: (robot, row in its keyframe maps))
    moved from ``start`` to ``poses`` (both (K, 3) ``T_map_keyframe``): each segment with its
    keyframe, each robot frame by the rigid fit of its keyframes' motion; ``simulated``'s
    iterations and time added to the stats when given."""
    keyframe_poses = dict(result.keyframe_poses)
    frames = {robot: dict(pieces) for robot, pieces in result.frames.items()}
    placements = dict(result.placements)
    segments = result.segments.copy()
    assert result.segment_keyframe is not None
    rows_of = robot_rows(owners)
    for robot in robots:
        rows = rows_of[robot]
        keyframe_poses[robot] = poses[rows]
        # Every frame of the robot (its pieces) moves with the best fit of its keyframes.
        T_new_old = se2.rigid_fit(start[rows], poses[rows])
        for piece, pose in frames.get(robot, {}).items():
            frames[robot][piece] = se2.pose_from_matrix(T_new_old @ se2.matrix_from_pose(*pose))
        if placements.get(robot) is not None:
            placements[robot] = frames[robot].get(0, placements[robot])
        # Each segment moves with its keyframe: T_new . T_old^-1.
        mine = np.flatnonzero(result.segment_robot == result.robots.index(robot))
        index = result.keyframe_index[robot]
        row = np.searchsorted(index, np.asarray(result.segment_keyframe)[mine])
        local = se2.inverse_transform_segments_each(start[rows][row], segments[mine])
        segments[mine] = se2.transform_segments_each(poses[rows][row], local)
    stats = dict(result.stats)
    timings = dict(result.timings)
    if simulated is not None:
        stats.update(ffs_iterations=simulated.iterations, ffs_converged=int(simulated.converged))
        timings["ffs_s"] = simulated.seconds
        timings["total_s"] = timings.get("total_s", 0.0) + simulated.seconds
    return dataclasses.replace(
        result,
        keyframe_poses=keyframe_poses,
        frames=frames,
        placements=placements,
        segments=segments,
        stats=stats,
        timings=timings,
    )
