"""Two partial maps of about 100 segments each merged with no initial guess (issue 5).

From a CARMEN log (intel by default): the first ``--scans`` scans, placed at their reference
poses and fused (Amigoni Alg. 5) into two overlapping halves (scans ``[0, n/2 + o/2)`` and
``[n/2 - o/2, n)``), each kept to its ``--segments`` longest segments and expressed in its
own first scan's frame. ``merge`` recovers how the second robot's frame lies in the first's;
the known answer is the reference poses' relative transform.

    .venv/bin/python -m bench.merge_speed [--log intel] [--scans 160] [--overlap 40]
        [--segments 100] [--repeats 7]

Prints the median time per merge over the repeats (every repeat recomputes: no reuse), the
split of that time (pairs/INTEGRATE, tree, fusion) and the error against the reference.
Target: under 100 ms (the paper: 12.8 s for 108 x 103 segments on a 1 GHz Pentium III).

    .venv/bin/python -m bench.merge_speed --split 2 4 8 [--logs intel aces fhw csail] [--joint]

instead cuts each whole log into K contiguous runs (each starting ``--overlap`` scans before
its predecessor ends; every second scan), builds each run's partial map from its
reference-placed scans (fused, untrimmed) in its own first scan's frame, merges the K maps in
no particular order and prints robots merged, the worst placement error, the number of valid
links that are wrong (> 0.3 m from the reference) and the merge time. The maps are reference
maps, not local-mapping output: this measures merging alone.

    .venv/bin/python -m bench.merge_speed --split 8 --logs intel --joint --live 10

runs the joint merger as the node does while the maps grow (``live_joint``).

Both modes pass the scans' poses as the robots' viewpoints, as the node passes keyframe
poses, so links are also judged on free space; ``--no-views`` merges on segments alone.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import cProfile  # noqa: E402
import dataclasses  # noqa: E402
import pickle  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import (  # noqa: E402
    add_merge_overrides,
    apart,
    carmen_log,
    equal_runs,
    joint_cut,
    merge_config_of,
)
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.extraction import extract_scan  # noqa: E402
from multi_robot_mapper.core.extraction_config import ExtractionConfig  # noqa: E402
from multi_robot_mapper.core.fusion import fuse  # noqa: E402
from multi_robot_mapper.core.matching import IntegrateConfig  # noqa: E402
from multi_robot_mapper.core.matching.scoring import pair_tolerance  # noqa: E402
from multi_robot_mapper.core.merging import MergeConfig, MergeResult, longest, merge  # noqa: E402
from multi_robot_mapper.io.carmen import CarmenScan, carmen_scan_data, read_carmen  # noqa: E402


def partial_map(
    scans: list[CarmenScan], segments: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference-placed, fused, trimmed; returns (T_world_robot, map in the robot's frame,
    the scans' poses in the robot's frame: the viewpoints)."""
    world = np.zeros((0, 4))
    owner = np.zeros(0, dtype=np.int64)
    config = IntegrateConfig()
    for scan in scans:
        found = extract_scan(carmen_scan_data(scan), ExtractionConfig())[0].segments
        placed = se2.transform_segments(se2.matrix_from_pose(*scan.reference_pose), found)
        world, owner = fuse(
            world, owner, placed, np.zeros(len(placed), np.int64), pair_tolerance(config), 0.02
        )
    T_world_robot = se2.matrix_from_pose(*scans[0].reference_pose)
    T_robot_world = se2.invert(T_world_robot)
    own = se2.transform_segments(T_robot_world, longest(world, segments))
    poses = np.array([scan.reference_pose for scan in scans])
    views = np.column_stack(
        (
            se2.transform_points(T_robot_world, poses[:, :2]),
            se2.wrap_angle(poses[:, 2] - scans[0].reference_pose[2]),
        )
    )
    return T_world_robot, own, views


