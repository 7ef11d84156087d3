"""The whole pipeline offline: every robot's scans in, a global segment map out.

``run_offline`` is what ``mrm replay`` runs, through the same stage functions the nodes call:
front end (scan -> segments), then a placement method. Methods:

- ``reference``: each scan placed at its reference (ground-truth) pose. A labelled tool for
  checking the evaluator and the pictures, never a mapping result.
- ``local``: odometry-free local mapping only (:class:`LocalMapper`, one per robot). Every
  robot's trajectory and partial map are in its own map frame and every robot frame is
  reported ``"unmerged"``: no placement between robots is claimed.
- ``pivot``: ``local``, then the robots' keyframes merged with no pose information in one
  graph (:func:`multi_robot_mapper.core.merging.joint.merge_joint`: places of each map
  searched on the others, consistent links only, every keyframe optimised together); a robot
  whose map was linked to no other stays ``"unmerged"``.
- ``ffs``: ``pivot``, then Force Field Simulation moves every merged keyframe at once
  (:func:`multi_robot_mapper.core.ffs.merge.merge_ffs`).
"""

from __future__ import annotations

import dataclasses
import heapq
import time
from collections.abc import Callable, Iterator, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import SegmentScan, extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import (
    Closure,
    Keyframe,
    KeyframeScan,
    LocalMapper,
    LocalMapperConfig,
)
from multi_robot_mapper.core.local_mapping.backend import Backend
from multi_robot_mapper.core.mapper_config import RobotMapperConfig
from multi_robot_mapper.core.merging import MergeConfig, MergeResult, merge
from multi_robot_mapper.core.merging.joint import JointState, place_scans
from multi_robot_mapper.core.merging.methods import MERGE_METHODS, merge_method
from multi_robot_mapper.core.scan import LaserScanData, ScanError
from multi_robot_mapper.core.scan_stream import ScanStreamConfig, ScanStreamGuard
from multi_robot_mapper.core.snapshots import (
    NewestPose,
    Snapshot,
    SnapshotSink,
    Timeline,
    all_anchors,
    newest_pose,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Pose = tuple[float, float, float]

METHODS = ("reference", "local", "pivot", "ffs")
IMPLEMENTED_METHODS = ("reference", "local", "pivot", "ffs")


class MethodNotImplementedError(NotImplementedError):
    """The requested placement method is not built yet."""


@dataclasses.dataclass(frozen=True)
class TimedLaserScan:
    """One scan of a robot's recording, with its reference pose when the recording has one."""

    stamp: float
    scan: LaserScanData
    reference_pose: Pose | None = None


@dataclasses.dataclass
class OfflineMap:
    """The pipeline's output, in the global ``map`` frame."""

    robots: list[str]
    map_segments: FloatArray  # (M, 4)
    segment_robot: IntArray  # (M,) index into robots
    trajectories: dict[str, tuple[FloatArray, FloatArray]]  # robot -> stamps (N,), poses (N, 3)
    robot_frames: dict[str, Pose | None]  # T_map_robotmap as (x, y, theta); None = unmerged
    stats: dict[str, object]
    # robot -> (K, 3) keyframe poses in the robot's own map frame (local mapping only)
    keyframe_poses: dict[str, FloatArray] = dataclasses.field(default_factory=dict)
    # robot -> every keyframe of every piece (pose in its piece's frame, segments in its own),
    # what the robot's partial_map carries (local mapping only)
    keyframes: dict[str, list[Keyframe]] = dataclasses.field(default_factory=dict)
    # robot -> every placed scan of every piece: stamps (N,), keyframe (N,), T_keyframe_scan
    # (N, 3) (LocalMapper.anchors; local mapping only)
    anchors: dict[str, tuple[FloatArray, IntArray, FloatArray]] = dataclasses.field(
        default_factory=dict
    )
    # robot -> the probability that its placement is right, and why an unmerged robot is not
    # placed (merging only)
    probabilities: dict[str, float] = dataclasses.field(default_factory=dict)
    unmerged_reasons: dict[str, str] = dataclasses.field(default_factory=dict)
    # robot -> its newest placed scan: T_piece_laser, the scan's stamp, the piece (local
    # mapping only)
    newest_poses: dict[str, NewestPose] = dataclasses.field(default_factory=dict)
    merge_result: MergeResult | None = None  # the merge itself (merging only)


# (stage, done, total): stage "mapping <robot>" with scans done of every robot's scans,
# then "merging" 0 of 1, 1 of 1.
Progress = Callable[[str, int, int], None]


@dataclasses.dataclass
class _FrontEnd:
    """Scans to segments for every placement method, each robot's stream checked by a
    :class:`ScanStreamGuard` as ``robot_mapper`` checks it, with the counts they all report."""

    extraction: ExtractionConfig
    stream: ScanStreamConfig
    progress: Progress | None
    total: int  # scans of every robot
    done: int = 0
    seconds: float = 0.0  # spent extracting
    # scans refused, by reason: ScanError kinds and the stream's rules (core.scan_stream)
    rejected: dict[str, int] = dataclasses.field(default_factory=dict)
    map_resets: int = 0  # a robot's map started over (its stamps jumped back and stayed)
    notices: list[str] = dataclasses.field(default_factory=list)  # e.g. a laser reconfigured

    def scans(
        self, robot: str, items: Sequence[TimedLaserScan], needs_reference: bool = False
    ) -> Iterator[tuple[TimedLaserScan, SegmentScan, bool]]:
        """Each usable scan of ``robot`` with its segments, in the order to map them, and
        whether the robot's map starts over before it; unusable ones are counted."""
        guard: ScanStreamGuard[tuple[TimedLaserScan, SegmentScan]] = ScanStreamGuard(self.stream)
        for item in items:
            self.step(robot)
            if needs_reference and item.reference_pose is None:
                continue
            started = time.perf_counter()
            try:
                segments, _ = extract_scan(item.scan, self.extraction)
            except ScanError as exc:
                self._refused(exc.kind)
                continue
            finally:
                self.seconds += time.perf_counter() - started
            verdict = guard.check(item.stamp, item.scan, (item, segments))
            for kind, _ in verdict.refused:
                self._refused(kind)
            self.notices += [f"{robot}: {notice}" for _, notice in verdict.notices]
            if not verdict.maps:
                continue
            reset = verdict.action == "reset"
            self.map_resets += reset
            for held in verdict.release:
                yield (*held.item, reset)
                reset = False
            yield item, segments, reset
        for kind, _ in guard.finish():
            self._refused(kind)

    def step(self, robot: str) -> None:
        self.done += 1
        if self.progress is not None:
            self.progress(f"mapping {robot}", self.done, self.total)

    def _refused(self, kind: str) -> None:
        self.rejected[kind] = self.rejected.get(kind, 0) + 1

    def counts(self) -> dict[str, object]:
        """The front end's part of ``stats.json``."""
        return {
            "scans_total": self.total,
            "scans_rejected": dict(self.rejected),
            "map_resets": self.map_resets,
            "stream_notices": list(self.notices),
            "front_end_s": round(self.seconds, 4),
        }


def require_method(method: str) -> None:
    """Raise unless ``method`` exists and is built (MethodNotImplementedError if not built yet)."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if method not in IMPLEMENTED_METHODS:
        raise MethodNotImplementedError(
            f"method '{method}' is not implemented yet (it arrives with the local-mapping and "
            f"merging issues); available: {', '.join(IMPLEMENTED_METHODS)}"
        )


def run_offline(
    recordings: Mapping[str, Sequence[TimedLaserScan]],
    method: str,
    extraction: ExtractionConfig,
    progress: Progress | None = None,
    local_mapping: LocalMapperConfig | None = None,
    merging: MergeConfig | None = None,
    snapshots: SnapshotSink | None = None,
    snapshot_period: float = 10.0,
    stream: ScanStreamConfig | None = None,
) -> OfflineMap:
    """Run the front end on every scan of every robot, then place them with ``method``.

    The robots' scans are mapped in the order of their stamps, as the robots would have sent
    them. With ``snapshots`` (a merging method), every ``snapshot_period`` s of bag time the
    keyframes so far are merged, as the merger node would have merged them (each merge an
    update of the previous one, every place matched), and handed to ``snapshots``; the last
    snapshot is the replay's own result, which is merged from scratch as without
    ``snapshots`` (the result never depends on whether snapshots were taken).
    ``recordings``: each robot's scans in the order they arrived (a node's subscription
    order), checked against their own stream by ``stream`` (default: the node's rules,
    ``RobotMapperConfig().stream_config()``) before anything is mapped."""
    require_method(method)
    total = sum(len(scans) for scans in recordings.values())
    front_end = _FrontEnd(
        extraction, stream or RobotMapperConfig().stream_config(), progress, total
    )
    if snapshots is not None and method not in MERGE_METHODS:
        raise ValueError(f"snapshots need a merging method ({', '.join(MERGE_METHODS)})")
    if method in ("local", "pivot", "ffs"):
        config = merging or MergeConfig()
        timeline = None
        if snapshots is not None:
            timeline = Timeline(snapshots, snapshot_period, method, config)
        local = _run_local(recordings, front_end, local_mapping or LocalMapperConfig(), timeline)
        if method == "local":
            return local
        if progress is not None:
            progress("merging", 0, 1)
        merged = _merged(local, config, method)
        if progress is not None:
            progress("merging", 1, 1)
        if snapshots is not None and merged.merge_result is not None:
            snapshots(final_snapshot(merged))
        return merged
    robots = sorted(recordings)
    segment_sets: list[FloatArray] = []
    owners: list[IntArray] = []
    trajectories: dict[str, tuple[FloatArray, FloatArray]] = {}
    started = time.perf_counter()
    for index, robot in enumerate(robots):
        stamps: list[float] = []
        poses: list[Pose] = []
        # 'reference' can only place scans that have a reference pose.
        # A reset changes nothing here: every scan is placed in the reference frame.
        for item, segments, _ in front_end.scans(robot, recordings[robot], needs_reference=True):
            assert item.reference_pose is not None
            T_map_laser = se2.matrix_from_pose(*item.reference_pose)
            segment_sets.append(se2.transform_segments(T_map_laser, segments.segments))
            owners.append(np.full(len(segments), index, dtype=np.int64))
            stamps.append(item.stamp)
            poses.append(item.reference_pose)
        trajectories[robot] = (
            np.asarray(stamps, dtype=np.float64),
            np.asarray(poses, dtype=np.float64).reshape(-1, 3),
        )
    map_segments = np.vstack(segment_sets) if segment_sets else np.zeros((0, 4))
    segment_robot = np.concatenate(owners) if owners else np.zeros(0, dtype=np.int64)
    posed = sum(len(t[0]) for t in trajectories.values())
    stats: dict[str, object] = {
        "method": method,
        "scans_posed": posed,
        "segments": len(map_segments),
        **front_end.counts(),
        "total_s": round(time.perf_counter() - started, 4),
    }
    # With reference poses every robot frame is the reference world frame.
    frames: dict[str, Pose | None] = {r: (0.0, 0.0, 0.0) for r in robots}
    return OfflineMap(robots, map_segments, segment_robot, trajectories, frames, stats)


def _closure_record(closure: Closure, scans: Sequence[KeyframeScan]) -> dict[str, object]:
    """A closure (or a heading across a loss) in ``stats.json``: its keyframes' stamps, the
    relative pose and the confidence."""
    return {
        "first_stamp": scans[closure.first].stamp,
        "second_stamp": scans[closure.second].stamp,
        "T_first_second": [round(v, 6) for v in closure.T_first_second],
        "confidence": round(closure.confidence, 4),
    }


def final_snapshot(merged: OfflineMap) -> Snapshot:
    """The last snapshot: a merging replay's own result."""
    assert merged.merge_result is not None
    placed = {r: t for r, t in merged.trajectories.items() if merged.robot_frames.get(r)}
    stamps = [p.stamp for p in merged.newest_poses.values()]
    stamps += [float(t[0][-1]) for t in merged.trajectories.values() if len(t[0])]
    stamp = max(stamps, default=0.0)
    return Snapshot(stamp, merged.merge_result, dict(merged.newest_poses), placed, final=True)


