"""Which beam geometry do a bag's reference poses agree with: the bag's own, or CARMEN's?

The bags of ../shared/data/bags/ were converted from CARMEN logs by a converter that spreads
180 beams over 180 degrees (``angle_increment`` = pi/179, last beam at +90 deg), where CARMEN's
FLASER convention is one beam per degree from -90 deg (last beam at +89 deg). The scans placed at
their reference poses (``NAME.truth.csv``) agree best under the geometry the poses were made
with: for pairs of scans that turned at least ``--min-turn`` degrees within 1.5 m of each other,
every point of the second scan is compared with the line through its nearest neighbours in the
first (``bench/carmen_geometry.py``'s measure, :func:`bench.harness.point_to_line_rms`), for each
candidate geometry.

    .venv/bin/python -m bench.bag_geometry [--bag intel] [--min-turn 20]

Candidates: the bag's, CARMEN's, CARMEN's step centred on the axis (-89.5 .. +89.5 deg at 180
beams), and CARMEN's with its step scaled by 0.994-1.009 or its first beam moved by up to 0.25
deg (where the minimum lies).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from bench.harness import BAGS, point_to_line_rms, scan_pairs
from multi_robot_mapper.io.bags import read_recordings
from multi_robot_mapper.io.carmen import beam_geometry
from multi_robot_mapper.io.recordings import attach_truth, read_truth_csv


def posed_scans(bag: Path, truth: Path) -> tuple[list[SimpleNamespace], float, float]:
    """The bag's scans that have a reference pose (ranges, reference_pose), and the bag's own
    first angle and step (rad)."""
    (recording,) = read_recordings(bag).values()
    recording = attach_truth(recording, read_truth_csv(truth))
    by_stamp = {s.stamp: s.scan for s in recording.scans}
    scans = [
        SimpleNamespace(ranges=np.asarray(by_stamp[g.stamp].ranges), reference_pose=g.pose)
        for g in recording.ground_truth
    ]
    first = recording.scans[0].scan
    return scans, first.angle_min, first.angle_increment


def candidates(beams: int, bag_first: float, bag_step: float) -> list[tuple[str, float, float]]:
    """(label, first beam, step) in radians: the three conventions, then CARMEN's with the step
    scaled (the bag's step is 1.0056 times CARMEN's at 180 beams, 1.0028 times at 360) and
    with the first beam moved."""
    carmen_first, carmen_step = beam_geometry(beams)
    rows = [
        ("bag (converter)", bag_first, bag_step),
        ("CARMEN", carmen_first, carmen_step),
        ("CARMEN step, centred", -carmen_step * (beams - 1) / 2.0, carmen_step),
    ]
    for factor in (0.994, 0.997, 1.003, 1.006, 1.009):
        rows.append((f"step x {factor:g}", carmen_first, carmen_step * factor))
    for offset_deg in (-0.25, -0.1, 0.1, 0.25):
        rows.append(
            (f"first {offset_deg:+g} deg", carmen_first + math.radians(offset_deg), carmen_step)
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bag", default="intel", help="NAME of NAME.bag and NAME.truth.csv")
    parser.add_argument("--min-turn", type=float, default=20.0, help="degrees")
    parser.add_argument("--max-gap", type=int, default=30, help="posed scans")
    parser.add_argument("--pairs", type=int, default=400)
    parser.add_argument("--min-range", type=float, default=0.05, help="m")
    parser.add_argument("--max-range", type=float, default=15.0, help="m")
    args = parser.parse_args()
    bag, truth = BAGS / f"{args.bag}.bag", BAGS / f"{args.bag}.truth.csv"
    if not bag.is_file() or not truth.is_file():
        raise SystemExit(f"{bag} or {truth} not found (../shared/data/bags beside this clone)")
    scans, bag_first, bag_step = posed_scans(bag, truth)
    beams = {s.ranges.size for s in scans}
    if len(beams) != 1:
        raise SystemExit(f"{args.bag} mixes beam counts {sorted(beams)}")
    (n,) = beams
    poses = np.array([s.reference_pose for s in scans])
    pairs = scan_pairs(poses, args.min_turn, args.max_gap, args.pairs)
    print(
        f"{args.bag}: {n} beams, {len(scans)} posed scans, {len(pairs)} scan pairs, "
        f"ranges {args.min_range}-{args.max_range} m"
    )
    print("| geometry | first beam (deg) | step (deg) | last beam (deg) | RMS (mm) | points |")
    print("| --- | --- | --- | --- | --- | --- |")
    for label, first, step in candidates(n, bag_first, bag_step):
        rms, count = point_to_line_rms(scans, pairs, first, step, args.min_range, args.max_range)
        last = math.degrees(first + step * (n - 1))
        print(
            f"| {label} | {math.degrees(first):.3f} | {math.degrees(step):.5f} | {last:.3f} | "
            f"{rms * 1e3:.3f} | {count} |"
        )


if __name__ == "__main__":
    main()
