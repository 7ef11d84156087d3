"""Where local mapping goes wrong: every placed scan whose motion from the previous placed
scan is wrong, and how it was placed.

Each CARMEN log is cut into ``--robots`` consecutive runs (as ``mrm import-carmen`` cuts it);
one LocalMapper maps each run. For every scan placed in the same piece as the scan before, the
motion since that scan is compared with the reference poses; a pair is wrong beyond 0.30 m or
5 degrees (the evaluation's pair threshold). Each wrong pair is printed with the context of the
match that placed it (``LocalUpdate.placed_by``: ``track``, the last keyframe from the
prediction; ``search``, the last scan with no guess; ``recent``, an older keyframe; ``other``,
another piece's keyframe; ``after gap``: right after scans set aside), its gap in scans, its
confidence in context, the error and the turn the mapper took. New pieces (the robot was
lost) are counted. ``bench/fit_placement.py`` judges every match tried, not only the chosen.

    .venv/bin/python -m bench.local_errors [--logs intel aces fhw csail] [--robots 4]
        [--set NAME=VALUE ...]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
from collections import Counter  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import carmen_log  # noqa: E402
from multi_robot_mapper.cli.import_carmen import split_runs  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.config import config_from_flat, parse_override  # noqa: E402
from multi_robot_mapper.core.extraction import extract_scan  # noqa: E402
from multi_robot_mapper.core.extraction_config import ExtractionConfig  # noqa: E402
from multi_robot_mapper.core.local_mapping import LocalMapper, LocalMapperConfig  # noqa: E402
from multi_robot_mapper.evaluation.metrics import (  # noqa: E402
    PAIR_ROTATION_RAD,
    PAIR_TRANSLATION_M,
)
from multi_robot_mapper.io.carmen import (  # noqa: E402
    carmen_scan_data,
    monotonic_stamps,
    read_carmen,
)


def relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The motion T_a_b of two (x, y, theta) poses."""
    T = se2.invert(se2.matrix_from_pose(*a)) @ se2.matrix_from_pose(*b)
    return np.asarray(se2.pose_from_matrix(T))


def run_log(name: str, robots: int, config: LocalMapperConfig) -> None:
    path = carmen_log(name)
    if not path.is_file():
        print(f"{name}: skipped, {path} not found")
        return
    scans = read_carmen(path)
    stamps, _ = monotonic_stamps(np.array([s.timestamp for s in scans]), path.name)
    extraction = ExtractionConfig()
    placed, wrong, lost = Counter(), [], 0
    for robot, (start, stop) in enumerate(split_runs(len(scans), robots, 0)):
        mapper = LocalMapper(config)
        previous = None  # (pose, reference pose, index) of the previous placed scan
        for index in range(start, stop):
            data = carmen_scan_data(scans[index])
            segments, _ = extract_scan(data, extraction)
            update = mapper.add_scan(float(stamps[index]), segments, data)
            if update.pose is None:
                continue
            if update.new_piece:
                lost += 1
                previous = None  # the new piece's frame is its first scan's
            reference = np.asarray(scans[index].reference_pose)
            if previous is not None:
                gap = index - previous[2]
                route = update.placed_by if gap == 1 else f"{update.placed_by} after gap"
                placed[route] += 1
                truth = relative(previous[1], reference)
                moved = relative(previous[0], np.asarray(update.pose))
                error = relative(truth, moved)
                shift, turn = float(np.hypot(error[0], error[1])), abs(float(error[2]))
                if shift > PAIR_TRANSLATION_M or turn > PAIR_ROTATION_RAD:
                    wrong.append(
                        f"  robot{robot + 1} scan {index - start}: {route}, gap {gap}, "
                        f"confidence {update.confidence:.2f}, error {shift:.2f} m "
                        f"{np.degrees(turn):.1f} deg, turned {np.degrees(abs(moved[2])):.0f} deg"
                    )
            previous = (np.asarray(update.pose), reference, index)
    total = sum(placed.values())
    counts = ", ".join(f"{route} {count}" for route, count in sorted(placed.items()))
    print(
        f"{name}, {robots} robots: {len(wrong)} wrong of {total} placed pairs ({counts}); "
        f"{lost} new pieces"
    )
    print("\n".join(wrong))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=["intel", "aces", "fhw", "csail"])
    parser.add_argument("--robots", type=int, default=4)
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    args = parser.parse_args()
    config = config_from_flat(LocalMapperConfig, dict(parse_override(o) for o in args.overrides))
    for name in args.logs:
        run_log(name, args.robots, config)


if __name__ == "__main__":
    main()
