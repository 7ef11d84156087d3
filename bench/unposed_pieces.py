"""What the unposed scans of local mapping are (issue 17): the pieces of map that never join.

A scan is unposed when it ends outside its robot's main piece: the robot was lost, mapped on
in a new piece, and that piece was never joined. Each shared log is cut into ``--robots``
consecutive runs (as ``mrm import-carmen`` cuts it) and each run is mapped by one
LocalMapper, back end in line, on the CARMEN scans directly (the replay reads the same scans
from a bag; the two can differ by a join where a decision is close). Every piece left
outside the main piece is then judged with the reference (the mapper never sees it):

- **overlap**: the share of the piece's returns (every beam, at the reference poses) within
  0.30 m of a return of the main piece. A piece that overlaps can be joined by matching; one
  that does not saw walls the rest of the run never sees again, and only the robot's motion
  when it was lost links it to the map;
- **guess**: whether the front end's best match when the robot was lost (``LostFrom``, the
  guess the back end searches around) is right within 0.30 m / 5 deg of the reference.

    .venv/bin/python -m bench.unposed_pieces [--logs intel aces fhw csail edmonton]
        [--robots 4 2] [--jobs 2] [--set NAME=VALUE ...]

Prints one Markdown table (unposed scans by overlap, and of those that do not overlap, by
the guess) and one line per piece.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

from collections import Counter  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from bench.harness import judge_every_run, map_run  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.evaluation.metrics import (  # noqa: E402
    PAIR_ROTATION_RAD,
    PAIR_TRANSLATION_M,
)
from multi_robot_mapper.io.carmen import (  # noqa: E402
    CarmenScan,
    carmen_scan_data,
)

OVERLAP_DISTANCE = 0.30  # m: a return this close to one of the main piece's sees the same wall
OVERLAPS = 0.30  # share of a piece's returns near the main piece's: the piece overlaps it


def returns_at_reference(scan: CarmenScan) -> np.ndarray:
    """Every return of ``scan`` (not the no-return readings) in the world frame, placed at
    its reference pose: (N, 2)."""
    data = carmen_scan_data(scan)
    ranges = np.asarray(data.ranges, dtype=np.float64)
    bearings = data.angle_min + data.angle_increment * np.arange(len(ranges))
    kept = np.isfinite(ranges) & (ranges > data.range_min) & (ranges < data.range_max)
    points = np.c_[ranges[kept] * np.cos(bearings[kept]), ranges[kept] * np.sin(bearings[kept])]
    return se2.transform_points(se2.matrix_from_pose(*scan.reference_pose), points)


def judge_run(
    name: str, robots: int, robot: int, overrides: dict[str, Any]
) -> list[dict[str, Any]]:
    """Map robot ``robot`` (0-based) of ``name`` cut into ``robots``; one row per piece left
    outside the main piece, and a last row with the run's totals."""
    run = map_run(name, robots, robot, overrides)
    scans, start, stop, mapper, index_of = run.scans, run.start, run.stop, run.mapper, run.index_of
    closer = mapper.backend.closer
    keyframes = closer.keyframes

    def scans_of(piece: int) -> tuple[list[int], np.ndarray]:
        times, poses = mapper.trajectory(piece)
        return [index_of[float(t)] for t in times], poses

    main = mapper.main_piece()
    in_main, _ = scans_of(main)
    main_returns = cKDTree(np.vstack([returns_at_reference(scans[i]) for i in in_main]))
    counts = Counter(keyframes.piece(int(k)) for k in range(len(keyframes)))
    rows = []
    for piece in sorted(counts):
        if piece == main:
            continue
        members, _ = scans_of(piece)
        if not members:
            continue
        returns = np.vstack([returns_at_reference(scans[i]) for i in members])
        distance, _ = main_returns.query(returns, distance_upper_bound=OVERLAP_DISTANCE)
        guess_right = None
        lost = closer.lost_from(piece)
        if lost is not None:
            # The reference of the piece's first scan, expressed in the piece it was lost
            # from through that piece's last placed scan before it.
            earlier_members, earlier_poses = scans_of(keyframes.piece(lost.keyframe))
            before = [k for k, i in enumerate(earlier_members) if i < min(members)]
            if before:
                last = before[-1]
                T_true = se2.compose(
                    tuple(earlier_poses[last]),
                    se2.between(
                        scans[earlier_members[last]].reference_pose,
                        scans[min(members)].reference_pose,
                    ),
                )
                guess = se2.compose(keyframes.pose(lost.keyframe), lost.T_keyframe_piece)
                error = se2.between(T_true, guess)
                guess_right = bool(
                    np.hypot(error[0], error[1]) <= PAIR_TRANSLATION_M
                    and abs(error[2]) <= PAIR_ROTATION_RAD
                )
        rows.append(
            {
                "log": name,
                "robots": robots,
                "robot": robot + 1,
                "piece": piece,
                "scans": len(members),
                "first_scan": min(members) - start,
                "overlap": float(np.mean(distance < OVERLAP_DISTANCE)),
                "guess_right": guess_right,
            }
        )
    rows.append({"log": name, "robots": robots, "robot": robot + 1, "total": stop - start})
    return rows


def main() -> None:
    results = judge_every_run(judge_run, __doc__)
    print(
        "| log | robots | unposed | pieces | in pieces that overlap the main piece | "
        "that do not: right guess | wrong guess | no guess (the run's first piece) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    totals: Counter[str] = Counter()
    # Each log and robot count, in the order they were run.
    cases = dict.fromkeys((r["log"], r["robots"]) for result in results for r in result)
    for name, robots in cases:
        rows = [
            r for result in results for r in result if (r["log"], r["robots"]) == (name, robots)
        ]
        pieces = [r for r in rows if "piece" in r]
        scans = sum(r["total"] for r in rows if "total" in r)
        count = Counter()
        for r in pieces:
            if r["overlap"] >= OVERLAPS:
                kind = "overlap"
            else:
                kind = {True: "right", False: "wrong", None: "none"}[r["guess_right"]]
            count[kind] += r["scans"]
        unposed = sum(r["scans"] for r in pieces)
        totals.update(count)
        totals["unposed"] += unposed
        totals["scans"] += scans
        print(
            f"| {name} | {robots} | {unposed} of {scans} ({100.0 * unposed / scans:.1f} %) | "
            f"{len(pieces)} | {count['overlap']} | {count['right']} | {count['wrong']} | "
            f"{count['none']} |"
        )
    print(
        f"all: {totals['unposed']} of {totals['scans']} scans unposed; {totals['overlap']} in "
        f"pieces that overlap the main piece, {totals['right']} / {totals['wrong']} / "
        f"{totals['none']} in pieces that do not (right guess / wrong guess / no guess)"
    )
    for result in results:
        for r in result:
            if "piece" in r:
                print(
                    f"  {r['log']} {r['robots']} robot{r['robot']} piece {r['piece']}: "
                    f"{r['scans']} scans from scan {r['first_scan']}, overlap {r['overlap']:.2f}, "
                    f"guess {r['guess_right']}"
                )


if __name__ == "__main__":
    main()
