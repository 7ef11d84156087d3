"""Tracking in corridors (issue 47 item 5): a shared bag's every scan through one robot's local
mapper, with the tracking options set as asked, scored where its truth file has poses.

    .venv/bin/python -m bench.tracking_corridors --bag aces [--set local_map_keyframes=3 ...]
    .venv/bin/python -m bench.tracking_corridors --ribbed-corridor
    .venv/bin/python -m bench.tracking_corridors --bag aces --pieces

Printed per run: pieces started (the robot was lost), scans placed by each context, scans
in the final trajectory (the main piece after the back end's joins), its ATE after a rigid fit
(m), and the **tracking breaks**: pairs of consecutive reference-posed scans (10-20 scans apart
on the dense bags) placed in one piece, with no new piece between them, whose motion as the
front end placed them (each scan's pose when it was placed, before any optimisation) is off
the reference's by more than 0.3 m or 0.1 rad: wrong placements the tracker made, whatever
the back end did later. ``--ribbed-corridor``: a simulated corridor with ribs for 12 m, bare
beyond the laser's 8 m, driven at 1 m/s, with each option; the along-track error every 2.5 s.
``--pieces``: where the robot was lost and why the pieces stayed apart, judged with the
reference (the mapper never sees it): each piece's scans, its span of bag scans and its own
rigid-fit RMSE and worst error (a bent piece drifted inside); then each join of two pieces the
evidence model weighed, its probability (made at ``join_probability``) and how far it is from
the reference, each piece carried onto the reference by its own rigid fit (so a bent piece's
joins look off by its bend).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections import Counter
from typing import Any

import numpy as np

from bench.bag_local_error import BREAK_M, BREAK_RAD
from bench.harness import BAGS
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.core.local_mapping.backend import Backend
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.evaluation.metrics import aligned_rmse
from multi_robot_mapper.io.recordings import (
    BeamGeometry,
    read_bags,
    read_truth_csv,
    with_beam_geometry,
)
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig


def _setting(text: str) -> tuple[str, Any]:
    name, _, value = text.partition("=")
    kind = type(getattr(LocalMapperConfig(), name))
    return name, (value.lower() == "true") if kind is bool else kind(value)


def run_bag(name: str, settings: dict[str, Any], show_pieces: bool = False) -> dict[str, Any]:
    """The bag's scans (CARMEN's beam geometry) through one local mapper; the figures."""
    (recording,) = with_beam_geometry(
        read_bags([BAGS / f"{name}.bag"]), BeamGeometry.parse("carmen")
    ).values()
    config = RobotMapperConfig()
    mapper = LocalMapper(dataclasses.replace(config.local_mapping, **settings))
    placed: list[tuple[bool, int, bool, Any]] = []  # accepted, piece, new piece, pose
    cpu = time.process_time()
    for scan in recording.scans:
        segments, _ = extract_scan(scan.scan, config.extraction)
        update = mapper.add_scan(scan.stamp, segments, scan.scan)
        placed.append((update.accepted, update.piece, update.new_piece, update.pose))
    cpu = time.process_time() - cpu
    stamps = np.array([s.stamp for s in recording.scans])
    final_stamps, final_poses = mapper.trajectory()
    table = read_truth_csv(BAGS / f"{name}.truth.csv")
    index, reference = table.index, table.pose
    poses = np.full((len(stamps), 3), np.nan)
    poses[np.searchsorted(stamps, final_stamps)] = final_poses
    both = np.isfinite(poses[index, 0])
    ate = aligned_rmse(poses[index[both]], reference[both])
    breaks = _tracking_breaks(placed, index, reference)
    if show_pieces:
        _print_pieces(mapper, stamps, index, reference)
    return {
        "bag": name,
        "settings": settings,
        "pieces": mapper.pieces_started,
        "placed_by": dict(mapper.scans_placed_by),
        "final": len(final_stamps),
        "scans": len(stamps),
        "ate_m": round(ate, 3),
        "breaks": breaks,
        "cpu_s": round(cpu, 1),
        "largest_piece": Counter(p for ok, p, _, _ in placed if ok).most_common(1)[0][1],
    }


# A bent piece's drift: its error along the way, fitted on its first scans with a reference pose.
_DRIFT_FIT = 30


def _drift(scans: np.ndarray, poses: np.ndarray, truth: np.ndarray) -> str:
    """Every 10th reference-posed scan's error (m) once the piece is fitted onto the reference
    by its first :data:`_DRIFT_FIT` of them: a slow slide, or a step."""
    fit = _DRIFT_FIT
    T = se2.pose_from_matrix(se2.fit_points(poses[:fit, :2], truth[:fit, :2]))
    moved = se2.compose_each(np.tile(T, (len(poses), 1)), poses)
    errors = np.hypot(*(moved[:, :2] - truth[:, :2]).T)
    return "drift: " + ", ".join(
        f"{s} {e:.2f}" for s, e in zip(scans[::10], errors[::10], strict=True)
    )


def _print_pieces(
    mapper: LocalMapper, stamps: np.ndarray, index: np.ndarray, reference: np.ndarray
) -> None:
    """The ``--pieces`` report (module docstring), on standard output."""
    T_reference_piece: dict[int, Any] = {}
    keyframes = {k.index: k for k in mapper.keyframes()}
    for piece in sorted({k.piece for k in keyframes.values()}):
        piece_stamps, poses = mapper.trajectory(piece)
        scans = np.searchsorted(stamps, piece_stamps)
        posed = np.isin(scans, index)
        line = f"piece {piece}: {len(scans)} scans, bag {scans.min()}-{scans.max()}"
        if posed.sum() >= 3:
            truth = reference[np.searchsorted(index, scans[posed])]
            T = se2.pose_from_matrix(se2.fit_points(poses[posed, :2], truth[:, :2]))
            errors = np.hypot(
                *(
                    se2.compose_each(np.tile(T, (int(posed.sum()), 1)), poses[posed])[:, :2]
                    - truth[:, :2]
                ).T
            )
            T_reference_piece[piece] = T
            line += f", own rigid fit RMSE {np.sqrt(np.mean(errors**2)):.3f} m"
            line += f" (worst {errors.max():.2f} m, {posed.sum()} posed)"
            if errors.max() > BREAK_M and posed.sum() > _DRIFT_FIT:
                line += "\n  " + _drift(scans[posed], poses[posed], truth)
        print(line)
    assert isinstance(mapper.backend, Backend)  # in line: the bench's mapper has no worker
    for weighed in mapper.backend.closer.weighed:
        first, mine = keyframes.get(weighed.first), keyframes.get(weighed.mine)
        if weighed.kind != "join" or first is None or mine is None:
            continue
        pieces = (first.piece, mine.piece)
        line = f"join {weighed.first}->{weighed.mine} pieces {pieces} P {weighed.probability:.3f}"
        if all(p in T_reference_piece for p in pieces):
            true = se2.between(
                se2.compose(T_reference_piece[first.piece], first.T_robotmap_keyframe),
                se2.compose(T_reference_piece[mine.piece], mine.T_robotmap_keyframe),
            )
            off = se2.between(true, weighed.found)
            line += f", off {np.hypot(off[0], off[1]):.2f} m {np.degrees(off[2]):.1f} deg"
        print(line)


def _tracking_breaks(
    placed: list[tuple[bool, int, bool, Any]], index: np.ndarray, reference: np.ndarray
) -> list[tuple[int, float, float]]:
    """(bag scan, m, deg) of each pair of consecutive reference-posed scans the front end
    placed in one piece with a motion off the reference's (module docstring)."""
    breaks = []
    for a, b, ref_a, ref_b in zip(
        index[:-1], index[1:], reference[:-1], reference[1:], strict=True
    ):
        if b >= len(placed) or not (placed[a][0] and placed[b][0]):
            continue
        if placed[a][1] != placed[b][1] or any(placed[k][2] for k in range(a + 1, b + 1)):
            continue
        motion, truth = se2.between(placed[a][3], placed[b][3]), se2.between(ref_a, ref_b)
        off = float(np.hypot(motion[0] - truth[0], motion[1] - truth[1]))
        turned = abs(float(se2.wrap_angle(motion[2] - truth[2])))
        if off > BREAK_M or turned > BREAK_RAD:
            breaks.append((int(b), round(off, 2), round(float(np.degrees(turned)), 1)))
    return breaks


