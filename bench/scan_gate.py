"""How well the local mapper's gate separates right from wrong scan matches.

Every consecutive scan pair of each log is matched by INTEGRATE with no guess (as the local
mapper's search does); for each gate (net-value fraction, cross support) it prints the share
of pairs accepted and how many accepted matches are wrong (beyond 0.30 m / 5 deg).

    .venv/bin/python -m bench.scan_gate [--logs intel aces fhw csail] [--limit N]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bench.harness import carmen_log
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.matching import IntegrateConfig, cross_support, integrate
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.io.carmen import carmen_scan_data, read_carmen

FRACTIONS = (0.0, 0.1, 0.15, 0.25)
SUPPORTS = (0.0, 0.1, 0.2)


def pair_outcomes(log: Path, limit: int | None) -> np.ndarray:
    """(correct, value, fraction, cross support) of each consecutive pair's best match."""
    scans = list(read_carmen(log))
    views = [carmen_scan_data(s) for s in scans]
    segments = [extract_scan(v, ExtractionConfig())[0].segments for v in views]
    config = IntegrateConfig()
    rows = []
    for k in range(min(len(scans) - 1, limit or len(scans))):
        result = integrate(segments[k], segments[k + 1], config, views=(views[k], views[k + 1]))
        T_true = se2.invert(se2.matrix_from_pose(*scans[k].reference_pose)) @ se2.matrix_from_pose(
            *scans[k + 1].reference_pose
        )
        x, y, theta = se2.pose_from_matrix(se2.invert(T_true) @ result.matrix)
        correct = np.hypot(x, y) <= 0.30 and abs(theta) <= np.radians(5.0)
        support = cross_support(segments[k], segments[k + 1], result.T_1_2, pair_tolerance(config))
        rows.append((float(correct), result.value, result.fraction, support))
    return np.asarray(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=["intel", "aces", "fhw", "csail"])
    parser.add_argument("--limit", type=int, default=None, help="at most this many pairs")
    args = parser.parse_args()
    header = "| gate (fraction, cross support) | " + " | ".join(args.logs) + " |"
    outcomes = {}
    for name in args.logs:
        path = carmen_log(name)
        if not path.is_file():
            raise SystemExit(f"{path} not found (the real logs live in ../shared/data/carmen)")
        outcomes[name] = pair_outcomes(path, args.limit)
    print("accepted share / accepted but wrong, per log (min_match_value 1 m in every row)\n")
    print(header)
    print("|" + " --- |" * (len(args.logs) + 1))
    for fraction in FRACTIONS:
        for support in SUPPORTS:
            cells = []
            for name in args.logs:
                correct, value, frac, cross = outcomes[name].T
                accepted = (value >= 1.0) & (frac >= fraction) & (cross >= support)
                wrong = int(np.count_nonzero(accepted & (correct == 0)))
                cells.append(f"{accepted.mean():.3f} / {wrong}")
            print(f"| {fraction:g}, {support:g} m | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
