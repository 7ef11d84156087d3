"""What tells a wrong loop closure from a right one? (issue 17: 0 wrong closures)

Each shared log is cut into ``--robots`` consecutive runs and each run is mapped by one
LocalMapper, back end in line, on the CARMEN scans directly (``unposed_pieces.map_run``).
Every accepted loop closure and join is then judged by the reference (the mapper never sees
it; > 0.30 m / 5 deg from the reference relative pose of the two keyframes, and a closure
wrong only because the reference is wrong at one of its scans is told apart, as in
``bench/local_table.py``), and set beside the evidence the back end could use:

- **edge sigma**: the standard deviations of the closure's edge (the information of the two
  keyframes' own scans at the windows' placement, ``LoopCloser._scan_edge``): the weakest
  and strongest translation direction (m) and the heading (deg). Near the ceiling (10 m,
  57 deg) the two scans share no wall that constrains that direction;
- **scan pair**: the two keyframes' own scans refined from the windows' placement (no
  search, as a local edge is): its confidence, its error against the reference, and how far
  it moved from the windows' placement, also in Mahalanobis units of the edge's information
  (a chi-square with 3 degrees of freedom: 16.3 at 99.9 %).

    .venv/bin/python -m bench.closure_evidence [--logs intel aces fhw csail edmonton]
        [--robots 4 2] [--jobs 2] [--set NAME=VALUE ...]

Prints every closure that is wrong by the reference with its evidence, then for each rule
that the evidence suggests, how many wrong and how many right closures it would refuse.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import judge_every_run, map_run  # noqa: E402
from bench.reference_check import ReferenceJudge  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.matching.integrate import pose_of_match  # noqa: E402
from multi_robot_mapper.io.bags import RobotRecording, TimedPose, TimedScan  # noqa: E402
from multi_robot_mapper.io.carmen import carmen_scan_data  # noqa: E402

CHI2_3DOF_999 = 16.27


def closures_of_run(
    name: str, robots: int, robot: int, overrides: dict[str, Any]
) -> list[dict[str, Any]]:
    """One row per accepted closure and join of robot ``robot`` (0-based) of ``name``."""
    run = map_run(name, robots, robot, overrides)
    members = range(run.start, run.stop)
    stamps = {i: stamp for stamp, i in run.index_of.items()}
    recording = RobotRecording(
        "robot",
        [TimedScan(stamps[i], "laser", carmen_scan_data(run.scans[i])) for i in members],
        [TimedPose(stamps[i], run.scans[i].reference_pose, "world") for i in members],
    )
    judge = ReferenceJudge({"robot": recording})
    closer = run.mapper.backend.closer
    keyframes = closer.keyframes
    rows = []
    for edge_id, closure in closer.accepted.items():
        stamp_a = float(keyframes.scans[closure.first].stamp)
        stamp_b = float(keyframes.scans[closure.second].stamp)
        a, b = run.index_of[stamp_a], run.index_of[stamp_b]
        T_true = se2.between(run.scans[a].reference_pose, run.scans[b].reference_pose)
        T_found = tuple(float(v) for v in closure.T_first_second)
        error = se2.between(T_true, T_found)
        information = np.asarray(closer.graph.edges[edge_id].information)
        covariance = np.linalg.inv(information)
        translation_variances = np.linalg.eigvalsh(covariance[:2, :2])
        # The two keyframes' scans alone, refined from the windows' placement.
        pair = closer._match(closure.first, closure.second, T_found, search=False)
        T_pair = pose_of_match(pair.T_1_2)
        moved = np.array(se2.between(T_found, T_pair))
        pair_error = se2.between(T_true, T_pair)
        rows.append(
            {
                "log": name,
                "robots": robots,
                "robot": robot + 1,
                "kind": closure.kind,
                "scans": (a - run.start, b - run.start),
                "confidence": float(closure.confidence),
                "verdict": judge.verdict("robot", stamp_a, "robot", stamp_b, T_found),
                "error": (float(np.hypot(*error[:2])), float(np.degrees(error[2]))),
                "sigma": (
                    float(np.sqrt(translation_variances[0])),
                    float(np.sqrt(translation_variances[1])),
                    float(np.degrees(np.sqrt(covariance[2, 2]))),
                ),
                "pair_confidence": float(pair.confidence),
                "pair_error": (float(np.hypot(*pair_error[:2])), float(np.degrees(pair_error[2]))),
                "pair_moved": (float(np.hypot(*moved[:2])), float(np.degrees(moved[2]))),
                "pair_mahalanobis": float(moved @ information @ moved),
            }
        )
    return rows


def right_by(error: tuple[float, float]) -> bool:
    return error[0] <= 0.30 and abs(error[1]) <= 5.0


RULES = {
    "the scan pair moves out of the edge's 99.9 % region": (
        lambda r: r["pair_mahalanobis"] > CHI2_3DOF_999
    ),
    "the edge's strongest translation sigma > 0.30 m (the scans share no wall)": (
        lambda r: r["sigma"][0] > 0.30
    ),
    "the edge's heading sigma > 20 deg": lambda r: r["sigma"][2] > 20.0,
    "the scan pair, refined confidently (>= 0.95), leaves the windows' placement": (
        lambda r: r["pair_confidence"] >= 0.95 and not right_by(r["pair_moved"])
    ),
}


def main() -> None:
    rows = [row for result in judge_every_run(closures_of_run, __doc__ or "") for row in result]
    wrong = [r for r in rows if r["verdict"] == "wrong"]
    right = [r for r in rows if r["verdict"] == "right"]
    print(
        f"{len(rows)} closures and joins: {len(right)} right, {len(wrong)} wrong, "
        f"{sum(r['verdict'] == 'reference' for r in rows)} wrong only by the reference"
    )
    for r in wrong:
        print(
            f"  {r['log']} {r['robots']} robot{r['robot']} {r['kind']} scans {r['scans']}: "
            f"confidence {r['confidence']:.3f}, error {r['error'][0]:.2f} m "
            f"{r['error'][1]:.1f} deg; edge sigma {r['sigma'][0]:.2f} / {r['sigma'][1]:.2f} m, "
            f"{r['sigma'][2]:.1f} deg; scan pair confidence {r['pair_confidence']:.2f}, "
            f"error {r['pair_error'][0]:.2f} m {r['pair_error'][1]:.1f} deg, moved "
            f"{r['pair_moved'][0]:.2f} m {r['pair_moved'][1]:.1f} deg "
            f"(Mahalanobis {r['pair_mahalanobis']:.1f})"
        )
    print("| rule | wrong refused | right refused |")
    print("| --- | --- | --- |")
    for rule, refuses in RULES.items():
        print(
            f"| {rule} | {sum(map(refuses, wrong))} of {len(wrong)} | "
            f"{sum(map(refuses, right))} of {len(right)} |"
        )
    pair_wrong = sum(not right_by(r["pair_error"]) for r in (*wrong, *right))
    print(
        f"the scan pair's own placement is wrong by the reference for {pair_wrong} of "
        f"{len(wrong) + len(right)} (the windows': {len(wrong)})"
    )


if __name__ == "__main__":
    main()