@dataclasses.dataclass
class _MappingTimes:
    mapping_s: float = 0.0
    errors: int = 0
    per_scan: list[float] = dataclasses.field(default_factory=list)


def _guarded(
    index: int, robot: str, items: Sequence[TimedLaserScan], front_end: _FrontEnd
) -> Iterator[tuple[float, int, TimedLaserScan, SegmentScan, bool]]:
    """A robot's scans as its stream guard lets them through (:meth:`_FrontEnd.scans`), each
    with its stamp and the robot's index, for merging robots in stamp order."""
    for item, segments, reset in front_end.scans(robot, items):
        yield item.stamp, index, item, segments, reset


def _map_in_time_order(
    recordings: Mapping[str, Sequence[TimedLaserScan]],
    front_end: _FrontEnd,
    config: LocalMapperConfig,
    timeline: Timeline | None,
) -> tuple[dict[str, LocalMapper], _MappingTimes]:
    """One :class:`LocalMapper` per robot fed its scans, every robot's scans in the order of
    their stamps (each robot's own in the order its stream guard lets them through); a robot
    whose stamps jumped back and stayed there starts a new, empty map, as the node does; the
    snapshots of ``timeline`` taken as bag time passes."""
    robots = sorted(recordings)
    mappers = {robot: LocalMapper(config) for robot in robots}
    times = _MappingTimes()
    streams = [
        _guarded(index, robot, recordings[robot], front_end) for index, robot in enumerate(robots)
    ]
    for stamp, index, item, segments, reset in heapq.merge(*streams, key=lambda e: e[:2]):
        robot = robots[index]
        if timeline is not None:
            timeline.before(stamp, mappers)
        if reset:
            mappers[robot] = LocalMapper(config)
        started = time.perf_counter()
        try:
            mappers[robot].add_scan(item.stamp, segments, item.scan)
        except Exception:  # as the node does: count it, keep the map built so far
            times.errors += 1
            continue
        finally:
            elapsed = time.perf_counter() - started
        times.mapping_s += elapsed
        times.per_scan.append(elapsed)
        if timeline is not None:
            timeline.mapped(stamp)
    return mappers, times


