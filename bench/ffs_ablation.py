"""FFS variants on the merger's own problem (issue 14): how far each variant of the simulation
moves the joint graph's placement, and where the field's own minimum lies.

    .venv/bin/python -m bench.ffs_ablation [--cases freiburg-079_2 intel_2 ...]
        [--variant "chain_stiffness=0" --variant "chain_stiffness=0.3 sigma_start=0.1" ...]
        [--from-reference] [--work bench_output/ffs_ablation] [--fresh]

Each case ``LOG_K`` is the log cut into K robots (``mrm import-carmen``; ``bag_NAME_K``: the shared
dense bag NAME, every scan, cut by ``mrm import-bag``; the bag cached under
``WORK/bags`` as ``bench/merge_table.py`` does), mapped by the local mapper and merged by the
joint graph once, both with the default configs (cached as ``WORK/CASE.pkl``; ``--fresh``
rebuilds it, as it must after a change to local mapping or merging). Then, for every
``--variant`` (``NAME=VALUE`` overrides of ``FfsConfig``, space-separated; ``time_budget`` is
0 unless given, so each run settles or reaches ``max_iterations``), FFS runs from the joint
graph's placement (``refine_with_ffs``). With ``--from-reference`` every merged keyframe starts
at its reference pose instead (rigidly aligned to the placement): FFS's own minimum on that
cut, apart from any merge's start.

Figure: ATE (m) of every scan of the merged robots against the reference after one rigid fit
of all of them (``mrm evaluate``'s ``ate_all_rmse_m`` where every robot is merged; it also
counts the unmerged robots, in their own frames), before FFS (the joint graph's, or the reference
placement's) and after, with FFS's iterations and seconds. Prints one Markdown table.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import (  # noqa: E402
    BAGS,
    CARMEN,
    OUTPUT,
    carmen_log,
    imported_bag,
    imported_dense_bag,
)
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.extraction_config import ExtractionConfig  # noqa: E402
from multi_robot_mapper.core.merging import MergeConfig, MergeResult  # noqa: E402
from multi_robot_mapper.core.merging.ffs.method import refine_with_ffs, with_keyframes_moved  # noqa: E402
from multi_robot_mapper.core.merging.joint import merge_joint, place_scans  # noqa: E402
from multi_robot_mapper.core.pipeline import OfflineMap, TimedLaserScan, run_offline  # noqa: E402

CASES = ("freiburg-079_2", "freiburg-079_4", "intel_2", "intel_4", "csail_2", "csail_4")
References = dict[str, tuple[np.ndarray, np.ndarray]]  # robot -> (stamps, (N, 3) poses)


def prepared(case: str, work: Path, fresh: bool) -> tuple[OfflineMap, MergeResult, References]:
    """The case's local maps, joint merge and reference poses (cached under ``work``)."""
    cache = work / f"{case}.pkl"
    if cache.exists() and not fresh:
        with cache.open("rb") as f:
            loaded: tuple[OfflineMap, MergeResult, References] = pickle.load(f)
        return loaded
    from multi_robot_mapper.io.bags import read_recordings, reference_poses

    log, robots = case.rsplit("_", 1)
    if log.startswith("bag_"):  # a shared dense bag, every scan
        bag = imported_dense_bag(log.removeprefix("bag_"), int(robots), work / "bags" / case)
    else:
        bag = imported_bag(log, int(robots), work / "bags" / case)
    inputs: dict[str, list[TimedLaserScan]] = {}
    references: References = {}
    for name, recording in read_recordings(bag).items():
        stamps = np.array([s.stamp for s in recording.scans], dtype=np.float64)
        poses, found = reference_poses(recording, stamps)
        inputs[name] = [
            TimedLaserScan(s.stamp, s.scan, tuple(map(float, p)) if ok else None)
            for s, p, ok in zip(recording.scans, poses, found, strict=True)
        ]
        references[name] = (stamps[found], poses[found])
    local = run_offline(inputs, "local", ExtractionConfig())
    joint = merge_joint(local.keyframes, MergeConfig(), budget=0.0)
    with cache.open("wb") as f:
        pickle.dump((local, joint, references), f)
    return local, joint, references


