"""Default local mapping of each shared CARMEN log as one robot, summed up in one line: pieces,
scans placed, scans per context, accepted closures, ATE after a rigid fit, and a digest of the
placed poses (to 0.1 mm): two checkouts that print the same digest placed every scan alike.

    PYTHONPATH=CHECKOUT .venv/bin/python -P bench/local_digest.py [LOG ...]

Run it by path against an older checkout (``PYTHONPATH`` that checkout) to show that a change
leaves the default placements as they were.
"""

from __future__ import annotations

import argparse
import hashlib

import numpy as np

from bench.harness import CARMEN
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.evaluation.metrics import aligned_rmse
from multi_robot_mapper.io.carmen import carmen_scan_data, monotonic_stamps, read_carmen
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig

LOGS = ("intel", "aces", "fhw", "csail", "freiburg-079", "edmonton")


def digest(name: str) -> str:
    log = read_carmen(CARMEN / f"{name}.log.gz")
    stamps, _ = monotonic_stamps(np.array([s.timestamp for s in log]), name)
    config = RobotMapperConfig()
    mapper = LocalMapper(config.local_mapping)
    for stamp, scan in zip(stamps, log, strict=True):
        data = carmen_scan_data(scan)
        mapper.add_scan(float(stamp), extract_scan(data, config.extraction)[0], data)
    placed_stamps, poses = mapper.trajectory()
    reference = np.array(
        [log[int(i)].reference_pose for i in np.searchsorted(stamps, placed_stamps)]
    )
    ate = aligned_rmse(poses, reference)
    accepted = sum(c.accepted for c in mapper.closures)
    fingerprint = hashlib.sha1(np.round(poses, 4).tobytes()).hexdigest()[:10]
    return (
        f"{name} pieces {mapper.pieces_started} placed {len(placed_stamps)} of {len(log)} "
        f"{mapper.scans_placed_by} closures {accepted} ATE {ate:.5f} digest {fingerprint}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    # Checked here, not by ``choices``: argparse checks a ``nargs="*"`` default list as one
    # value, so running with no log named (every log) was refused.
    parser.add_argument("logs", nargs="*", help=f"default: all of {', '.join(LOGS)}")
    logs = parser.parse_args().logs or list(LOGS)
    if unknown := sorted(set(logs) - set(LOGS)):
        parser.error(f"unknown logs {unknown}; choose from {', '.join(LOGS)}")
    for name in logs:
        print(digest(name), flush=True)


if __name__ == "__main__":
    main()
