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
  (:func:`multi_robot_mapper.core.merging.ffs.method.merge_ffs`).
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
from multi_robot_mapper.core.merge_stage import merged as merged_map
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.merging.methods import MERGE_METHODS
from multi_robot_mapper.core.offline import OfflineMap, TimedLaserScan
from multi_robot_mapper.core.scan import ScanError
from multi_robot_mapper.core.scan_stream import ScanStreamConfig, ScanStreamGuard
from multi_robot_mapper.core.se2 import Pose
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

# The replay's methods: the two that merge nothing, then the merging registry's (the one list
# of merging methods, core/merging/methods.py).
METHODS = ("reference", "local", *MERGE_METHODS)


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
    """Raise ValueError unless ``method`` is one of :data:`METHODS`."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")


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
    ``ScanStreamConfig()``) before anything is mapped."""
    require_method(method)
    total = sum(len(scans) for scans in recordings.values())
    front_end = _FrontEnd(extraction, stream or ScanStreamConfig(), progress, total)
    if snapshots is not None and method not in MERGE_METHODS:
        raise ValueError(f"snapshots need a merging method ({', '.join(MERGE_METHODS)})")
    if method == "local" or method in MERGE_METHODS:
        config = merging or MergeConfig()
        timeline = None
        if snapshots is not None:
            timeline = Timeline(snapshots, snapshot_period, method, config)
        local = _run_local(recordings, front_end, local_mapping or LocalMapperConfig(), timeline)
        if method == "local":
            return local
        return _merged_run(local, config, method, progress, snapshots)
    return _run_reference(recordings, front_end, method)


def _merged_run(
    local: OfflineMap,
    config: MergeConfig,
    method: str,
    progress: Progress | None,
    snapshots: SnapshotSink | None,
) -> OfflineMap:
    """The merging stage of ``run_offline`` on its ``local`` run, with its progress; the
    merged result handed to ``snapshots`` as the last snapshot."""
    if progress is not None:
        progress("merging", 0, 1)
    merged = merged_map(local, config, method)
    if progress is not None:
        progress("merging", 1, 1)
    if snapshots is not None and merged.merge_result is not None:
        snapshots(final_snapshot(merged))
    return merged


def _run_reference(
    recordings: Mapping[str, Sequence[TimedLaserScan]], front_end: _FrontEnd, method: str
) -> OfflineMap:
    """The ``reference`` method of ``run_offline``: every scan with a reference pose placed
    at it."""
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
    maps = _LocalMaps()
    for index, robot in enumerate(robots):
        maps.add(index, robot, mappers[robot])
    stats = _local_stats(maps, front_end, times, started, timeline)
    frames: dict[str, Pose | None] = {r: None for r in robots}  # never claimed: "unmerged"
    return OfflineMap(
        robots,
        np.vstack(maps.segment_sets) if maps.segment_sets else np.zeros((0, 4)),
        np.concatenate(maps.owners) if maps.owners else np.zeros(0, dtype=np.int64),
        maps.trajectories,
        frames,
        stats,
        maps.keyframe_poses,
        maps.all_keyframes,
        maps.anchors,
        newest_poses=maps.newest_poses,
    )


@dataclasses.dataclass
class _LocalMaps:
    """What a ``local`` run reports of each robot's :class:`LocalMapper`, robot after robot:
    its main piece's map, trajectory and keyframes, every keyframe and anchor, its newest
    pose, its counts and its back end's times."""

    segment_sets: list[FloatArray] = dataclasses.field(default_factory=list)
    owners: list[IntArray] = dataclasses.field(default_factory=list)
    trajectories: dict[str, tuple[FloatArray, FloatArray]] = dataclasses.field(default_factory=dict)
    keyframe_poses: dict[str, FloatArray] = dataclasses.field(default_factory=dict)
    all_keyframes: dict[str, list[Keyframe]] = dataclasses.field(default_factory=dict)
    anchors: dict[str, tuple[FloatArray, IntArray, FloatArray]] = dataclasses.field(
        default_factory=dict
    )
    newest_poses: dict[str, NewestPose] = dataclasses.field(default_factory=dict)
    per_robot: dict[str, dict[str, object]] = dataclasses.field(default_factory=dict)
    backend_times: list[float] = dataclasses.field(default_factory=list)
    optimise_times: list[float] = dataclasses.field(default_factory=list)

    def add(self, index: int, robot: str, mapper: LocalMapper) -> None:
        """Robot ``robot`` (the ``index``-th) mapped by ``mapper``."""
        self.backend_times += mapper.backend_seconds
        self.optimise_times += mapper.optimise_seconds
        main = mapper.main_piece()
        backend = mapper.backend  # in line: this process's
        assert isinstance(backend, Backend)
        map_segments = backend.map.map_segments(piece=main)
        keyframes = [kf for kf in mapper.keyframes() if kf.piece == main]
        self.keyframe_poses[robot] = np.array(
            [kf.T_robotmap_keyframe for kf in keyframes], dtype=np.float64
        ).reshape(-1, 3)
        self.segment_sets.append(map_segments)
        self.owners.append(np.full(len(map_segments), index, dtype=np.int64))
        self.trajectories[robot] = mapper.trajectory(main)
        self.all_keyframes[robot] = mapper.keyframes()
        self.anchors[robot] = all_anchors(mapper)
        newest = newest_pose(mapper)
        if newest is not None:
            self.newest_poses[robot] = newest
        self.per_robot[robot] = _robot_stats(
            mapper, backend, len(self.trajectories[robot][0]), len(keyframes), len(map_segments)
        )