def split_runs(name: str, robots: int, overlap: int, use_views: bool, config: MergeConfig) -> None:
    """Merge a whole log cut into ``robots`` reference-placed partial maps; print one line."""
    path = carmen_log(name)
    if not path.is_file():
        print(f"{name}: skipped, {path} not found")
        return
    frames, maps, views = {}, {}, {}
    for k, whole_run in enumerate(equal_runs(list(read_carmen(path)), robots, overlap)):
        run = whole_run[::2]
        frames[f"robot{k}"], maps[f"robot{k}"], views[f"robot{k}"] = partial_map(run, 10**9)
    started = time.perf_counter()
    result = merge(maps, config, viewpoints=views if use_views else None)
    elapsed = time.perf_counter() - started
    worst = 0.0
    reference = result.reference
    assert reference is not None
    for robot, pose in result.placements.items():
        if pose is None:
            continue
        truth = se2.invert(frames[reference]) @ frames[robot]
        dx, dy, _ = se2.pose_from_matrix(se2.invert(truth) @ se2.matrix_from_pose(*pose))
        worst = max(worst, float(np.hypot(dx, dy)))
    wrong = 0
    for (a, b), record in result.pairs.items():
        if record.link.valid:
            truth = se2.invert(frames[a]) @ frames[b]
            dx, dy, _ = se2.pose_from_matrix(se2.invert(truth) @ record.link.matrix)
            wrong += bool(np.hypot(dx, dy) > 0.3)
    merged = sum(pose is not None for pose in result.placements.values())
    sizes = [len(m) for m in maps.values()]
    print(
        f"{name:6s} {robots} robots: merged {merged}/{robots}, worst error {worst * 100:.1f} cm, "
        f"valid links {result.stats['links_valid']}/{len(result.pairs)} (wrong {wrong}), "
        f"merge {elapsed:.1f} s, map sizes {min(sizes)}-{max(sizes)} segments, "
        f"overlapping {overlapping(frames, maps, config.pairwise.link_min_value)}/{robots}"
    )