def ate_all(result: MergeResult, local: OfflineMap, references: References) -> float:
    """RMSE (m) of every placed scan's position (the merged robots') after one rigid fit of all
    to the reference."""
    estimated, reference = [], []
    for robot in local.robots:
        anchors = local.anchors.get(robot)
        placed = None if anchors is None else place_scans(result, robot, anchors)
        if placed is None:
            continue
        stamps, poses = placed
        ref_stamps, ref_poses = references[robot]
        row = np.clip(np.searchsorted(ref_stamps, stamps), 0, len(ref_stamps) - 1)
        same = np.abs(ref_stamps[row] - stamps) < 1e-6
        estimated.append(poses[same, :2])
        reference.append(ref_poses[row[same], :2])
    if not estimated:
        return float("nan")  # no robot merged
    est, ref = np.vstack(estimated), np.vstack(reference)
    error = se2.transform_points(se2.fit_points(est, ref), est) - ref
    return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))


def at_reference(joint: MergeResult, local: OfflineMap, references: References) -> MergeResult:
    """``joint`` with every merged keyframe at its reference pose, rigidly aligned to the joint
    graph's placement (its segments moved with it)."""
    robots = [r for r in joint.robots if len(joint.keyframe_index.get(r, ())) > 0]
    if not robots:
        return joint
    owners, start, truth = [], [], []
    for robot in robots:
        stamp = {kf.index: kf.stamp for kf in local.keyframes[robot]}
        ref_stamps, ref_poses = references[robot]
        for row, index in enumerate(joint.keyframe_index[robot]):
            nearest = int(np.argmin(np.abs(ref_stamps - stamp[int(index)])))
            owners.append((robot, row))
            start.append(joint.keyframe_poses[robot][row])
            truth.append(ref_poses[nearest])
    start_poses, true_poses = np.array(start), np.array(truth)
    T_map_world = se2.fit_points(true_poses[:, :2], start_poses[:, :2])
    turn = float(np.arctan2(T_map_world[1, 0], T_map_world[0, 0]))
    placed = np.column_stack(
        [
            se2.transform_points(T_map_world, true_poses[:, :2]),
            se2.wrap_angle(true_poses[:, 2] + turn),
        ]
    )
    return with_keyframes_moved(joint, robots, owners, start_poses, placed)


def _present(log: str) -> bool:
    """Is the case's log there: a CARMEN log, or ``bag_NAME`` a shared dense bag?"""
    if log.startswith("bag_"):
        return (BAGS / f"{log.removeprefix('bag_')}.bag").is_file()
    return carmen_log(log).exists()


def variant_config(text: str) -> MergeConfig:
    """MergeConfig with the FFS overrides ``NAME=VALUE ...`` (time_budget 0 unless given)."""
    config = MergeConfig()
    overrides: dict[str, Any] = {"time_budget": 0.0}
    for item in text.split():
        name, _, value = item.partition("=")
        overrides[name] = type(getattr(config.ffs, name))(value)
    return dataclasses.replace(config, ffs=dataclasses.replace(config.ffs, **overrides))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES))
    parser.add_argument("--variant", action="append", default=None)
    parser.add_argument("--from-reference", action="store_true")
    parser.add_argument("--work", type=Path, default=OUTPUT / "ffs_ablation")
    parser.add_argument("--fresh", action="store_true")
    args = parser.parse_args()
    variants = args.variant or [""]
    args.work.mkdir(parents=True, exist_ok=True)
    start = "reference" if args.from_reference else "joint graph"
    print(
        f"| case | merged | FFS variant | ATE all at the {start} (m) | after FFS (m) | "
        "iterations | s |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for case in args.cases:
        if not _present(case.rsplit("_", 1)[0]):
            print(f"{case}: its log is not in {CARMEN} nor {BAGS}; skipped", file=sys.stderr)
            continue
        local, joint, references = prepared(case, args.work, args.fresh)
        if args.from_reference:
            joint = at_reference(joint, local, references)
        before = ate_all(joint, local, references)
        merged = sum(len(joint.keyframe_index.get(robot, ())) > 0 for robot in local.robots)
        for text in variants:
            started = time.perf_counter()
            refined = refine_with_ffs(joint, variant_config(text))
            seconds = time.perf_counter() - started
            after = ate_all(refined, local, references)
            print(
                f"| {case} | {merged}/{len(local.robots)} | {text or 'defaults'} | {before:.4f} | "
                f"{after:.4f} | "
                f"{refined.stats['ffs_iterations']} | {seconds:.1f} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
