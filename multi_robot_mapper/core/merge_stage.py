"""The merging stage of an offline run: every robot's local map placed in one ``map`` frame
(the joint graph of their keyframes, :func:`~multi_robot_mapper.core.merging.joint.
merge_joint`, or FFS after it), each merged robot's scans placed through its keyframes, and
what the replay reports of it."""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging import MergeConfig, MergeResult, merge
from multi_robot_mapper.core.merging.joint import JointState, place_scans
from multi_robot_mapper.core.merging.methods import merge_method
from multi_robot_mapper.core.offline import OfflineMap
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def merged(local: OfflineMap, config: MergeConfig, method: str = "pivot") -> OfflineMap:
    """Place the robots of a ``local`` run in one ``map`` frame (the merging stage): the joint
    graph of every robot's keyframes (:func:`merge_joint`, every place matched), or, for maps
    without keyframes, every map moved as one rigid body (:func:`merge`)."""
    if local.keyframes:
        return _merged_joint(local, config, method)
    started = time.perf_counter()
    maps = {
        robot: local.map_segments[local.segment_robot == index]
        for index, robot in enumerate(local.robots)
    }
    result = merge(maps, config, viewpoints=local.keyframe_poses)
    trajectories = {}
    for robot, (stamps, poses) in local.trajectories.items():
        T_map_robot = result.matrix(robot)
        if T_map_robot is None or len(poses) == 0:
            trajectories[robot] = (stamps, poses)  # unmerged: still in its own frame
            continue
        turn = float(np.arctan2(T_map_robot[1, 0], T_map_robot[0, 0]))
        placed = np.column_stack(
            (se2.transform_points(T_map_robot, poses[:, :2]), se2.wrap_angle(poses[:, 2] + turn))
        )
        trajectories[robot] = (stamps, placed)
    # Both robot lists are sorted names: merge's owner indices are ours (asserted, not assumed).
    assert result.robots == local.robots
    segment_robot = np.asarray(result.segment_robot, dtype=np.int64)
    seconds = time.perf_counter() - started
    stats = _merge_stats(local, result, seconds, result.stats["links_valid"], method)
    return OfflineMap(
        local.robots,
        result.segments,
        segment_robot.reshape(-1),
        trajectories,
        dict(result.placements),
        stats,
        local.keyframe_poses,
        newest_poses=local.newest_poses,
        merge_result=result,
    )


def _merged_joint(local: OfflineMap, config: MergeConfig, method: str = "pivot") -> OfflineMap:
    """The joint merge of a ``local`` run: every place matched (no time budget), then one more
    update with nothing changed (what a merger pays per update once its matches are made).
    A merged robot's trajectory is every scan whose keyframe was merged, placed through its
    keyframe's optimised pose; an unmerged robot keeps its own frame. ``method``: 'pivot' or
    'ffs' (:data:`MERGE_METHODS`)."""
    merge_keyframes = merge_method(method)
    started = time.perf_counter()
    result = merge_keyframes(local.keyframes, config, budget=0.0)
    first_s = time.perf_counter() - started
    again = time.perf_counter()
    merge_keyframes(local.keyframes, config, previous=result, budget=0.0)
    update_s = time.perf_counter() - again
    frames, trajectories = _placed_trajectories(local, result)
    assert result.robots == local.robots
    stats = _joint_merge_stats(local, result, frames, (first_s, update_s), method)
    believed = {
        robot: result.frame_probabilities[robot][_main_piece(local, robot)]
        for robot in local.robots
        if frames.get(robot) is not None
    }
    reasons = {
        robot: result.unmerged_reasons.get(robot, "its main piece of map is not placed")
        for robot in local.robots
        if frames.get(robot) is None
    }
    stats["unmerged_reasons"] = reasons
    return OfflineMap(
        local.robots,
        result.segments,
        np.asarray(result.segment_robot, dtype=np.int64).reshape(-1),
        trajectories,
        frames,
        stats,
        local.keyframe_poses,
        local.keyframes,
        local.anchors,
        probabilities=believed,
        unmerged_reasons=reasons,
        newest_poses=local.newest_poses,
        merge_result=result,
    )