def split_joint(name: str, robots: int, overlap: int, config: MergeConfig) -> None:
    """``split_runs`` for the joint merger: each run's keyframes built at the reference poses,
    merged with ``merge_joint`` (every place matched); one line: robots placed, worst
    placement error, worst keyframe error in ``map``, links in the graph and how many are
    wrong (> 0.30 m or 5 deg from the reference), merge time, the time of an update with
    nothing new, of one bringing every robot's newest keyframe (every place matched) and the
    slowest of three live updates (one robot's newest keyframe, the node's update_budget;
    issue 13: <= 1 s with 8 robots of 100 keyframes) and the part of it that is not place
    matching (consistency, graph, fusion: what the budget cannot bound), keyframes."""
    from multi_robot_mapper.core.merging.joint import merge_joint

    path = carmen_log(name)
    if not path.is_file():
        print(f"{name}: skipped, {path} not found")
        return
    frames, keyframes = joint_cut(list(read_carmen(path)), robots, overlap)
    world = {}
    for robot in keyframes:
        world[robot] = {
            kf.index: frames[robot] @ se2.matrix_from_pose(*kf.T_robotmap_keyframe)
            for kf in keyframes[robot]
        }
    started = time.perf_counter()
    result = merge_joint(keyframes, config, budget=0.0)
    elapsed = time.perf_counter() - started
    # Updates as a live merger makes them (one core, every new place matched): nothing
    # changed, and every robot's newest keyframe arriving on the merge of all the others.
    started = time.perf_counter()
    merge_joint(keyframes, config, previous=result, budget=0.0)
    update_same = time.perf_counter() - started
    before = merge_joint({r: k[:-1] for r, k in keyframes.items()}, config, budget=0.0)
    started = time.perf_counter()
    merge_joint(keyframes, config, previous=before, budget=0.0)
    update_new = time.perf_counter() - started
    # The usual live update: one robot's newest keyframe, place matching within the node's
    # update_budget (the first, a middle and the last robot in turn; the slowest reported).
    # The update before it is one the node made too (with nothing new): the matching budget
    # is what the rest of the last update left.
    update_live, update_floor = 0.0, 0.0
    names = sorted(keyframes)
    for robot in {names[0], names[len(names) // 2], names[-1]}:
        trimmed = {r: (k[:-1] if r == robot else k) for r, k in keyframes.items()}
        before = merge_joint(trimmed, config, budget=0.0)
        before = merge_joint(trimmed, config, previous=before)
        started = time.perf_counter()
        live = merge_joint(keyframes, config, previous=before)
        elapsed_live = time.perf_counter() - started
        if elapsed_live > update_live:
            update_live = elapsed_live
            update_floor = live.timings["total_s"] - live.timings["matching_s"]
    assert result.reference is not None
    T_map_world = se2.invert(frames[result.reference])
    worst, worst_keyframe = worst_placement(result, frames), 0.0
    for robot, pose in result.placements.items():
        if pose is None:
            continue
        for index, placed in zip(
            result.keyframe_index[robot], result.keyframe_poses[robot], strict=True
        ):
            gap = (T_map_world @ world[robot][int(index)])[:2, 2] - placed[:2]
            worst_keyframe = max(worst_keyframe, float(np.hypot(*gap)))
    wrong = 0
    links = result.state.links if result.state is not None else []  # type: ignore[attr-defined]
    for link in links:
        truth = (
            se2.invert(world[link.target[0]][link.keyframe]) @ world[link.source[0]][link.centre]
        )
        wrong += apart(truth, se2.matrix_from_pose(*link.T_keyframe_centre))
    placed = sum(pose is not None for pose in result.placements.values())
    count = sum(len(k) for k in keyframes.values())
    print(
        f"| {name} | {robots} | {placed}/{robots} | {worst * 100:.1f} cm | "
        f"{worst_keyframe * 100:.1f} cm | {len(links)} | {wrong} | {elapsed:.1f} | "
        f"{update_same:.2f} | {update_new:.2f} | {update_live:.2f} ({update_floor:.2f}) | "
        f"{count} |",
        flush=True,
    )


def worst_placement(result: MergeResult, frames: dict[str, np.ndarray]) -> float:
    """Metres between each placed robot's map frame and where the reference puts it (the
    merge's reference robot's frame at its reference pose), the worst; 0 when none placed."""
    if result.reference is None:
        return 0.0
    T_map_world = se2.invert(frames[result.reference])
    worst = 0.0
    for robot, pose in result.placements.items():
        if pose is not None:
            truth = T_map_world @ frames[robot]
            dx, dy, _ = se2.pose_from_matrix(se2.invert(truth) @ se2.matrix_from_pose(*pose))
            worst = max(worst, float(np.hypot(dx, dy)))
    return worst


def live_joint(
    name: str,
    robots: int,
    overlap: int,
    config: MergeConfig,
    every: float,
    profile: str | None = None,
    grid: bool = False,
) -> None:
    """The node's regime on a reference-built cut: the robots drive at once (each run's time
    counted from its own first scan), and every ``every`` seconds the keyframes made so far
    are merged with the previous update within ``update_budget``; then updates with nothing
    new until no match and no verdict is pending. One line: updates, their time (median, 90th
    and 95th percentiles, largest), the largest part not spent matching, the updates until
    every robot was placed (and stayed so), robots placed at the end, keyframes; then the CPU
    seconds per update (median, p90, p95, max) and each stage's median time. ``profile``: a
    file for cProfile's statistics of every update (``python -m pstats FILE``). ``grid``: each
    update as ``map_merger``'s worker makes it, the global occupancy grid included
    (:func:`~multi_robot_mapper.core.merging.occupancy.merge_keeping_state`, the default
    ``grid.*``): its time is the stage "grid"."""

    path = carmen_log(name)
    if not path.is_file():
        print(f"{name}: skipped, {path} not found")
        return
    frames, keyframes = joint_cut(list(read_carmen(path)), robots, overlap)
    start = {robot: kfs[0].stamp for robot, kfs in keyframes.items()}
    stop = max(kfs[-1].stamp - start[robot] for robot, kfs in keyframes.items())
    times: list[float] = []
    cpus: list[float] = []  # CPU seconds per update: the figure to compare on a loaded machine
    stages: list[list[float]] = []
    rest = 0.0
    placed_since = None
    result = None
    clock = 0.0
    worst, off = 0.0, 0  # the worst placement of any update, the updates placing one > 0.30 m off
    profiler = cProfile.Profile() if profile else None
    kept: dict[str, Any] | None = {} if grid else None  # the worker's own dict
    while True:
        clock = min(clock + every, stop)
        shown = {
            robot: [kf for kf in kfs if kf.stamp - start[robot] <= clock]
            for robot, kfs in keyframes.items()
        }
        began, cpu = time.perf_counter(), time.process_time()
        if profiler is not None:
            profiler.enable()
        result = _live_update({r: f for r, f in shown.items() if f}, config, result, kept)
        if profiler is not None:
            profiler.disable()
        times.append(time.perf_counter() - began)
        cpus.append(time.process_time() - cpu)
        stages.append([result.timings[f"{stage}_s"] for stage in STAGES])
        stages[-1].append(times[-1] - result.timings["total_s"])  # the grid, when made
        rest = max(rest, result.timings["total_s"] - result.timings["matching_s"])
        error = worst_placement(result, frames)
        worst, off = max(worst, error), off + (error > 0.30)
        placed = sum(pose is not None for pose in result.placements.values())
        if placed < robots:
            placed_since = None
        elif placed_since is None:
            placed_since = len(times)
        if clock >= stop and not result.stats["matches_pending"] + result.stats["verdicts_pending"]:
            break
    if profiler is not None and profile:
        profiler.dump_stats(profile)
    spread = np.percentile(times, [50, 90, 95, 100])
    count = sum(len(k) for k in keyframes.values())
    print(
        f"| {name} | {robots} | {len(times)} | {spread[0]:.2f} | {spread[1]:.2f} | "
        f"{spread[2]:.2f} | {spread[3]:.2f} | {rest:.2f} | {placed_since or '-'} | "
        f"{placed}/{robots} | {count} |",
        flush=True,
    )
    print(
        "  CPU s per update (median, p90, p95, max): "
        + ", ".join(f"{v:.2f}" for v in np.percentile(cpus, [50, 90, 95, 100])),
        flush=True,
    )
    print(
        f"  placements of every update: worst {worst * 100:.1f} cm from the reference; "
        f"{off} of {len(times)} updates placed a robot more than 0.30 m off",
        flush=True,
    )
    assert result is not None
    light = dataclasses.replace(result, state=None)
    result = result if kept is None else dataclasses.replace(result, state=kept["state"])
    print(
        f"  the last result pickled: {len(pickle.dumps(result, protocol=5)) / 1e6:.1f} MB with "
        f"its state, {len(pickle.dumps(light, protocol=5)) / 1e6:.2f} MB without (what crosses "
        "map_merger's worker pipe each way since the worker keeps the state)",
        flush=True,
    )
    median = np.median(np.array(stages), axis=0)
    print(
        "  median per stage (s): "
        + ", ".join(f"{stage} {m:.3f}" for stage, m in zip((*STAGES, "grid"), median, strict=True)),
        flush=True,
    )


STAGES = ("matching", "consistency", "graph", "fusion")


def _live_update(
    keyframes: dict[str, list[Any]],
    config: MergeConfig,
    previous: MergeResult | None,
    kept: dict[str, Any] | None,
) -> MergeResult:
    """One update of :func:`live_joint`: ``merge_joint`` alone, or with ``kept`` (a worker's
    dict) the merge and its grid as ``map_merger``'s worker makes them."""
    from multi_robot_mapper.core.merging.joint import merge_joint
    from multi_robot_mapper.core.merging.occupancy import GridConfig, merge_keeping_state

    if kept is None:
        return merge_joint(keyframes, config, previous=previous)
    result, _ = merge_keeping_state(kept, keyframes, config, GridConfig(), previous)
    return result


def overlapping(frames: dict[str, np.ndarray], maps: dict[str, np.ndarray], shared: float) -> int:
    """The largest group of robots joined by pairs whose maps, placed at the truth, share at
    least ``shared`` metres of wall (within 10 cm): the most any merger could link."""
    from scipy.spatial import cKDTree

    from multi_robot_mapper.core.geometry import sample_segments

    step = 0.05
    points = {r: sample_segments(se2.transform_segments(frames[r], maps[r]), step)[0] for r in maps}
    trees = {r: cKDTree(p) for r, p in points.items()}
    group = {r: {r} for r in maps}
    names = sorted(maps)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            near = trees[b].query(points[a], distance_upper_bound=0.1)[0] < 0.1
            if near.sum() * step >= shared and group[a] is not group[b]:
                union = group[a] | group[b]
                for r in union:
                    group[r] = union
    return max(len(g) for g in group.values())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", default="intel")
    parser.add_argument("--scans", type=int, default=160)
    parser.add_argument("--overlap", type=int, default=40)
    parser.add_argument("--segments", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--split", type=int, nargs="*", default=[])
    parser.add_argument(
        "--joint",
        action="store_true",
        help="--split with the joint merger: keyframes built at the reference poses, merged "
        "in one graph; prints | log | robots | placed | worst placement | worst keyframe | "
        "links | wrong | merge (s) | update, nothing new (s) | "
        "update, a keyframe per robot (s) | update, one robot's keyframe, budget (s) "
        "(of which not matching) | "
        "keyframes |",
    )
    parser.add_argument(
        "--live",
        type=float,
        metavar="SECONDS",
        help="--split --joint in the node's regime: the robots at once, an update every "
        "SECONDS of their runs within update_budget; prints | log | robots | updates | "
        "median | p90 | max (s) | largest part not matching (s) | updates until all placed | "
        "placed | keyframes |",
    )
    parser.add_argument(
        "--profile", metavar="FILE", help="with --live: cProfile statistics of every update"
    )
    parser.add_argument(
        "--grid",
        action="store_true",
        help="with --live: each update as map_merger's worker makes it, with the global "
        "occupancy grid (its time: the stage 'grid')",
    )
    parser.add_argument("--logs", nargs="*", default=["intel", "aces", "fhw", "csail"])
    parser.add_argument(
        "--no-views",
        action="store_true",
        help="merge on segments alone, without the scans' poses as viewpoints (free space)",
    )
    add_merge_overrides(parser)
    args = parser.parse_args()
    base = merge_config_of(args)
    if args.split:
        for name in args.logs:
            for robots in args.split:
                if args.joint and args.live:
                    live_joint(name, robots, args.overlap, base, args.live, args.profile, args.grid)
                elif args.joint:
                    split_joint(name, robots, args.overlap, base)
                else:
                    split_runs(name, robots, args.overlap, not args.no_views, base)
        return
    path = carmen_log(args.log)
    if not path.is_file():
        print(f"skipped: {path} not found")
        return
    scans = []
    for scan in read_carmen(path):
        scans.append(scan)
        if len(scans) >= args.scans:
            break
    half, extra = len(scans) // 2, args.overlap // 2
    T_world_a, map_a, views_a = partial_map(scans[: half + extra], args.segments)
    T_world_b, map_b, views_b = partial_map(scans[half - extra :], args.segments)
    T_a_b = se2.invert(T_world_a) @ T_world_b
    maps = {"robot_a": map_a, "robot_b": map_b}
    # The scans' poses are the viewpoints, as keyframe poses are in the node (--no-views: none).
    views = None if args.no_views else {"robot_a": views_a, "robot_b": views_b}
    config = dataclasses.replace(base, reference="robot_a")
    times, cpu, parts = [], [], []
    result = merge(maps, config, viewpoints=views)
    for _ in range(args.repeats):
        started, started_cpu = time.perf_counter(), time.process_time()
        result = merge(maps, config, viewpoints=views)
        times.append(time.perf_counter() - started)
        cpu.append(time.process_time() - started_cpu)
        parts.append(result.timings)
    pose = result.placements["robot_b"]
    print(
        f"{args.log}: scans [0, {half + extra}) and [{half - extra}, {len(scans)}), "
        f"{len(map_a)} x {len(map_b)} segments, "
        f"{'without viewpoints' if views is None else 'free space from the scans poses'}"
    )
    if pose is None:
        print("robot_b unmerged: no valid link")
    else:
        dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_a_b) @ se2.matrix_from_pose(*pose))
        link = result.links[0]
        print(
            f"error vs reference: {np.hypot(dx, dy) * 100:.2f} cm, "
            f"{np.degrees(abs(dtheta)):.3f} deg (link value {link.value:.1f} m, "
            f"fraction {link.fraction:.2f})"
        )
    median = {k: float(np.median([p[k] for p in parts])) * 1e3 for k in parts[0]}
    print(
        f"merge: median {np.median(times) * 1e3:.1f} ms over {args.repeats} repeats "
        f"(min {min(times) * 1e3:.1f}, max {max(times) * 1e3:.1f}); pairs "
        f"{median['pairs_s']:.1f} ms, tree {median['tree_s']:.2f} ms, fusion "
        f"{median['fusion_s']:.1f} ms; global map {len(result.segments)} segments"
    )
    load = os.getloadavg()[0]
    print(f"CPU time per merge: median {np.median(cpu) * 1e3:.1f} ms (load average {load:.1f})")
    reuse = merge(maps, config, previous=result, viewpoints=views)
    print(
        f"re-run with previous (maps unchanged, pair reused): "
        f"{reuse.timings['total_s'] * 1e3:.1f} ms"
    )


if __name__ == "__main__":
    main()
