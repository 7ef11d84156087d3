"""The shared bags (ROS 1, every scan, ../shared/data/bags) replayed with the ``local`` method
on one core: scans per second, and, where a bag allows it, the trajectory's error against its
reference poses (ATE after a rigid fit) and on the benchmark's relations.

    taskset -c 1 nice -n 10 .venv/bin/python -m bench.bag_replay [--bags intel aces ...]
        [--scans N] [--beam-geometry carmen] [--json FILE]

Timing covers what ``mrm replay`` runs between reading the bag and writing the result (front
end and local mapping: :func:`~multi_robot_mapper.core.pipeline.run_offline`), as wall time
and as this process's CPU time (the machine is shared: CPU time is the steadier measure).
"Real time" is the bags' own clock: 10 scans per second.

How relations are matched to a bag's scans (the converter rewrote every stamp, so a relation's
stamps, on the original log's clock, name no bag scan directly):

- ``mit-csail``: ``mit-csail.clf.gz`` is the raw log the bag was made from; its k-th FLASER
  line is the bag's k-th scan, so its timestamps are the relations' clock for every scan.
- ``intel``, ``aces``, ``fr079``: the corrected CARMEN log (../carmen/) gives each scan of the
  truth file (its k-th row is the log's k-th scan) a timestamp on the log's clock, which may
  differ from the relations' by a constant. The offset is taken where most differences between
  a relation stamp and a log stamp agree (1 ms bins, refined by their median within 3 ms) and
  trusted only when it brings ``ANCHOR_SIGNIFICANCE`` times more relation stamps within
  ``ANCHOR_MATCH_S`` of a log scan than chance would; a relation is then matched when both its
  stamps lie within ``ANCHOR_MATCH_S`` of such scans (so only relations between two scans of
  the corrected log can match). The reference poses' own error on the matched relations is
  printed beside: a wrong match shows there as metres.
- ``mit-killian``, ``fr-clinic``: no log with their scans' timestamps: nothing is matched.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bench.harness import BAGS  # noqa: E402
from multi_robot_mapper.core.pipeline import TimedLaserScan, run_offline  # noqa: E402
from multi_robot_mapper.evaluation.metrics import aligned_rmse  # noqa: E402
from multi_robot_mapper.evaluation.relations import (  # noqa: E402
    RELATION_MATCH_S,
    read_relations,
    relation_errors,
)
from multi_robot_mapper.io.bags import RobotRecording  # noqa: E402
from multi_robot_mapper.io.carmen import read_carmen  # noqa: E402
from multi_robot_mapper.io.recordings import (  # noqa: E402
    BeamGeometry,
    attach_truth,
    read_bags,
    read_truth_csv,
    with_beam_geometry,
)
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig  # noqa: E402

ALL_BAGS = ("intel", "aces", "fr079", "mit-csail", "mit-killian", "fr-clinic_robotlaser")
RELATIONS = {"fr-clinic_robotlaser": "fr-clinic"}  # bag -> relations file name, if not its own
CORRECTED = {"intel": "intel", "aces": "aces", "fr079": "freiburg-079"}  # ../carmen/ logs
ANCHOR_MATCH_S = 0.01  # the corrected logs' stamps scatter by a few ms about the offset
ANCHOR_SIGNIFICANCE = 5.0  # an offset is trusted when it matches this many times chance
BAG_RATE_HZ = 10.0


def relation_clock(name: str, recording: RobotRecording) -> tuple[np.ndarray, float, str]:
    """Each scan's stamp on the relations' clock (NaN where unknown or not trusted), the
    tolerance to match a relation's stamp with, and how the clock was found."""
    clock = np.full(len(recording.scans), np.nan)
    raw = BAGS / f"{name}.clf.gz"
    if raw.is_file():
        stamps = np.array([s.timestamp for s in read_carmen(raw)])
        if len(stamps) == len(clock):
            return stamps, RELATION_MATCH_S, f"{raw.name}: every scan"
    if name not in CORRECTED or not recording.ground_truth:
        return clock, 0.0, "no log with the scans' timestamps"
    log = BAGS.parent / "carmen" / f"{CORRECTED[name]}.log.gz"
    table = read_truth_csv(BAGS / f"{name}.truth.csv")
    logged = np.array([s.timestamp for s in read_carmen(log)])
    relations = read_relations(BAGS / f"{RELATIONS.get(name, name)}.relations")
    wanted = np.unique(np.r_[relations.first, relations.second])
    differences = (wanted[:, None] - logged[None, :]).ravel()
    bins, counts = np.unique(np.round(differences, 3), return_counts=True)
    peak = bins[np.argmax(counts)]
    offset = float(np.median(differences[np.abs(differences - peak) <= 0.003]))
    # Stamps that fall near a log stamp at this offset, against how many would by chance (each
    # log stamp covers 2 ANCHOR_MATCH_S of the log's span).
    near = np.abs(differences - offset) <= ANCHOR_MATCH_S
    matched = int(np.count_nonzero(near.reshape(len(wanted), -1).any(axis=1)))
    chance = len(wanted) * min(1.0, 2 * ANCHOR_MATCH_S * len(logged) / np.ptp(logged))
    how = (
        f"{log.name} + {offset:.4f} s: {matched} of {len(wanted)} relation stamps within "
        f"{ANCHOR_MATCH_S * 1e3:g} ms of a scan of the log, {chance:.0f} by chance"
    )
    if matched < ANCHOR_SIGNIFICANCE * chance:
        return clock, 0.0, how + ": no clock offset stands out, nothing matched"
    clock[table.index] = logged + offset
    return clock, ANCHOR_MATCH_S, how


