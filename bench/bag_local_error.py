"""How well a replay of a shared bag holds together locally, and where it breaks: the motion
the trajectory estimates between consecutive reference-posed scans (10-20 scans apart) against
the reference poses' own, from the poses ``bench/bag_replay.py --out DIR`` saved.

    .venv/bin/python -m bench.bag_local_error DIR [DIR ...]

Per saved run (``NAME_GEOMETRY.npz``): the median and the mean (below 0.3 m / 5 deg) of the
translational and rotational errors of those motions, and every pair off by more than 0.3 m or
0.1 rad (a wrong placement: the trajectory breaks there), with the bag scan where it happened.
Unlike the ATE of a whole run, one such break does not hide the local accuracy.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bench.harness import BAGS
from multi_robot_mapper.core import se2
from multi_robot_mapper.io.recordings import read_truth_csv

BREAK_M, BREAK_RAD = 0.3, 0.1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path)
    args = parser.parse_args()
    print(
        "| run | pairs | median (m) | mean < 0.3 m (m) | median (deg) | mean < 5 deg (deg) "
        "| breaks: bag scan (m, deg) |"
    )
    print("| --- " * 7 + "|")
    for path in sorted(p for folder in args.folders for p in folder.glob("*.npz")):
        name = path.stem.rsplit("_", 1)[0]
        truth = BAGS / f"{name}.truth.csv"
        if not truth.is_file():
            continue
        table = read_truth_csv(truth)
        poses = np.load(path)["poses"]
        inside = table.index < len(poses)
        index, reference = table.index[inside], table.pose[inside]
        true_motion = se2.between_each(reference[:-1], reference[1:])
        motion = se2.between_each(poses[index[:-1]], poses[index[1:]])
        dt = np.hypot(*(motion[:, :2] - true_motion[:, :2]).T)
        da = np.abs(se2.wrap_angle(motion[:, 2] - true_motion[:, 2]))
        breaks = np.flatnonzero((dt > BREAK_M) | (da > BREAK_RAD))
        listed = ", ".join(f"{index[k + 1]} ({dt[k]:.2f}, {np.degrees(da[k]):.1f})" for k in breaks)
        print(
            f"| {path.stem} | {len(dt)} | {np.nanmedian(dt):.4f} | "
            f"{np.nanmean(dt[dt < BREAK_M]):.4f} | {np.degrees(np.nanmedian(da)):.3f} | "
            f"{np.degrees(np.nanmean(da[da < np.radians(5)])):.3f} | {listed or '-'} |"
        )


if __name__ == "__main__":
    main()
