"""Links between robots judged against the reference (issue 13): how well the link confidence
separates right from wrong links, and how many wrong links the joint merger accepts.

Each CARMEN log is cut into K robots (``mrm import-carmen``), each robot mapped alone by the
local mapper exactly as ``mrm replay --method local`` does (every piece of every robot kept:
what its ``partial_map`` carries), then merged by the joint merger. The merger never sees the
reference; this bench does: every keyframe's stamp has a reference pose, so every link
candidate ``T_keyframe_centre`` can be compared with the reference relative pose of its two
keyframes. A link is *right* within 0.30 m / 5 deg (the confidence's own tolerance).

    .venv/bin/python -m bench.link_bench prepare [--logs ...] [--robots 2 4 8]
        [--work bench_output/link_bench]     # local mapping, cached (slow: minutes per case)
    .venv/bin/python -m bench.link_bench links [--logs ...] [--robots 2 4 8] [--set N=V ...]
        [--json PATH] [--curve PATH.png]
    .venv/bin/python -m bench.link_bench updates [--logs ...] [--robots 2 4 8] [--every 30]
        # the node's regime: growing maps, one update per --every s of log, within the
        # update_budget; prints | case | keyframes | updates | median | p90 | max (s) | placed |
    .venv/bin/python -m bench.link_bench sources [--logs ...] [--robots 2 4 8] [--set N=V ...]
        # issue 14 item 3: for every place that could be found on another map, is a right
        # placement among the correlation's and among Wolter's shape matching's hypotheses
        # (shape_hypotheses, 4 unless --set), before verification

``links`` prints, over every candidate of every case: precision and recall of "confidence >=
t" and of "fit >= t" for a range of thresholds (the curve the ``link_confidence`` and
``link_fit`` defaults are chosen from), then per case the candidates, the links the merger
accepted and how many of them are wrong, the robots (pieces) merged and the merge time.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import CARMEN, OUTPUT, carmen_log, imported_bag  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.config import config_from_flat, parse_override  # noqa: E402
from multi_robot_mapper.core.extraction_config import ExtractionConfig  # noqa: E402
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE  # noqa: E402
from multi_robot_mapper.core.matching.scoring import pair_tolerance  # noqa: E402
from multi_robot_mapper.core.merging import MergeConfig  # noqa: E402
from multi_robot_mapper.core.pipeline import OfflineMap, TimedLaserScan, run_offline  # noqa: E402
from multi_robot_mapper.io.bags import read_recordings, reference_poses  # noqa: E402

LOGS = ("intel", "aces", "fhw", "csail", "freiburg-079")


def bag_of(name: str, robots: int, work: Path) -> Path:
    """The log cut into ``robots`` runs (imported once with ``mrm import-carmen``)."""
    return imported_bag(name, robots, work / "bags" / f"{name}_{robots}")


def prepare(name: str, robots: int, work: Path) -> Path:
    """Local mapping of one case, pickled with the reference poses of every scan."""
    out = work / "cases" / f"{name}_{robots}.pkl"
    if out.exists():
        return out
    recordings = read_recordings(bag_of(name, robots, work))
    inputs: dict[str, list[TimedLaserScan]] = {}
    reference: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for robot, rec in recordings.items():
        stamps = np.array([s.stamp for s in rec.scans], dtype=np.float64)
        poses, found = reference_poses(rec, stamps)
        inputs[robot] = [
            TimedLaserScan(s.stamp, s.scan, tuple(float(v) for v in p) if ok else None)  # type: ignore[arg-type]
            for s, p, ok in zip(rec.scans, poses, found, strict=True)
        ]
        reference[robot] = (stamps[found], np.asarray(poses)[found])
    started = time.perf_counter()
    local = run_offline(inputs, "local", ExtractionConfig())
    seconds = time.perf_counter() - started
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("wb") as file:
        pickle.dump({"local": local, "reference": reference, "seconds": seconds}, file)
    print(f"{name} {robots}: local mapping {seconds:.1f} s -> {out}", flush=True)
    return out


def load(name: str, robots: int, work: Path) -> tuple[OfflineMap, dict[str, Any]]:
    with (work / "cases" / f"{name}_{robots}.pkl").open("rb") as file:
        case = pickle.load(file)
    return case["local"], case["reference"]


class Truth:
    """Reference pose of every keyframe (by its stamp)."""

    def __init__(self, local: OfflineMap, reference: dict[str, Any]) -> None:
        self.poses: dict[tuple[str, int], np.ndarray] = {}
        for robot, frames in local.keyframes.items():
            stamps, poses = reference[robot]
            lookup = {float(s): p for s, p in zip(stamps, poses, strict=True)}
            for kf in frames:
                pose = lookup.get(float(kf.stamp))
                if pose is not None:
                    self.poses[(robot, kf.index)] = se2.matrix_from_pose(*pose)

    def relative(self, a: tuple[str, int], b: tuple[str, int]) -> np.ndarray | None:
        """T_a_b by the reference (None when a keyframe has no reference pose)."""
        if a not in self.poses or b not in self.poses:
            return None
        return se2.invert(self.poses[a]) @ self.poses[b]

    def error(self, a: tuple[str, int], b: tuple[str, int], T_a_b: tuple) -> tuple[float, float]:
        """Translation (m) and rotation (rad) error of a relative pose against the reference."""
        truth = self.relative(a, b)
        if truth is None:
            return (np.nan, np.nan)
        dx, dy, dt = se2.pose_from_matrix(se2.invert(truth) @ se2.matrix_from_pose(*T_a_b))
        return float(np.hypot(dx, dy)), abs(float(dt))


def right(error: tuple[float, float]) -> bool:
    return bool(error[0] < RIGHT_DISTANCE and error[1] < RIGHT_ANGLE)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("step", choices=("prepare", "links", "updates", "sources"))
    parser.add_argument(
        "--every", type=float, default=30.0, help="updates: seconds of log between updates"
    )
    parser.add_argument("--logs", nargs="+", default=list(LOGS))
    parser.add_argument("--robots", nargs="+", type=int, default=[2, 4, 8])
    parser.add_argument("--work", type=Path, default=OUTPUT / "link_bench")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--curve", type=Path, default=None)
    args = parser.parse_args()
    cases = [(name, k) for name in args.logs for k in args.robots]
    missing = [name for name in args.logs if not carmen_log(name).exists()]
    if missing:
        print(f"note: skipping {', '.join(missing)} (no log in {CARMEN})", file=sys.stderr)
        cases = [(n, k) for n, k in cases if n not in missing]
    if args.step == "prepare":
        for name, k in cases:
            prepare(name, k, args.work)
        return 0
    overrides = dict(parse_override(item) for item in args.set)
    config = config_from_flat(MergeConfig, overrides)
    if args.step == "updates":
        updates(cases, args, config)
    elif args.step == "sources":
        sources(cases, args, config)
    else:
        report(cases, args, config)
    return 0


def updates(cases: list[tuple[str, int]], args: argparse.Namespace, config: MergeConfig) -> None:
    """The node's regime: every ``--every`` seconds of log, the keyframes made so far (at
    their final poses in their pieces) merged with the previous update, place matching within
    ``update_budget``; then updates with nothing new until no match or verdict is pending. Per
    case: the updates' times (median, 90th percentile, largest), their count, and what the
    last placed."""
    from multi_robot_mapper.core.merging.joint import merge_joint

    for name, k in cases:
        if not (args.work / "cases" / f"{name}_{k}.pkl").exists():
            print(f"note: {name} {k} not prepared (run the prepare step)", file=sys.stderr)
            continue
        local, _ = load(name, k, args.work)
        stamps = [kf.stamp for frames in local.keyframes.values() for kf in frames]
        start, stop = min(stamps), max(stamps)
        times: list[float] = []
        result = None
        clock = start
        while True:
            clock = min(clock + args.every, stop)
            shown = {
                robot: [kf for kf in frames if kf.stamp <= clock]
                for robot, frames in local.keyframes.items()
            }
            shown = {robot: frames for robot, frames in shown.items() if frames}
            began = time.perf_counter()
            result = merge_joint(shown, config, previous=result)
            times.append(time.perf_counter() - began)
            if (
                clock >= stop
                and not result.stats["matches_pending"] + result.stats["verdicts_pending"]
            ):
                break
        keyframes = sum(len(frames) for frames in local.keyframes.values())
        spread = np.percentile(times, [50, 90, 100])
        placed = sum(p is not None for p in result.placements.values())
        print(
            f"| {name}_{k} | {keyframes} | {len(times)} | {spread[0]:.2f} | {spread[1]:.2f} | "
            f"{spread[2]:.2f} | {placed}/{k} |",
            flush=True,
        )


THRESHOLDS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99)


def curve(rows: list[dict[str, Any]], key: str) -> list[tuple[float, int, int, float, float]]:
    """(threshold, accepted, wrong accepted, precision, recall) of "key >= threshold"."""
    right = sum(r["right"] for r in rows)
    out = []
    for t in THRESHOLDS:
        taken = [r for r in rows if r[key] >= t]
        good = sum(r["right"] for r in taken)
        precision = good / len(taken) if taken else float("nan")
        out.append((t, len(taken), len(taken) - good, precision, good / right if right else 0.0))
    return out


def any_right(rows: np.ndarray, centre: int, robot: str, unit: Any, truth: Truth) -> bool:
    """Is any placement (rows theta, x, y of keyframe ``centre`` of ``robot`` in ``unit``'s
    frame) right by the reference, judged from the unit's keyframe nearest to it?"""
    for theta, x, y in rows:
        T_unit_centre = se2.matrix_from_pose(x, y, theta)
        r = int(np.argmin(np.hypot(*(unit.poses[:, :2] - [x, y]).T)))
        T_keyframe_centre = se2.invert(se2.matrix_from_pose(*unit.poses[r])) @ T_unit_centre
        error = truth.error(
            (unit.robot, int(unit.index[r])),
            (robot, centre),
            se2.pose_from_matrix(T_keyframe_centre),
        )
        if right(error):
            return True
    return False