def _run_local(
    recordings: Mapping[str, Sequence[TimedLaserScan]],
    front_end: _FrontEnd,
    config: LocalMapperConfig,
    timeline: Timeline | None = None,
) -> OfflineMap:
    """One :class:`LocalMapper` per robot, exactly as ``robot_mapper`` runs it (with the back
    end in line, so that a replay is deterministic)."""
    robots = sorted(recordings)
    started = time.perf_counter()
    mappers, times = _map_in_time_order(recordings, front_end, config, timeline)
    segment_sets: list[FloatArray] = []
    owners: list[IntArray] = []
    trajectories: dict[str, tuple[FloatArray, FloatArray]] = {}
    keyframe_poses: dict[str, FloatArray] = {}
    all_keyframes: dict[str, list[Keyframe]] = {}
    anchors: dict[str, tuple[FloatArray, IntArray, FloatArray]] = {}
    newest_poses: dict[str, NewestPose] = {}
    per_robot: dict[str, dict[str, object]] = {}
    backend_times: list[float] = []
    optimise_times: list[float] = []
    for index, robot in enumerate(robots):
        mapper = mappers[robot]
        backend_times += mapper.backend_seconds
        optimise_times += mapper.optimise_seconds
        main = mapper.main_piece()
        backend = mapper.backend  # in line: this process's
        assert isinstance(backend, Backend)
        map_segments = backend.map.map_segments(piece=main)
        keyframes = [kf for kf in mapper.keyframes() if kf.piece == main]
        keyframe_poses[robot] = np.array(
            [kf.T_robotmap_keyframe for kf in keyframes], dtype=np.float64
        ).reshape(-1, 3)
        segment_sets.append(map_segments)
        owners.append(np.full(len(map_segments), index, dtype=np.int64))
        trajectories[robot] = mapper.trajectory(main)
        all_keyframes[robot] = mapper.keyframes()
        anchors[robot] = all_anchors(mapper)
        newest = newest_pose(mapper)
        if newest is not None:
            newest_poses[robot] = newest
        scans = backend.map.scans
        per_robot[robot] = {
            "scans_accepted": mapper.scans_accepted,
            "scans_set_aside": mapper.scans_set_aside,
            "scans_tracked": mapper.scans_tracked,
            "scans_placed_by": dict(mapper.scans_placed_by),
            "scans_in_main_piece": len(trajectories[robot][0]),
            "scans_held": mapper.scans_held,  # not placed yet when the scans ended (nor set aside)
            "set_aside_reasons": dict(mapper.set_aside_reasons),
            "pieces_started": mapper.pieces_started,
            "pieces_left": len(set(backend.map.pieces.tolist())),
            "keyframes": len(keyframes),
            "keyframes_all_pieces": len(scans),
            "map_segments": len(map_segments),
            "local_edges": backend.closer.local_edges,
            "motion_bounds": backend.closer.motion_bounds,
            "closures_accepted": len(mapper.closures),
            "closures_refused": dict(backend.closer.refused),
            "closures": [{"kind": c.kind, **_closure_record(c, scans)} for c in mapper.closures],
            # headings across losses (the front end's guess's heading; its position unused)
            "headings": [_closure_record(c, scans) for c in backend.closer.headings],
            "front_end_stage_s": {k: round(v, 4) for k, v in mapper.stage_seconds.items()},
        }

    def summary(values: list[float]) -> dict[str, float]:
        array = np.asarray(values) if values else np.zeros(1)
        return {
            "median_ms": round(float(np.median(array)) * 1e3, 3),
            "p95_ms": round(float(np.percentile(array, 95)) * 1e3, 3),
            "max_ms": round(float(array.max()) * 1e3, 3),
        }

    scan_times = summary(times.per_scan)
    stats: dict[str, object] = {
        "method": "local",
        "scans_posed": sum(len(t[0]) for t in trajectories.values()),
        "segments": int(sum(len(s) for s in segment_sets)),
        **front_end.counts(),
        "local_mapping_s": round(times.mapping_s, 4),
        "mapping_errors": times.errors,
        "local_mapping_median_ms": scan_times["median_ms"],
        "local_mapping_p95_ms": scan_times["p95_ms"],
        "backend_per_keyframe": summary(backend_times),
        "optimisation_per_keyframe": summary(optimise_times),
        "closures_accepted": sum(int(str(r["closures_accepted"])) for r in per_robot.values()),
        "robots": per_robot,
        "total_s": round(time.perf_counter() - started, 4),
    }
    if timeline is not None:  # merges while mapping: part of total_s, counted apart
        stats["snapshots"] = timeline.taken
        stats["snapshot_merges_s"] = round(timeline.merge_s, 4)
    frames: dict[str, Pose | None] = {r: None for r in robots}  # never claimed: "unmerged"
    return OfflineMap(
        robots,
        np.vstack(segment_sets) if segment_sets else np.zeros((0, 4)),
        np.concatenate(owners) if owners else np.zeros(0, dtype=np.int64),
        trajectories,
        frames,
        stats,
        keyframe_poses,
        all_keyframes,
        anchors,
        newest_poses=newest_poses,
    )


def _merged(local: OfflineMap, config: MergeConfig, method: str = "pivot") -> OfflineMap:
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
    stats = _merge_stats(local, result, time.perf_counter() - started, result.stats["links_valid"])
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
    # A robot's frame is its main piece's (local mapping's trajectory and map are in it).
    frames: dict[str, Pose | None] = {}
    trajectories = {}
    for robot, own in local.trajectories.items():
        frames[robot] = result.frames.get(robot, {}).get(_main_piece(local, robot))
        placed = None
        if frames[robot] is not None and robot in local.anchors:
            placed = place_scans(result, robot, local.anchors[robot])
        trajectories[robot] = own if placed is None else placed
    assert result.robots == local.robots
    stamp = {(r, kf.index): kf.stamp for r, frames in local.keyframes.items() for kf in frames}
    graph_links = result.state.links if isinstance(result.state, JointState) else []
    stats = _merge_stats(local, result, first_s, result.stats["links_accepted"])
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
    local: OfflineMap, result: MergeResult, seconds: float, links: int
) -> dict[str, object]:
    """The ``local`` run's stats with the merge's (``seconds`` it took, ``links`` it used)."""
    stats = dict(local.stats)
    stats.update(
        {
            "method": "pivot",
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
