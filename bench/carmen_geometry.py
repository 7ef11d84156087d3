"""Which FLASER beam geometry do a log's reference poses agree with?

For each candidate geometry (first beam angle, step between beams) the scans are placed at
their reference poses, and for pairs of scans that turned at least ``--min-turn`` degrees
within 1.5 m of each other (a wrong step bends the two views differently) every point of the
second scan is compared with the line through its nearest neighbours in the first. The
geometry with the smallest point-to-line RMS is the one the poses were made with. The
reference poses' own noise (a few centimetres) dominates the RMS, so differences are small;
what counts is where the minimum lies.

    .venv/bin/python -m bench.carmen_geometry [--log freiburg-079] [--min-range 4]

Default sweep: first angle -90 deg +- 0.1 deg, step 0.998-1.002 times CARMEN's (1 deg for
180/181 beams, 0.5 deg for 360/361), and 180 deg / (n - 1) (a step spreading n beams over
180 deg).
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from bench.harness import point_to_line_rms, require_log, scan_pairs
from multi_robot_mapper.io.carmen import beam_geometry, read_carmen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--log", default="freiburg-079")
    parser.add_argument("--min-turn", type=float, default=20.0, help="degrees")
    parser.add_argument("--max-gap", type=int, default=30, help="scans")
    parser.add_argument("--pairs", type=int, default=400)
    parser.add_argument("--min-range", type=float, default=0.05, help="m")
    parser.add_argument("--max-range", type=float, default=15.0, help="m")
    args = parser.parse_args()
    log = read_carmen(require_log(args.log, "carmen_geometry"))
    beams = {s.ranges.size for s in log}
    if len(beams) != 1:
        raise SystemExit(f"{args.log} mixes beam counts {sorted(beams)}")
    (n,) = beams
    poses = np.array([s.reference_pose for s in log])
    pairs = scan_pairs(poses, args.min_turn, args.max_gap, args.pairs)
    _, carmen_step = beam_geometry(n)
    print(
        f"{args.log}: {n} beams, {len(pairs)} scan pairs, "
        f"ranges {args.min_range}-{args.max_range} m"
    )
    print("| first beam (deg) | step (deg) | last beam (deg) | point-to-line RMS (mm) | points |")
    print("| --- | --- | --- | --- | --- |")
    steps = [carmen_step * f for f in (0.998, 0.999, 1.0, 1.001, 1.002)]
    if not math.isclose(math.pi / (n - 1), carmen_step):
        steps.append(math.pi / (n - 1))
    for first_deg in (-90.1, -90.0, -89.9):
        for step in steps:
            rms, count = point_to_line_rms(
                log, pairs, math.radians(first_deg), step, args.min_range, args.max_range
            )
            last = first_deg + math.degrees(step) * (n - 1)
            mark = " (CARMEN)" if first_deg == -90.0 and step == carmen_step else ""
            print(
                f"| {first_deg:.2f} | {math.degrees(step):.5f}{mark} | {last:.3f} | "
                f"{rms * 1e3:.3f} | {count} |"
            )


if __name__ == "__main__":
    main()