def replay(name: str, args: argparse.Namespace) -> dict[str, Any]:
    """One bag replayed and scored; a row of the table."""
    path = BAGS / f"{name}.bag"
    (recording,) = with_beam_geometry(read_bags([path]), args.beam_geometry).values()
    truth = BAGS / f"{name}.truth.csv"
    if truth.is_file():
        recording = attach_truth(recording, read_truth_csv(truth))
    scans = recording.scans[: args.scans or None]
    config = RobotMapperConfig()
    inputs = {name: [TimedLaserScan(s.stamp, s.scan) for s in scans]}
    wall, cpu = time.perf_counter(), time.process_time()
    offline = run_offline(inputs, "local", config.extraction, local_mapping=config.local_mapping)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    stamps = np.array([s.stamp for s in scans])
    poses = np.full((len(scans), 3), np.nan)
    traj_stamps, traj_poses = offline.trajectories[name]
    poses[np.searchsorted(stamps, traj_stamps)] = traj_poses
    row: dict[str, Any] = {
        "bag": name,
        "scans": len(scans),
        "of": len(recording.scans),
        "beams": int(np.asarray(scans[0].scan.ranges).size),
        "wall_s": round(wall, 1),
        "cpu_s": round(cpu, 1),
        "scans_per_cpu_s": round(len(scans) / cpu, 1),
        "real_time_factor": round(len(scans) / cpu / BAG_RATE_HZ, 2),
        "posed": len(traj_stamps),
        # where the time goes: the front end's extraction, and local mapping's stages (its
        # back end, in line here, is the "handoff")
        "front_end_s": offline.stats["front_end_s"],
        "local_mapping_s": offline.stats["local_mapping_s"],
        "stages_s": offline.stats["robots"][name]["front_end_stage_s"],  # type: ignore[index]
    }
    truth_of = {g.stamp: g.pose for g in recording.ground_truth}
    both = [i for i, t in enumerate(stamps) if t in truth_of and np.isfinite(poses[i, 0])]
    if both:
        ref = np.array([truth_of[stamps[i]] for i in both])
        row["ate_m"] = round(aligned_rmse(poses[both], ref), 4)
        row["ate_scans"] = len(both)
    relations = read_relations(BAGS / f"{RELATIONS.get(name, name)}.relations")
    clock, tolerance, how = relation_clock(name, recording)
    known = np.isfinite(clock[: len(scans)])
    errors = relation_errors(relations, clock[: len(scans)][known], poses[known], tolerance)
    row["relations"] = errors.summary() | {"matched_by": how}
    if args.out is not None:  # every scan's pose (NaN: unposed) and the relations' errors
        args.out.mkdir(parents=True, exist_ok=True)
        np.savez(
            args.out / f"{name}_{args.beam_geometry.kind}.npz",
            stamps=stamps,
            poses=poses,
            translation_m=errors.translation_m,
            rotation_rad=errors.rotation_rad,
        )
    if recording.ground_truth:  # the reference poses on the same relations: how good a match
        reference = np.full((len(scans), 3), np.nan)
        for i, t in enumerate(stamps):
            reference[i] = truth_of.get(t, np.nan)
        own = relation_errors(relations, clock[: len(scans)][known], reference[known], tolerance)
        row["reference_relations"] = own.summary()
    return row


def reference_figures(row: dict[str, Any]) -> str:
    """The reference poses' own relation error where any relation matched two posed scans."""
    own = row.get("reference_relations")
    if not own or not own["matched"]:
        return "-"
    return f"{own['matched']}, {own['translation_mean_m']:.4f} ± {own['translation_std_m']:.4f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bags", nargs="+", default=list(ALL_BAGS), choices=ALL_BAGS)
    parser.add_argument("--scans", type=int, default=0, help="first N scans only (0: all)")
    parser.add_argument("--beam-geometry", type=BeamGeometry.parse, default=BeamGeometry())
    parser.add_argument("--json", type=Path, help="also write the rows here")
    parser.add_argument("--out", type=Path, help="folder for each bag's poses and errors (.npz)")
    args = parser.parse_args()
    rows = []
    print(
        "| bag | scans | beams | geometry | wall s | CPU s | scans/CPU s | x real time (10 Hz) "
        "| posed | ATE (m) | relations matched | transl. (m) | rot. (deg) | reference poses on "
        "them: matched, transl. (m) |"
    )
    print("| --- " * 14 + "|")
    for name in args.bags:
        row = replay(name, args)
        rows.append(row)
        rel = row["relations"]
        scored = rel["matched"] > 0
        print(
            f"| {name} | {row['scans']} of {row['of']} | {row['beams']} | "
            f"{args.beam_geometry.kind} | {row['wall_s']} | {row['cpu_s']} | "
            f"{row['scans_per_cpu_s']} | {row['real_time_factor']} | {row['posed']} | "
            f"{row.get('ate_m', '-')} | {rel['matched']} of {rel['relations']} | "
            + (
                f"{rel['translation_mean_m']:.4f} ± {rel['translation_std_m']:.4f} | "
                f"{rel['rotation_mean_deg']:.3f} ± {rel['rotation_std_deg']:.3f} |"
                if scored
                else "- | - |"
            )
            + f" {reference_figures(row)} |",
            flush=True,
        )
    for row in rows:
        print(f"{row['bag']}: relations matched by {row['relations']['matched_by']}")
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