def sources(cases: list[tuple[str, int]], args: argparse.Namespace, config: MergeConfig) -> None:
    """Where each source of placements puts each place before verification (issue 14 item 3):
    for every place of every map searched on every other map, is a right placement among the
    map correlation's ``link_hypotheses`` and among the shape matching's ``shape_hypotheses``
    (4 unless ``--set`` gives it)? Counted over the places whose centre lies within
    ``place_spacing`` of the other map's keyframes at the reference (a place that could be
    found there)."""
    from multi_robot_mapper.core.merging.place_links import Target, placement_hypotheses
    from multi_robot_mapper.core.merging.places import places_of, units_of

    if not config.shape_hypotheses:
        config = dataclasses.replace(config, shape_hypotheses=4)
    print(
        "| case | places that could be found | right among correlation's | right among shape's "
        "| right among either | right only among shape's | shape (ms per place, median) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, k in cases:
        local, reference = load(name, k, args.work)
        truth = Truth(local, reference)
        units = units_of(local.keyframes)
        counts = np.zeros(5, dtype=int)
        times: list[float] = []
        for source in units.values():
            places = places_of(source, config)
            for target_unit in units.values():
                if target_unit.robot == source.robot:
                    continue
                target = Target.of(target_unit, config)
                found_at = [truth.poses.get((target_unit.robot, int(i))) for i in target_unit.index]
                path = np.array([T[:2, 2] for T in found_at if T is not None]).reshape(-1, 2)
                for place in places:
                    centre = truth.poses.get((source.robot, place.centre))
                    if centre is None or not len(path):
                        continue
                    if np.min(np.hypot(*(path - centre[:2, 2]).T)) > config.place_spacing:
                        continue
                    started = time.perf_counter()
                    correlated, shaped = placement_hypotheses(place, target, config)
                    times.append(time.perf_counter() - started)

                    by_correlation = any_right(
                        correlated, place.centre, source.robot, target_unit, truth
                    )
                    by_shape = any_right(shaped, place.centre, source.robot, target_unit, truth)
                    counts += [
                        1,
                        by_correlation,
                        by_shape,
                        by_correlation or by_shape,
                        by_shape and not by_correlation,
                    ]
        print(
            f"| {name} {k} | {counts[0]} | {counts[1]} | {counts[2]} | {counts[3]} | {counts[4]} "
            f"| {1000 * float(np.median(times)) if times else float('nan'):.0f} |",
            flush=True,
        )


def overlapping_truth(local: OfflineMap, truth: Truth, minimum: float = 15.0) -> int:
    """The largest group of robots joined by pairs whose maps (every piece, at the reference
    poses of their keyframes) share at least ``minimum`` metres of wall: what any merger could
    link (as bench/merge_speed.py --split counts it)."""
    from multi_robot_mapper.core.matching import IntegrateConfig, score_pairs, transform_values

    maps = {}
    for robot, frames in local.keyframes.items():
        placed = [
            se2.transform_segments(truth.poses[(robot, kf.index)], np.asarray(kf.segments))
            for kf in frames
            if (robot, kf.index) in truth.poses and len(kf.segments)
        ]
        maps[robot] = np.vstack(placed) if placed else np.zeros((0, 4))
    robots = sorted(maps)
    parent = {r: r for r in robots}

    def root(r: str) -> str:
        while parent[r] != r:
            r = parent[r]
        return r

    config = IntegrateConfig()
    for i, a in enumerate(robots):
        for b in robots[i + 1 :]:
            if not len(maps[a]) or not len(maps[b]):
                continue
            scores = score_pairs(maps[a], maps[b], np.zeros((1, 3)), pair_tolerance(config))
            if float(transform_values(scores, 1)[0]) >= minimum:
                parent[root(b)] = root(a)
    sizes: dict[str, int] = {}
    for r in robots:
        sizes[root(r)] = sizes.get(root(r), 0) + 1
    return max(sizes.values(), default=0)


def report(cases: list[tuple[str, int]], args: argparse.Namespace, config: MergeConfig) -> None:
    from multi_robot_mapper.core.merging.joint import merge_joint

    rows: list[dict[str, Any]] = []
    table = []
    for name, k in cases:
        if not (args.work / "cases" / f"{name}_{k}.pkl").exists():
            print(f"note: {name} {k} not prepared (run the prepare step)", file=sys.stderr)
            continue
        local, reference = load(name, k, args.work)
        truth = Truth(local, reference)
        started = time.perf_counter()
        result = merge_joint(local.keyframes, config, budget=0)
        seconds = time.perf_counter() - started
        state = result.state
        for record in state.matches.values():
            for c in record.candidates:
                error = truth.error(
                    (c.target[0], c.keyframe), (c.source[0], c.centre), c.T_keyframe_centre
                )
                if np.isnan(error[0]):
                    continue
                rows.append(
                    {
                        "case": f"{name}_{k}",
                        "source": list(c.source),
                        "centre": c.centre,
                        "target": list(c.target),
                        "keyframe": c.keyframe,
                        "rank": c.rank,
                        "confidence": c.confidence,
                        "fit": c.fit,
                        "value": c.value,
                        "error_m": error[0],
                        "error_rad": error[1],
                        "right": right(error),
                    }
                )
        wrong = [
            c
            for c in state.links
            if not right(
                truth.error((c.target[0], c.keyframe), (c.source[0], c.centre), c.T_keyframe_centre)
            )
        ]
        merged_robots = sorted({robot for robot in result.keyframe_index})
        table.append(
            {
                "case": f"{name}_{k}",
                "robots": k,
                "robots_placed": len(merged_robots),
                "overlapping_truth": overlapping_truth(local, truth),
                "maps": result.stats["maps"],
                "maps_merged": result.stats["maps_merged"],
                "places": result.stats["places"],
                "place_matches": result.stats["place_matches"],
                "candidates": sum(len(r.candidates) for r in state.matches.values()),
                "links_accepted": len(state.links),
                "links_wrong": len(wrong),
                "pairs_breaking_cycles": result.stats["pairs_breaking_cycles"],
                "merge_s": seconds,
                "timings": result.timings,
            }
        )
        last = table[-1]
        print(
            f"{name} {k}: robots placed {last['robots_placed']}/{k} (overlapping at the truth "
            f"{last['overlapping_truth']}), maps {last['maps_merged']}/{last['maps']}, places "
            f"{last['places']}, candidates {last['candidates']}, links accepted "
            f"{last['links_accepted']} (wrong {last['links_wrong']}), merge {seconds:.1f} s",
            file=sys.stderr,
            flush=True,
        )
    for key in ("confidence", "fit"):
        for rank in (None, 0):
            chosen = [r for r in rows if rank is None or r["rank"] == rank]
            label = "all candidates" if rank is None else "best placements only"
            total = len(chosen)
            good = sum(r["right"] for r in chosen)
            print(f"\n{key} >= t, {label} ({total} candidates, {good} right):")
            print("| t | accepted | wrong | precision | recall |")
            print("| --- | --- | --- | --- | --- |")
            for t, n, bad, precision, recall in curve(chosen, key):
                print(f"| {t:.2f} | {n} | {bad} | {precision:.3f} | {recall:.3f} |")
    print(
        "\n| case | robots placed | overlapping (truth) | maps merged | places | place matches "
        "| candidates | links accepted | wrong | merge (s) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for row in table:
        print(
            f"| {row['case']} | {row['robots_placed']}/{row['robots']} | "
            f"{row['overlapping_truth']} | {row['maps_merged']}/{row['maps']} | {row['places']} "
            f"| {row['place_matches']} | {row['candidates']} | {row['links_accepted']} | "
            f"{row['links_wrong']} | {row['merge_s']:.1f} |"
        )
    out = args.json or args.work / "link_bench.json"
    out.write_text(json.dumps({"candidates": rows, "cases": table}, indent=1))
    print(f"-> {out}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