def ribbed_corridor(settings: dict[str, Any]) -> list[tuple[float, float | None]]:
    """(time, along-track error in m, None once a scan is held) every 2.5 s of the drive."""
    ribs = [
        [x, side * 1.2, x, side * 0.9]
        for x, side in zip(
            [0.0, 1.1, 2.9, 3.6, 5.8, 6.5, 8.7, 9.2, 11.5, 12.0], [1, -1] * 5, strict=True
        )
    ]
    walls = np.vstack((np.array([[-5.0, -1.2, 300.0, -1.2], [-5.0, 1.2, 300.0, 1.2]]), ribs))
    laser = LaserModel(beams=361, range_noise=0.005, dropout=0.0, range_max=8.0)
    rng = np.random.default_rng(11)
    mapper = LocalMapper(dataclasses.replace(LocalMapperConfig(), **settings))
    errors: list[tuple[float, float | None]] = []
    for k in range(300):
        stamp = 0.1 * k
        view = simulate_scan(walls, (stamp, 0.0, 0.0), laser, rng)
        update = mapper.add_scan(stamp, extract_scan(view, ExtractionConfig())[0], view)
        if not update.accepted or update.pose is None:
            errors.append((round(stamp, 1), None))
            break
        if k % 25 == 0:
            errors.append((round(stamp, 1), round(update.pose[0] - stamp, 3)))
    return errors


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bag", choices=("intel", "aces", "fr079", "mit-csail"))
    parser.add_argument("--set", action="append", default=[], type=_setting, metavar="NAME=V")
    parser.add_argument("--ribbed-corridor", action="store_true")
    parser.add_argument("--pieces", action="store_true", help="the pieces and joins, judged")
    args = parser.parse_args()
    settings = dict(args.set)
    if args.ribbed_corridor:
        for options in (
            {},
            {"velocity_window": 0.5},
            {"velocity_window": 0.5, "motion_prior": True},
        ):
            print(options or "defaults", ribbed_corridor(options | settings))
    if args.bag:
        print(run_bag(args.bag, settings, args.pieces))


if __name__ == "__main__":
    main()