def _robot_stats(
    mapper: LocalMapper, backend: Backend, in_main: int, keyframes: int, map_segments: int
) -> dict[str, object]:
    """One robot's part of a ``local`` run's ``stats.json``: its scans (``in_main`` in its
    main piece), pieces, keyframes (``keyframes`` in its main piece, whose map has
    ``map_segments`` segments), closures and the front end's time per stage."""
    scans = backend.map.scans
    return {
        "scans_accepted": mapper.scans_accepted,
        "scans_set_aside": mapper.scans_set_aside,
        "scans_tracked": mapper.scans_tracked,
        "scans_placed_by": dict(mapper.scans_placed_by),
        "scans_in_main_piece": in_main,
        "scans_held": mapper.scans_held,  # not placed yet when the scans ended (nor set aside)
        "set_aside_reasons": dict(mapper.set_aside_reasons),
        "pieces_started": mapper.pieces_started,
        "pieces_left": len(set(backend.map.pieces.tolist())),
        "keyframes": keyframes,
        "keyframes_all_pieces": len(scans),
        "map_segments": map_segments,
        "local_edges": backend.closer.local_edges,
        "motion_bounds": backend.closer.motion_bounds,
        "closures_accepted": len(mapper.closures),
        "closures_refused": dict(backend.closer.refused),
        "closures": [{"kind": c.kind, **_closure_record(c, scans)} for c in mapper.closures],
        # headings across losses (the front end's guess's heading; its position unused)
        "headings": [_closure_record(c, scans) for c in backend.closer.headings],
        "front_end_stage_s": {k: round(v, 4) for k, v in mapper.stage_seconds.items()},
    }


def _time_summary(values: list[float]) -> dict[str, float]:
    """Median, 95th percentile and maximum of ``values`` (s) in ms."""
    array = np.asarray(values) if values else np.zeros(1)
    return {
        "median_ms": round(float(np.median(array)) * 1e3, 3),
        "p95_ms": round(float(np.percentile(array, 95)) * 1e3, 3),
        "max_ms": round(float(array.max()) * 1e3, 3),
    }


def _local_stats(
    maps: _LocalMaps,
    front_end: _FrontEnd,
    times: _MappingTimes,
    started: float,
    timeline: Timeline | None,
) -> dict[str, object]:
    """A ``local`` run's ``stats.json`` (its mapping ``started`` then)."""
    scan_times = _time_summary(times.per_scan)
    stats: dict[str, object] = {
        "method": "local",
        "scans_posed": sum(len(t[0]) for t in maps.trajectories.values()),
        "segments": int(sum(len(s) for s in maps.segment_sets)),
        **front_end.counts(),
        "local_mapping_s": round(times.mapping_s, 4),
        "mapping_errors": times.errors,
        "local_mapping_median_ms": scan_times["median_ms"],
        "local_mapping_p95_ms": scan_times["p95_ms"],
        "backend_per_keyframe": _time_summary(maps.backend_times),
        "optimisation_per_keyframe": _time_summary(maps.optimise_times),
        "closures_accepted": sum(int(str(r["closures_accepted"])) for r in maps.per_robot.values()),
        "robots": maps.per_robot,
        "total_s": round(time.perf_counter() - started, 4),
    }
    if timeline is not None:  # merges while mapping: part of total_s, counted apart
        stats["snapshots"] = timeline.taken
        stats["snapshot_merges_s"] = round(timeline.merge_s, 4)
    return stats
