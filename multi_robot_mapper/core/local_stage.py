"""The local mapping stage of an offline run: one :class:`LocalMapper` per robot, exactly as
``robot_mapper`` runs it, every robot's scans in the order of their stamps, and what the replay
reports of it (``stats.json``)."""

from __future__ import annotations

import dataclasses
import heapq
import time
from collections.abc import Iterator, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.extraction import SegmentScan
from multi_robot_mapper.core.front_end import FrontEnd
from multi_robot_mapper.core.local_mapping import (
    Closure,
    Keyframe,
    KeyframeScan,
    LocalMapper,
    LocalMapperConfig,
)
from multi_robot_mapper.core.local_mapping.backend import Backend
from multi_robot_mapper.core.offline import OfflineMap, TimedLaserScan
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.snapshots import NewestPose, Timeline, all_anchors, newest_pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass
class _MappingTimes:
    mapping_s: float = 0.0
    errors: int = 0
    per_scan: list[float] = dataclasses.field(default_factory=list)


def _guarded(
    index: int, robot: str, items: Sequence[TimedLaserScan], front_end: FrontEnd
) -> Iterator[tuple[float, int, TimedLaserScan, SegmentScan, bool]]:
    """A robot's scans as its stream guard lets them through (:meth:`FrontEnd.scans`), each
    with its stamp and the robot's index, for merging robots in stamp order."""
    for item, segments, reset in front_end.scans(robot, items):
        yield item.stamp, index, item, segments, reset


def _map_in_time_order(
    recordings: Mapping[str, Sequence[TimedLaserScan]],
    front_end: FrontEnd,
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


def run_local(
    recordings: Mapping[str, Sequence[TimedLaserScan]],
    front_end: FrontEnd,
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
    front_end: FrontEnd,
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


def _closure_record(closure: Closure, scans: Sequence[KeyframeScan]) -> dict[str, object]:
    """A closure (or a heading across a loss) in ``stats.json``: its keyframes' stamps, the
    relative pose and the confidence."""
    return {
        "first_stamp": scans[closure.first].stamp,
        "second_stamp": scans[closure.second].stamp,
        "T_first_second": [round(v, 6) for v in closure.T_first_second],
        "confidence": round(closure.confidence, 4),
    }
