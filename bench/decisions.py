"""The wrong-decision benchmark (issue 46): how often the merger publishes a robot placed
wrong, how many overlapping robots it merges, how soon, and how often local mapping accepts
a wrong closure or join -- over many scenarios, live and at the end.

    .venv/bin/python -m bench.decisions collect --source generated --first 0 --count 200
        [--maps truth own] [--updates 8] [--jobs 2] [--work bench_output/decisions]
    .venv/bin/python -m bench.decisions collect --source carmen --logs intel aces ...
        --robots 2 4 8 [--maps truth own]
    .venv/bin/python -m bench.decisions judge [--work ...] [--set NAME=VALUE ...]
    .venv/bin/python -m bench.decisions table [--work ...]

``collect`` builds each scenario (``bench/scenarios.py``), its robots' partial maps as they
grow (truth maps and/or own maps), and runs the merger as the node does (``merge_joint``,
``--updates`` updates evenly over the robots' time, each warm from the last; every place matched:
``budget`` 0, so that a result does not depend on this machine's speed). Each update's maps
and place matches are kept (``WORK/cases/NAME.pkl``), and each decision is judged against the
truth into ``WORK/records/NAME.json``. ``judge`` re-runs every kept update's decisions with
today's code from the kept place matches (no matching: minutes, not hours) and judges them
again: the way to try a decision rule. ``table`` prints the figures of every record.

What is counted (the truth is never seen by the merger):

- **placements**: every map (a robot's piece) the merger places in ``map`` at an update, and
  whether it is *wrong*: its published keyframes, put in ``world`` by the reference map's own
  (a rigid fit of the reference's keyframes to their true poses), lie more than 0.30 m or
  5 deg from their true poses (the median over its keyframes). On own maps this error holds
  the maps' drift too. *Ever*: every update's publication counts; *end*: the last update. A
  wrong placement that is the truth moved by the building's own symmetry (generated rotation
  wings: no map can tell the wings apart) is counted apart too.
- **merged**: of the robots in the largest group that overlap at the truth (``OVERLAP_WALL``
  of shared wall, ``bench/scenarios.py``), those whose main map is placed right at the end.
- **time to merge**: from the first update at which a robot overlaps the placed group at the
  truth to the first at which it is placed (s of the robots' time).
- **decisions**: every pair of maps' consistent set of links, with its evidence
  (``PairVerdict.evidence``) and whether its placement is right (the median over its links of
  the error of the placement at the linked keyframes): the data the join model is fitted on.
- **closures and joins** (own maps): every one the local mapper accepted, wrong beyond 0.30 m
  or 5 deg of the truth's relative pose of its two keyframes.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pickle  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from concurrent.futures.process import BrokenProcessPool  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import OUTPUT, RIGHT_ANGLE, RIGHT_DISTANCE  # noqa: E402
from bench.scenarios import (  # noqa: E402
    DENSE_BAGS,
    Scenario,
    TruthTable,
    bag_scenario,
    carmen_scenario,
    overlap_component,
    own_snapshots,
    truth_snapshots,
    update_times,
    world_scenario,
    world_walls,
)
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.config import config_from_flat, parse_override  # noqa: E402
from multi_robot_mapper.core.local_mapping import Keyframe  # noqa: E402
from multi_robot_mapper.core.merging import MergeConfig, MergeResult  # noqa: E402
from multi_robot_mapper.core.merging.consistency import PairVerdict, oriented, placement  # noqa: E402
from multi_robot_mapper.core.merging.joint import JointState, merge_joint  # noqa: E402
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey, units_of  # noqa: E402

# --- judging --------------------------------------------------------------------------------


@dataclasses.dataclass
class Truth:
    """Each map's keyframes' true poses in ``world``, by unit and keyframe index."""

    poses: dict[UnitKey, dict[int, np.ndarray]]  # 3x3 T_world_keyframe

    @staticmethod
    def of(scenario: TruthTable, units: dict[UnitKey, MapUnit]) -> Truth:
        poses: dict[UnitKey, dict[int, np.ndarray]] = {}
        for key, unit in units.items():
            world = scenario.truth_of(key[0], unit.stamps)
            poses[key] = {
                int(i): se2.matrix_from_pose(*p)
                for i, p in zip(unit.index, world, strict=True)
                if np.isfinite(p).all()  # a keyframe without a reference pose is not judged
            }
        return Truth(poses)


def _error(T_estimate: np.ndarray, T_truth: np.ndarray) -> tuple[float, float]:
    dx, dy, dt = se2.pose_from_matrix(se2.invert(T_truth) @ T_estimate)
    return math.hypot(dx, dy), abs(dt)


def _wrong(error: tuple[float, float]) -> bool:
    return error[0] > RIGHT_DISTANCE or error[1] > RIGHT_ANGLE


def judge_placements(
    result: MergeResult,
    units: dict[UnitKey, MapUnit],
    truth: Truth,
    symmetries: list[np.ndarray] | None = None,
) -> dict[str, dict[str, Any]]:
    """Every placed map's verdict (module doc): ``unit name -> {wrong, error_m, error_deg,
    ...}``. The published keyframes (their poses in ``map``) are put in ``world`` by the rigid
    fit of the reference map's own keyframes to their true poses; a map's error is the median
    over its keyframes of how far each lies from its true pose (and turned from it)."""
    placed: dict[UnitKey, dict[int, np.ndarray]] = {}
    for robot, index in result.keyframe_index.items():
        for i, pose in zip(index, result.keyframe_poses[robot], strict=True):
            for key in units:
                if key[0] == robot and int(i) in truth.poses[key]:
                    placed.setdefault(key, {})[int(i)] = np.asarray(pose, dtype=np.float64)
    ref = next((k for k in placed if k[0] == result.reference and k[1] == 0), None)
    out: dict[str, dict[str, Any]] = {}
    if ref is None or len(placed[ref]) < 2:
        return out
    ids = sorted(placed[ref])
    T_world_map = se2.rigid_fit(
        np.array([placed[ref][i] for i in ids]),
        np.array([se2.pose_from_matrix(truth.poses[ref][i]) for i in ids]),
    )
    for key, mine in placed.items():
        ids = sorted(mine)
        estimate = se2.matrices_from_poses(np.array([mine[i] for i in ids]))
        real = np.stack([truth.poses[key][i] for i in ids])
        moved = T_world_map[None] @ estimate
        distance = float(np.median(np.hypot(*(moved[:, :2, 2] - real[:, :2, 2]).T)))
        turn = np.arctan2(moved[:, 1, 0], moved[:, 0, 0]) - np.arctan2(real[:, 1, 0], real[:, 0, 0])
        angle = float(np.median(np.abs(se2.wrap_angle(turn))))
        wrong = _wrong((distance, angle))
        out[f"{key[0]}/{key[1]}"] = {
            "wrong": wrong,
            "judged": True,
            # placed where the building's own symmetry repeats what it saw (no map tells)
            "symmetry_image": wrong and _symmetry_image(result, key, units, truth, symmetries),
            "error_m": round(distance, 3),
            "error_deg": round(math.degrees(angle), 2),
            "keyframes": len(ids),
            "reference": key == ref,
        }
    return out


def _symmetry_image(
    result: MergeResult,
    key: UnitKey,
    units: dict[UnitKey, MapUnit],
    truth: Truth,
    symmetries: list[np.ndarray] | None,
) -> bool:
    """Is a wrong placement of map ``key`` the truth moved by one of the building's
    symmetries (relative to the reference's frame), within 0.30 m / 5 deg?"""
    if not symmetries or result.reference is None:
        return False
    world = _frames_in_world(units, truth)
    ref = (result.reference, 0)
    if ref not in world or key not in world:
        return False
    T_map_ref = se2.matrix_from_pose(*result.frames[ref[0]].get(0, (0.0, 0.0, 0.0)))
    T_world_map = world[ref] @ se2.invert(T_map_ref)
    placed = T_world_map @ se2.matrix_from_pose(*result.frames[key[0]][key[1]])
    middle = se2.matrix_from_pose(*units[key].poses[:, :2].mean(axis=0), 0.0)
    return any(not _wrong(_error(placed @ middle, S @ world[key] @ middle)) for S in symmetries)


def _frames_in_world(units: dict[UnitKey, MapUnit], truth: Truth) -> dict[UnitKey, np.ndarray]:
    """Each map's frame in ``world``: the rigid fit of its keyframes' true poses."""
    out = {}
    for key, unit in units.items():
        known = [r for r, i in enumerate(unit.index) if int(i) in truth.poses[key]]
        if len(known) >= 2:
            world = np.array(
                [se2.pose_from_matrix(truth.poses[key][int(unit.index[r])]) for r in known]
            )
            out[key] = se2.rigid_fit(unit.poses[known], world)
    return out


def judge_verdict(
    verdict: PairVerdict,
    units: dict[UnitKey, MapUnit],
    truth: Truth,
    symmetry: np.ndarray | None = None,
) -> tuple[float, float]:
    """The median error of a consistent set's placement at its linked keyframes (m, rad);
    with ``symmetry`` (a rigid motion of the building onto itself), against the truth of B
    moved by it."""
    S = np.eye(3) if symmetry is None else symmetry
    a, b = verdict.pair
    T_a_b = placement(verdict, a, units)
    errors = []
    for candidate in verdict.links:
        link = oriented(candidate, a)
        if link.k_first not in truth.poses[a] or link.k_second not in truth.poses[b]:
            continue  # no reference pose at one of its keyframes
        pa = se2.matrix_from_pose(*units[a].poses[units[a].row(link.k_first)])
        pb = se2.matrix_from_pose(*units[b].poses[units[b].row(link.k_second)])
        estimate = se2.invert(pa) @ T_a_b @ pb
        real = se2.invert(truth.poses[a][link.k_first]) @ S @ truth.poses[b][link.k_second]
        errors.append(_error(estimate, real))
    if not errors:
        return float("nan"), float("nan")
    return float(np.median([e[0] for e in errors])), float(np.median([e[1] for e in errors]))


def verdict_record(
    verdict: PairVerdict,
    units: dict[UnitKey, MapUnit],
    truth: Truth,
    symmetries: list[np.ndarray] | None = None,
) -> dict[str, Any]:
    """A pair's consistent set: its evidence and its truth (module doc); whether a wrong one
    is the truth moved by the building's own symmetry (no map can tell it from the truth)."""
    error = judge_verdict(verdict, units, truth)
    image = _wrong(error) and any(
        not _wrong(judge_verdict(verdict, units, truth, S)) for S in symmetries or []
    )
    record: dict[str, Any] = {
        "pair": [f"{k[0]}/{k[1]}" for k in verdict.pair],
        "places": verdict.places,
        "links": len(verdict.links),
        "weight": round(verdict.weight, 4),
        "rival_weight": round(verdict.rival_weight, 4),
        "max_confidence": round(max(c.confidence for c in verdict.links), 4),
        "accepted": verdict.accepted,
        "reason": verdict.reason,
        "seen_through": [round(v, 3) for v in verdict.seen_through],
        "error_m": round(error[0], 3),
        "error_deg": round(math.degrees(error[1]), 2),
        "right": not _wrong(error),
        "judged": bool(np.isfinite(error[0])),  # false: no keyframe of it has a reference
        "symmetry_image": image,
    }
    if verdict.evidence is not None:
        for name, ev in (("b_on_a", verdict.evidence.b_on_a), ("a_on_b", verdict.evidence.a_on_b)):
            record[name] = {
                "score": round(ev.score, 3),
                "rival": round(ev.rival, 3),
                "wall": round(ev.wall, 3),
                "conflict": round(ev.conflict, 3),
                "matched": round(ev.matched, 3),
            }
        record["probability"] = verdict.probability
    return record


# --- one scenario ---------------------------------------------------------------------------


def snapshots_of(
    scenario: Scenario, kind: str, times: list[float]
) -> tuple[dict[str, list[list[Keyframe]]], list[dict[str, Any]]]:
    """Every robot's partial map at each update time (``kind``: truth or own), and the own
    maps' closures and joins judged (none for truth maps)."""
    snapshots: dict[str, list[list[Keyframe]]] = {}
    closures: list[dict[str, Any]] = []
    weighed: list[dict[str, Any]] = []
    for robot, drive in scenario.drives.items():
        if kind == "truth":
            snapshots[robot] = truth_snapshots(drive, times)
            continue
        own = own_snapshots(drive, times)
        snapshots[robot] = own.snapshots
        for item in own.weighed:
            first, second = own.keyframe_stamps[[item.first, item.mine]]
            world = scenario.truth().truth_of(robot, np.array([first, second]))
            if not np.isfinite(world).all():
                continue  # a keyframe without a reference pose
            real = se2.between(tuple(world[0]), tuple(world[1]))
            error = _error(se2.matrix_from_pose(*item.found), se2.matrix_from_pose(*real))
            ev = item.evidence
            weighed.append(
                {
                    "robot": robot,
                    "kind": item.kind,
                    "probability": round(item.probability, 6),
                    "score": round(ev.score, 3),
                    "rival": round(ev.rival, 3),
                    "wall": round(ev.wall, 3),
                    "conflict": round(ev.conflict, 3),
                    "matched": round(ev.matched, 3),
                    "error_m": round(error[0], 3),
                    "right": not _wrong(error),
                }
            )
            if item.prior is not None:
                weighed[-1]["graph_prior"] = round(item.prior, 3)
        for closure in own.closures:
            first, second = own.keyframe_stamps[[closure.first, closure.second]]
            world = scenario.truth().truth_of(robot, np.array([first, second]))
            if not np.isfinite(world).all():
                continue  # judged only between keyframes with reference poses
            real = se2.between(tuple(world[0]), tuple(world[1]))
            error = _error(
                se2.matrix_from_pose(*closure.T_first_second), se2.matrix_from_pose(*real)
            )
            closures.append(
                {
                    "robot": robot,
                    "kind": closure.kind,
                    "first": closure.first,
                    "second": closure.second,
                    "confidence": round(closure.confidence, 4),
                    "error_m": round(error[0], 3),
                    "error_deg": round(math.degrees(error[1]), 2),
                    "wrong": error[1] > RIGHT_ANGLE if closure.kind == "heading" else _wrong(error),
                }
            )
    return snapshots, closures + [
        {**w, "weighed_kind": w["kind"], "kind": "weighed"} for w in weighed
    ]


def run_updates(
    scenario: TruthTable,
    times: list[float],
    snapshots: dict[str, list[list[Keyframe]]],
    config: MergeConfig,
    kept: list[Any] | None,
) -> tuple[list[dict[str, Any]], list[Any]]:
    """The merger's updates (module doc), each judged; and what each update matched (kept for
    ``judge``). With ``kept`` (an earlier run's matches), no place is matched again."""
    previous: MergeResult | None = None
    records: list[dict[str, Any]] = []
    matches: list[Any] = []
    walls_truth: dict[str, np.ndarray] = {}
    for step, clock in enumerate(times):
        held = {r: s[step] for r, s in snapshots.items() if s[step]}
        if not held:
            matches.append({})
            continue
        if kept is not None:
            previous = _with_matches(previous, kept[step])
        started = time.perf_counter()
        result = merge_joint(held, config, previous=previous, budget=0.0)
        seconds = time.perf_counter() - started
        previous = result
        assert isinstance(result.state, JointState)
        matches.append(result.state.matches)
        units = units_of(held)
        truth = Truth.of(scenario, units)
        for robot, frames in held.items():
            walls_truth[robot] = world_walls(frames, scenario.truth_of(robot, _stamps(frames)))
        records.append(
            {
                "time": round(clock, 3),
                "seconds": round(seconds, 3),
                "reference": result.reference,
                "placements": judge_placements(result, units, truth, scenario.symmetries()),
                "overlapping": sorted(overlap_component(walls_truth)),
                "verdicts": [
                    verdict_record(v, units, truth, scenario.symmetries())
                    for v in result.verdicts.values()
                    if isinstance(v, PairVerdict) and v.links
                ],
            }
        )
    return records, matches


def _with_matches(previous: MergeResult | None, matches: dict[Any, Any]) -> MergeResult:
    """A previous result carrying ``matches`` (a kept update's): the next update matches no
    place again whose map is unchanged."""
    state = JointState(matches=dict(matches))
    if previous is None:
        return MergeResult(
            [], {}, None, [], {}, np.zeros((0, 4)), np.zeros(0, np.int64), {}, {}, state=state
        )
    return dataclasses.replace(previous, state=state)


def _stamps(frames: list[Keyframe]) -> np.ndarray:
    return np.array([kf.stamp for kf in frames], dtype=np.float64)


def scenario_of(name: str) -> Scenario | None:
    """A scenario by name: ``generated:SEED``, ``generated_own:SEED``, ``world:WORLD:K:SEED``,
    ``carmen:LOG:K``, ``bag:BAG:K``."""
    kind, *rest = name.split(":")
    if kind in ("generated", "generated_own"):
        from bench.scenarios import generated_scenario

        return generated_scenario(int(rest[0]), own=kind == "generated_own")
    if kind == "world":
        return world_scenario(rest[0], int(rest[1]), int(rest[2]))
    if kind == "carmen":
        return carmen_scenario(rest[0], int(rest[1]))
    if kind == "bag":
        return bag_scenario(rest[0], int(rest[1]))
    raise ValueError(f"unknown scenario {name!r}")


def collect_one(name: str, kinds: list[str], updates: int, work: str) -> str:
    """Build, merge and judge one scenario (module doc); returns a line for the log."""
    started = time.perf_counter()
    scenario = scenario_of(name)
    if scenario is None:
        return f"{name}: skipped (its data is absent)"
    times = update_times(scenario, updates)
    config = MergeConfig()
    lines = []
    for kind in kinds:
        stem = f"{name.replace(':', '_')}_{kind}"
        if (Path(work) / "records" / f"{stem}.json").is_file():
            lines.append(f"{kind}: kept")  # collected before (a run resumed)
            continue
        snapshots, closures = snapshots_of(scenario, kind, times)
        truth = scenario.truth()
        records, matches = run_updates(truth, times, snapshots, config, None)
        kept = {"times": times, "snapshots": snapshots, "matches": matches, "truth": truth}
        with open(Path(work) / "cases" / f"{stem}.pkl", "wb") as handle:
            pickle.dump(kept, handle)
        _write_records(work, stem, name, kind, scenario.description, records, closures)
        last = records[-1]["placements"] if records else {}
        wrong = sum(p["wrong"] for p in last.values())
        lines.append(f"{kind}: {len(last)} placed, {wrong} wrong at the end")
    return f"{name}: {'; '.join(lines)} ({time.perf_counter() - started:.0f} s)"


def _write_records(
    work: str,
    stem: str,
    name: str,
    kind: str,
    description: dict[str, Any],
    records: list[dict[str, Any]],
    closures: list[dict[str, Any]],
) -> None:
    out = {
        "scenario": name,
        "maps": kind,
        "description": description,
        "updates": records,
        "closures": closures,
    }
    (Path(work) / "records" / f"{stem}.json").write_text(json.dumps(out))


class _CaseUnpickler(pickle.Unpickler):
    """Reads the cases kept before bench/ became a package, whose pickles name the module
    ``scenarios`` (then a top-level module), as ``bench.scenarios``."""

    def find_class(self, module: str, name: str) -> Any:
        return super().find_class("bench.scenarios" if module == "scenarios" else module, name)


def judge_one(stem: str, work: str, overrides: dict[str, Any]) -> str:
    """Re-run one kept scenario's decisions with today's code (module doc)."""
    with open(Path(work) / "cases" / f"{stem}.pkl", "rb") as handle:
        kept = _CaseUnpickler(handle).load()
    old = json.loads((Path(work) / "records" / f"{stem}.json").read_text())
    config = config_from_flat(MergeConfig, overrides)
    truth = dataclasses.replace(
        kept["truth"], symmetry=str(old["description"].get("symmetry", "none"))
    )
    records, _ = run_updates(truth, kept["times"], kept["snapshots"], config, kept["matches"])
    _write_records(
        work, stem, old["scenario"], old["maps"], old["description"], records, old["closures"]
    )
    return stem


# --- the figures ----------------------------------------------------------------------------


def figures(records: list[dict[str, Any]]) -> dict[str, Any]:
    """The benchmark's figures over a set of scenario records (module doc)."""
    published = wrong_ever = end_placed = end_wrong = 0
    overlapping = merged = 0
    delays: list[float] = []
    closures = wrong_closures = joins = wrong_joins = 0
    decisions = accepted_wrong = accepted = 0
    robots_ever_wrong = 0
    symmetry_ever = symmetry_end = 0
    for case in records:
        updates = case["updates"]
        ever_wrong: set[str] = set()
        for update in updates:
            for name, p in update["placements"].items():
                published += 1
                if p["wrong"]:
                    wrong_ever += 1
                    symmetry_ever += p.get("symmetry_image", False)
                    ever_wrong.add(name.split("/")[0])
            for v in update["verdicts"]:
                decisions += 1
                accepted += v["accepted"]
                accepted_wrong += v["accepted"] and v.get("judged", True) and not v["right"]
        robots_ever_wrong += len(ever_wrong)
        if updates:
            last = updates[-1]
            end_placed += len(last["placements"])
            end_wrong += sum(p["wrong"] for p in last["placements"].values())
            symmetry_end += sum(p.get("symmetry_image", False) for p in last["placements"].values())
            for robot in last["overlapping"]:
                overlapping += 1
                if _placed_right(last, robot):
                    merged += 1
                    delays.append(_delay(updates, robot))
        for c in case["closures"]:
            if c["kind"] == "weighed":
                continue  # a decision the evidence model weighed (bench/fit_join.py reads it)
            if c["kind"] == "join":
                joins += 1
                wrong_joins += c["wrong"]
            else:
                closures += 1
                wrong_closures += c["wrong"]
    return {
        "scenarios": len(records),
        "published": published,
        "wrong_ever": wrong_ever,
        "symmetry_ever": symmetry_ever,
        "symmetry_end": symmetry_end,
        "robots_ever_wrong": robots_ever_wrong,
        "end_placed": end_placed,
        "end_wrong": end_wrong,
        "overlapping": overlapping,
        "merged": merged,
        "delay_median_s": float(np.median(delays)) if delays else float("nan"),
        "delay_p90_s": float(np.percentile(delays, 90)) if delays else float("nan"),
        "closures": closures,
        "wrong_closures": wrong_closures,
        "joins": joins,
        "wrong_joins": wrong_joins,
        "decisions": decisions,
        "accepted": accepted,
        "accepted_wrong": accepted_wrong,
    }


def _main_unit(update: dict[str, Any], robot: str) -> str | None:
    mine = [n for n in update["placements"] if n.split("/")[0] == robot]
    return f"{robot}/0" if f"{robot}/0" in mine else (mine[0] if mine else None)


def _placed_right(update: dict[str, Any], robot: str) -> bool:
    unit = _main_unit(update, robot)
    return unit is not None and not update["placements"][unit]["wrong"]


def _delay(updates: list[dict[str, Any]], robot: str) -> float:
    """Seconds from the first update at which the robot overlaps at the truth to the first at
    which it is placed right (and stays so)."""
    start = next((u["time"] for u in updates if robot in u["overlapping"]), updates[-1]["time"])
    placed = updates[-1]["time"]
    for update in reversed(updates):
        if not _placed_right(update, robot):
            break
        placed = update["time"]
    return max(0.0, placed - start)


def _rate(wrong: int, total: int) -> str:
    return f"{wrong} / {total} ({1000.0 * wrong / total:.1f} per 1000)" if total else "0 / 0"


def print_table(work: str) -> None:
    cases = [json.loads(p.read_text()) for p in sorted((Path(work) / "records").glob("*.json"))]
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for case in cases:
        source = str(case["description"].get("source", "?"))
        groups.setdefault((source, case["maps"]), []).append(case)
    print(
        "| source | maps | scenarios | published wrong, ever (of them the building's own "
        "symmetry) | robots ever wrong | wrong at the end (symmetry) | overlapping robots "
        "merged | time to merge, median / p90 (s) | closures wrong | joins wrong | sets "
        "accepted wrong |"
    )
    print("|" + " --- |" * 11)
    for (source, maps), members in sorted(groups.items()):
        f = figures(members)
        share = f"{f['merged']} / {f['overlapping']}"
        if f["overlapping"]:
            share += f" ({100.0 * f['merged'] / f['overlapping']:.1f} %)"
        print(
            f"| {source} | {maps} | {f['scenarios']} | {_rate(f['wrong_ever'], f['published'])} "
            f"({f['symmetry_ever']}) | {f['robots_ever_wrong']} | "
            f"{_rate(f['end_wrong'], f['end_placed'])} ({f['symmetry_end']}) | {share} | "
            f"{f['delay_median_s']:.0f} / {f['delay_p90_s']:.0f} | "
            f"{_rate(f['wrong_closures'], f['closures'])} | {_rate(f['wrong_joins'], f['joins'])} "
            f"| {_rate(f['accepted_wrong'], f['accepted'])} |"
        )


def _names(args: argparse.Namespace) -> list[str]:
    if args.source in ("generated", "generated_own"):
        seeds = range(args.first, args.first + args.count)
        return [f"{args.source}:{seed}" for seed in seeds]
    if args.source == "carmen":
        return [f"carmen:{log}:{k}" for log in args.logs for k in args.robots]
    if args.source == "bag":
        return [f"bag:{bag}:{k}" for bag in args.bags for k in args.robots]
    return [f"world:{w}:{k}:{args.first}" for w in args.worlds for k in args.robots]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    collect = sub.add_parser("collect")
    collect.add_argument("--source", choices=("generated", "carmen", "bag", "world"), required=True)
    collect.add_argument("--bags", nargs="*", default=list(DENSE_BAGS))
    collect.add_argument("--first", type=int, default=0)
    collect.add_argument("--count", type=int, default=200)
    collect.add_argument(
        "--logs", nargs="*", default=["intel", "aces", "fhw", "csail", "freiburg-079", "edmonton"]
    )
    collect.add_argument("--worlds", nargs="*", default=["office", "corridors", "rooms"])
    collect.add_argument("--robots", type=int, nargs="*", default=[2, 4, 8])
    collect.add_argument("--maps", nargs="*", choices=("truth", "own"), default=["truth"])
    collect.add_argument("--updates", type=int, default=8, help="merger updates per scenario")
    collect.add_argument("--jobs", type=int, default=1)
    collect.add_argument("--work", default=str(OUTPUT / "decisions"))
    judge = sub.add_parser("judge")
    judge.add_argument("--work", default=str(OUTPUT / "decisions"))
    judge.add_argument("--jobs", type=int, default=1)
    judge.add_argument("--only", default="", help="stems containing this")
    judge.add_argument("--set", dest="overrides", action="append", default=[])
    table = sub.add_parser("table")
    table.add_argument("--work", default=str(OUTPUT / "decisions"))
    args = parser.parse_args()
    if args.command == "table":
        print_table(args.work)
        return
    for folder in ("cases", "records"):
        (Path(args.work) / folder).mkdir(parents=True, exist_ok=True)
    if args.command == "collect":
        jobs = [(name, args.maps, args.updates, args.work) for name in _names(args)]
        _run(collect_one, jobs, args.jobs)
    else:
        overrides = dict(parse_override(o) for o in args.overrides)
        stems = [p.stem for p in sorted((Path(args.work) / "cases").glob("*.pkl"))]
        _run(judge_one, [(s, args.work, overrides) for s in stems if args.only in s], args.jobs)
    print_table(args.work)


def _run(function: Any, jobs: list[tuple[Any, ...]], workers: int) -> None:
    """Each job in a worker process; a worker that dies (a crash, the kernel's OOM killer)
    costs its job only: the pool is made again and the others go on (a job that kills two
    workers is reported and skipped)."""
    if workers <= 1:
        for job in jobs:
            try:
                print(function(*job), flush=True)
            except Exception as exc:  # one scenario's failure costs that scenario only
                print(f"{job[0]}: failed: {type(exc).__name__}: {exc}", flush=True)
        return
    pending = list(jobs)
    deaths: dict[int, int] = {}
    while pending:
        with ProcessPoolExecutor(workers) as pool:
            futures = {pool.submit(function, *job): k for k, job in enumerate(pending)}
            done: set[int] = set()
            try:
                for future in as_completed(futures):
                    print(future.result(), flush=True)
                    done.add(futures[future])
            except BrokenProcessPool:
                pass
        left = [k for k in range(len(pending)) if k not in done]
        for k in left[:workers]:  # the jobs running when the pool broke
            deaths[id(pending[k])] = deaths.get(id(pending[k]), 0) + 1
        skipped = [k for k in left if deaths.get(id(pending[k]), 0) >= 2]
        for k in skipped:
            print(f"{pending[k][0]}: skipped, its worker died twice", flush=True)
        pending = [pending[k] for k in left if k not in skipped]


if __name__ == "__main__":
    main()