def _placed_trajectories(
    local: OfflineMap, result: MergeResult
) -> tuple[dict[str, Pose | None], dict[str, tuple[FloatArray, FloatArray]]]:
    """Each robot's frame in ``map`` (None: unmerged) and its trajectory: every scan whose
    keyframe was merged, placed through its keyframe's optimised pose; an unmerged robot's
    in its own frame."""
    # A robot's frame is its main piece's (local mapping's trajectory and map are in it).
    frames: dict[str, Pose | None] = {}
    trajectories = {}
    for robot, own in local.trajectories.items():
        frames[robot] = result.frames.get(robot, {}).get(_main_piece(local, robot))
        placed = None
        if frames[robot] is not None and robot in local.anchors:
            placed = place_scans(result, robot, local.anchors[robot])
        trajectories[robot] = own if placed is None else placed
    return frames, trajectories


def _joint_merge_stats(
    local: OfflineMap,
    result: MergeResult,
    frames: dict[str, Pose | None],
    seconds: tuple[float, float],
    method: str,
) -> dict[str, object]:
    """The ``local`` run's stats with the joint merge's by ``method`` (``seconds``: the first
    merge's and an update's with nothing changed): the robots unmerged, every link in the
    graph, the merge's timings and counts."""
    first_s, update_s = seconds
    stamp = {(r, kf.index): kf.stamp for r, frames in local.keyframes.items() for kf in frames}
    graph_links = result.state.links if isinstance(result.state, JointState) else []
    stats = _merge_stats(local, result, first_s, result.stats["links_accepted"], method)
    stats.update(
        {
            "robots_unmerged": [robot for robot in local.robots if frames.get(robot) is None],
            # Every link in the joint graph: keyframe (robot, stamp) a, keyframe b and T_a_b,
            # so that a bench holding the reference can judge each one.
            "merge_graph_links": [
                [
                    link.target[0],
                    stamp[(link.target[0], link.keyframe)],
                    link.source[0],
                    stamp[(link.source[0], link.centre)],
                    *(round(float(v), 5) for v in link.T_keyframe_centre),
                ]
                for link in graph_links
            ],
            "merge_update_s": round(update_s, 4),
            "merge_timings": {k: round(v, 4) for k, v in result.timings.items()},
            "merge_stats": dict(result.stats),
        }
    )
    return stats


def own_frame_map(offline: OfflineMap, robot: str) -> FloatArray:
    """(N, 4) ``robot``'s map in its own map frame (its main piece): a ``local`` run's map of
    it, or, after a merge (where an unmerged robot's segments are not in the global map), its
    main piece's keyframe segments placed at their keyframes' poses."""
    if offline.merge_result is None:
        mine: FloatArray = offline.map_segments[
            offline.segment_robot == offline.robots.index(robot)
        ]
        return mine
    main = _main_piece(offline, robot)
    placed = [
        se2.transform_segments(se2.matrix_from_pose(*kf.T_robotmap_keyframe), kf.segments)
        for kf in offline.keyframes.get(robot, [])
        if kf.piece == main and len(kf.segments)
    ]
    return np.vstack(placed) if placed else np.zeros((0, 4))


def _main_piece(local: OfflineMap, robot: str) -> int:
    """The piece of ``robot``'s map holding the most placed scans (ties: the oldest), as
    :meth:`LocalMapper.main_piece` chose it."""
    piece_of = {kf.index: kf.piece for kf in local.keyframes.get(robot, [])}
    anchors = local.anchors.get(robot)
    if anchors is None or not piece_of:
        return 0
    pieces = np.array([piece_of.get(int(k), -1) for k in anchors[1]], dtype=np.int64)
    found, counts = np.unique(pieces[pieces >= 0], return_counts=True)
    return int(found[np.argmax(counts)]) if len(found) else 0


def _merge_stats(
    local: OfflineMap, result: MergeResult, seconds: float, links: int, method: str
) -> dict[str, object]:
    """The ``local`` run's stats with the merge's by ``method`` (``seconds`` it took, ``links``
    it used)."""
    stats = dict(local.stats)
    stats.update(
        {
            "method": method,
            "segments": len(result.segments),
            "merge_reference": result.reference,
            "merge_links": [
                {"a": link.robot_a, "b": link.robot_b, "value": round(link.value, 3)}
                for link in result.links
            ],
            "merge_links_valid": links,
            "merge_pairs": len(result.pairs),
            "merge_s": round(seconds, 4),
            "robots_unmerged": result.unmerged,
        }
    )
    stats["total_s"] = round(float(str(stats["total_s"])) + seconds, 4)
    return stats
