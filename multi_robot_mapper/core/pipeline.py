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

The stages, each in its own module: the front end (``front_end.py``: scans to segments, each
robot's stream checked), the reference placement (``reference_stage.py``), local mapping
(``local_stage.py``) and merging (``merge_stage.py``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.front_end import FrontEnd, Progress
from multi_robot_mapper.core.local_mapping import LocalMapperConfig
from multi_robot_mapper.core.local_stage import run_local
from multi_robot_mapper.core.merge_stage import merged as merged_map
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.merging.methods import MERGE_METHODS
from multi_robot_mapper.core.offline import OfflineMap, TimedLaserScan
from multi_robot_mapper.core.reference_stage import run_reference
from multi_robot_mapper.core.scan_stream import ScanStreamConfig
from multi_robot_mapper.core.snapshots import Snapshot, SnapshotSink, Timeline

__all__ = ["METHODS", "OfflineMap", "Progress", "TimedLaserScan", "require_method", "run_offline"]

# The replay's methods: the two that merge nothing, then the merging registry's (the one list
# of merging methods, core/merging/methods.py).
METHODS = ("reference", "local", *MERGE_METHODS)


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
    if snapshots is not None and method not in MERGE_METHODS:
        raise ValueError(f"snapshots need a merging method ({', '.join(MERGE_METHODS)})")
    total = sum(len(scans) for scans in recordings.values())
    front_end = FrontEnd(extraction, stream or ScanStreamConfig(), progress, total)
    if method == "reference":
        return run_reference(recordings, front_end, method)
    config = merging or MergeConfig()
    timeline = None
    if snapshots is not None:
        timeline = Timeline(snapshots, snapshot_period, method, config)
    local = run_local(recordings, front_end, local_mapping or LocalMapperConfig(), timeline)
    if method == "local":
        return local
    return _merged_run(local, config, method, progress, snapshots)


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


def final_snapshot(merged: OfflineMap) -> Snapshot:
    """The last snapshot: a merging replay's own result."""
    assert merged.merge_result is not None
    placed = {r: t for r, t in merged.trajectories.items() if merged.robot_frames.get(r)}
    stamps = [p.stamp for p in merged.newest_poses.values()]
    stamps += [float(t[0][-1]) for t in merged.trajectories.values() if len(t[0])]
    stamp = max(stamps, default=0.0)
    return Snapshot(stamp, merged.merge_result, dict(merged.newest_poses), placed, final=True)
