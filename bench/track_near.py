"""When does a confident track need a second opinion? (issues 11 and 17, the front end's speed)

The front end first refines the constant-velocity prediction alone against the last keyframe
(``attempts.match_scan``); a confident placement within a third of the correctness tolerance
of the prediction settles there. Otherwise the prediction is refined again with rivals
(turned copies), and a confident placement far from the prediction is confirmed by a search
with no guess, which costs tens of milliseconds per scan. This bench measures both
refinements, whenever confident: the distance from the prediction (in units of the
correctness tolerance, 0.30 m and 5 deg: ``max(d / 0.30 m, turn / 5 deg)``) and whether the
placement is right by the reference (the motion from the last placed scan within 0.30 m /
5 deg of the reference's).

Each shared log is cut into ``--robots`` runs as ``mrm import-carmen`` cuts it, and each run
is mapped by one LocalMapper (back end in line, as a replay), with the defaults. The bench
only observes: it wraps ``attempts.match_scan`` (to see the prediction) and
``attempts.close_to`` (called with a refinement and the prediction, only when that
refinement is confident: first the prediction alone, then with rivals), and changes no
decision. The prediction alone settles within a third of the tolerance (``attempts.NEAR``),
or within all of it when sure (``attempts.SURE``). Beyond the tolerance the front end no
longer computes its confidence (the placement is discarded whatever it is), so the first
table's rows beyond 1.00 stay empty; runs before that change counted them too.

A third table follows every confident track that lands beyond the tolerance of its prediction,
the case where the search confirms it unless the track is sure (``attempts.SURE``): by the
track's confidence, whether the track was right, whether the search disagreed (a likely
placement elsewhere) or was not run, and what was finally placed (right, wrong, or nothing:
the robot started a new piece). It says what the search buys for its tens of milliseconds.
Before it, the confident predictions refined alone that landed beyond a third of the
tolerance but within it (where the rivals are tried), by their confidence in context (the
bench also wraps ``attempts.integrate`` to read it): what the rivals can buy there.

    .venv/bin/python -m bench.track_near [--logs intel aces fhw csail edmonton freiburg-079]
        [--robots 4] [--jobs 2]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import itertools  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import carmen_log, present_logs, right  # noqa: E402
from multi_robot_mapper.cli.import_carmen import split_runs  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.extraction import extract_scan  # noqa: E402
from multi_robot_mapper.core.extraction_config import ExtractionConfig  # noqa: E402
from multi_robot_mapper.core.local_mapping import (  # noqa: E402
    LocalMapper,
    LocalMapperConfig,
    attempts,
    mapper,
)
from multi_robot_mapper.core.matching.confidence import (  # noqa: E402
    LIKELY,
    RIGHT_ANGLE,
    RIGHT_DISTANCE,
)
from multi_robot_mapper.io.carmen import (  # noqa: E402
    carmen_scan_data,
    monotonic_stamps,
    read_carmen,
)

LOGS = ("intel", "aces", "fhw", "csail", "edmonton", "freiburg-079")
# Bins of the distance from the prediction, in units of the correctness tolerance.
BINS = (0.0, 1 / 3, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0, 5.0, np.inf)


def observe(name: str, robots: int) -> dict[str, list[Any]]:
    """(distance from the prediction in tolerances, right) of every confident refinement, per
    kind ("alone": the prediction alone; "rivals": with its rivals), and ("far") the outcome
    of every confident track beyond the tolerance (:func:`far_outcome`), while mapping
    ``name`` cut into ``robots`` runs."""
    seen: dict[str, Any] = {}
    match_scan, close_to, integrate = mapper.match_scan, attempts.close_to, attempts.integrate

    def watched_match_scan(*args: Any, **kwargs: Any) -> Any:
        seen["prediction"] = args[4][0] if args[5] else None  # motions[0], when tracking
        seen["here"], seen["threshold"] = args[1].here, args[0].integrate_confidence
        seen["decision"] = match_scan(*args, **kwargs)
        return seen["decision"]

    def watched_integrate(*args: Any, **kwargs: Any) -> Any:
        result = integrate(*args, **kwargs)
        # the first match of a tracked scan is the prediction refined alone
        seen.setdefault("alone_confidence", attempts.in_context(result.confidence, "track"))
        return result

    def watched_close_to(a: Any, b: Any, distance: float, angle: float) -> bool:
        if b is seen.get("prediction"):
            # the refinement's motion from the last placed scan: the prediction alone is
            # checked first, with its rivals next
            seen["rivals" if "alone" in seen else "alone"] = a
        return close_to(a, b, distance, angle)

    mapper.match_scan, attempts.close_to = watched_match_scan, watched_close_to
    attempts.integrate = watched_integrate
    try:
        scans = read_carmen(carmen_log(name))
        stamps, _ = monotonic_stamps(np.array([s.timestamp for s in scans]), name)
        extraction = ExtractionConfig()
        found: dict[str, list[Any]] = {"alone": [], "rivals": [], "far": []}
        for start, stop in split_runs(len(scans), robots, 0):
            local = LocalMapper(LocalMapperConfig())
            last_placed: np.ndarray | None = None  # reference pose of the last placed scan
            for index in range(start, stop):
                data = carmen_scan_data(scans[index])
                segments, _ = extract_scan(data, extraction)
                seen.clear()
                update = local.add_scan(float(stamps[index]), segments, data)
                reference = np.asarray(scans[index].reference_pose)
                if last_placed is not None:
                    truth = se2.between(tuple(last_placed), tuple(reference))
                    for kind in ("alone", "rivals"):
                        if kind not in seen:
                            continue
                        motion = seen[kind]
                        dx, dy, dtheta = se2.between(seen["prediction"], motion)
                        away = max(np.hypot(dx, dy) / RIGHT_DISTANCE, abs(dtheta) / RIGHT_ANGLE)
                        ex, ey, etheta = se2.between(truth, motion)
                        right = np.hypot(ex, ey) < RIGHT_DISTANCE and abs(etheta) < RIGHT_ANGLE
                        confidence = seen["alone_confidence"] if kind == "alone" else None
                        found[kind].append((float(away), bool(right), confidence))
                    if "decision" in seen and (outcome := far_outcome(seen, local, truth)):
                        found["far"].append(outcome)
                if update.accepted:
                    last_placed = reference
        return found
    finally:
        mapper.match_scan, attempts.close_to = match_scan, close_to
        attempts.integrate = integrate


def far_outcome(seen: dict[str, Any], local: LocalMapper, truth: Any) -> tuple[str, ...] | None:
    """(track confidence band, track right or wrong, search agrees / disagrees / not searched,
    placed right / wrong / nothing) of a confident track beyond the tolerance of its
    prediction, which the search confirms unless the track is sure (None: not that case)."""
    made = local.last_attempts
    tracks = [a for a in made if a.stage == "track"]
    searches = [a for a in made if a.stage == "search"]
    if not tracks or tracks[0].confidence < seen["threshold"] or seen["prediction"] is None:
        return None
    track = tracks[0]
    motion = se2.between(seen["here"], track.pose)
    if attempts.close_to(motion, seen["prediction"], RIGHT_DISTANCE, RIGHT_ANGLE):
        return None  # settled near its prediction, never searched

    chosen, integrated, _ = seen["decision"]
    if not searches:
        verdict = "not searched"  # sure enough (attempts.SURE)
    elif searches[0].confidence >= LIKELY and not attempts.close_to(
        searches[0].pose, track.pose, RIGHT_DISTANCE, RIGHT_ANGLE
    ):
        verdict = "disagrees"
    else:
        verdict = "agrees"
    if not integrated:
        placed = "nothing"
    elif chosen.piece != track.piece:
        placed = "another piece"  # not comparable with the last scan's reference
    else:
        placed = "right" if right(se2.between(seen["here"], chosen.pose), truth) else "wrong"
    bands = ((attempts.SURE, f"≥ {attempts.SURE}"), (0.99, "≥ 0.99"), (0.0, "< 0.99"))
    band = next(label for low, label in bands if track.confidence >= low)
    return (
        band,
        "right" if right(motion, truth) else "wrong",
        verdict,
        placed,
    )


def right_of_all(per_log: list[list[Any]], keep: Any) -> str:
    """Table cells "right / all" of the refinements ``(away, right, confidence)`` that
    ``keep(away, confidence)`` selects, one per log, then over all logs."""
    counts = [
        [right for away, right, confidence in seen if keep(away, confidence)] for seen in per_log
    ]
    cells = [f"{sum(kept)} / {len(kept)}" for kept in counts]
    cells.append(f"{sum(sum(kept) for kept in counts)} / {sum(len(kept) for kept in counts)}")
    return " | ".join(cells)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=list(LOGS))
    parser.add_argument("--robots", type=int, default=4)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    logs = present_logs(args.logs)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        results = dict(zip(logs, pool.map(observe, logs, [args.robots] * len(logs)), strict=True))
    for kind, title in (("alone", "refined alone"), ("rivals", "refined with its rivals")):
        print(f"\nThe prediction {title}, when confident; every log cut into {args.robots} robots:")
        print("right / all, by distance from the prediction (in tolerances)\n")
        print("| distance | " + " | ".join(logs) + " | all |")
        print("| --- " * (len(logs) + 2) + "|")
        for lo, hi in itertools.pairwise(BINS):
            cells = right_of_all(
                [results[name][kind] for name in logs],
                lambda away, _, lo=lo, hi=hi: lo < away <= hi or (lo == 0 == away),
            )
            print(f"| {lo:.2f}–{hi:.2f} | {cells} |")
    print(
        "\nThe prediction refined alone, confident, beyond a third of the tolerance "
        "(attempts.NEAR) but within it, where the rivals are tried: right / all by its "
        "confidence in context\n"
    )
    print("| confidence | " + " | ".join(logs) + " | all |")
    print("| --- " * (len(logs) + 2) + "|")
    bands = ((attempts.SURE, 2.0), (0.99, attempts.SURE), (0.0, 0.99))
    for low, high in bands:
        cells = right_of_all(
            [results[name]["alone"] for name in logs],
            lambda away, confidence, low=low, high=high: (
                1 / 3 < away <= 1.0 and low <= confidence < high
            ),
        )
        label = f"≥ {low}" if high > 1.0 else f"{low}–{high}"
        print(f"| {label} | {cells} |")
    outcomes = sorted({o for name in logs for o in results[name]["far"]})
    print(f"\nConfident tracks beyond the tolerance, searched; {args.robots} robots:")
    print("track confidence / track / search / placed, count per log\n")
    print("| confidence | track | search | placed | " + " | ".join(logs) + " | all |")
    print("| --- " * (len(logs) + 5) + "|")
    for outcome in outcomes:
        counts = [results[name]["far"].count(outcome) for name in logs]
        print(f"| {' | '.join(outcome)} | " + " | ".join(map(str, counts)) + f" | {sum(counts)} |")


if __name__ == "__main__":
    main()
