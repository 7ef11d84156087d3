"""``mrm evaluate DIR [--bag BAG ...] [--truth CSV] [--relations FILE [--relation-stamps LOG]]
[--json]``: score a replay result against the bag's reference poses and against relations.

Without ``--bag`` (and without ``--relations``) the bags are the ones ``mrm replay`` read to
make DIR, read with the options it read them with (``--names``, ``--scan-topics``,
``--beam-geometry``, ``--truth``; each one given here replaces its record): DIR/replay.json
records them.

Reference poses: each scan of the bag gets the reference pose stamped nearest it (within
GROUND_TRUTH_MATCH_S, the rule ``mrm replay`` uses) and the estimated pose whose trajectory stamp
equals its stamp (within STAMP_MATCH_S); scans without a reference pose are left out and
counted. Reference points are every scan's valid points placed at its reference pose (the
ground-truth pose is taken as the pose of the scan's laser frame), thinned to every k-th valid point
so at most ``--max-points`` remain. The bag's reference poses are its ``<robot>/ground_truth``
topics, or the ``--truth`` files.

Relations (``--relations FILE``, the benchmark of Kümmerle et al. 2009,
:mod:`multi_robot_mapper.evaluation.relations`): the mean ± std of the translational and
rotational errors of the relative motions the trajectory estimates between the relations' pairs
of stamps. A relation's stamps name scans by their stamp: the bag's own stamps, or, with
``--relation-stamps LOG``, the timestamps of a CARMEN log whose k-th FLASER line is the bag's
k-th scan (for a bag whose converter rewrote its stamps). Needs no reference pose.

Prints a table (or the JSON with ``--json``) and writes ``DIR/metrics.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.cli.common import CliError, check_limits, check_output, missing_input
from multi_robot_mapper.cli.recordings import (
    add_recording_options,
    load_recordings,
    reading_options,
    recorded_options,
)
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.scan import ScanError, scan_points
from multi_robot_mapper.evaluation import metrics as rules
from multi_robot_mapper.evaluation.metrics import Metrics, RobotTrack, evaluate
from multi_robot_mapper.evaluation.relations import RelationErrors
from multi_robot_mapper.io.bags import GROUND_TRUTH_MATCH_S, nearest_stamps, reference_poses
from multi_robot_mapper.io.outputs import atomic_write_text
from multi_robot_mapper.io.results import REPLAYED_FILE, ReplayResult

FloatArray = NDArray[np.float64]

STAMP_MATCH_S = 1e-6  # a trajectory stamp belongs to the scan stamped within this
MAX_REFERENCE_POINTS = 200_000
METRICS_FILE = "metrics.json"


class AssociationError(ValueError):
    """The result folder and the bag do not belong together (message says why)."""


@dataclass
class EvaluationInputs:
    tracks: dict[str, RobotTrack]
    reference_points: FloatArray  # (P, 2) in the reference frame
    beam_stride: int
    scans_without_reference: dict[str, int]


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="score a replay result folder against the bag's reference poses and relations",
        description=__doc__,
    )
    parser.add_argument(
        "directory",
        type=Path,
        metavar="DIR",
        help="the result folder mrm replay --out wrote (map.json, robots.json, trajectories/)",
    )
    parser.add_argument(
        "--bag",
        dest="bags",
        action="append",
        default=[],
        type=Path,
        metavar="BAG",
        help="the bag that was replayed, with reference poses (repeat for one bag per robot, "
        "in the replay's order; default: without --relations, the bags mrm replay read, as "
        "DIR/replay.json records them, with the options it read them with unless given here; "
        "a folder without that record needs --bag or --relations)",
    )
    add_recording_options(parser)
    # None: not given, so that the record of the replay can decide (reading_options fills in
    # the record, or the usual default the help states).
    parser.set_defaults(scan_topics=None, beam_geometry=None)
    parser.add_argument(
        "--relations",
        type=Path,
        metavar="FILE",
        help="relations to score the trajectories on (t1 t2 x y z roll pitch yaw per line; "
        "default: none)",
    )
    parser.add_argument(
        "--relation-stamps",
        type=Path,
        metavar="LOG",
        help="CARMEN log whose k-th FLASER line is the bag's k-th scan: its timestamps are the "
        "relations' clock (needs --bag of one robot; default: the bag's own stamps)",
    )
    parser.add_argument("--json", action="store_true", help="print the metrics as JSON")
    parser.add_argument(
        "--max-points",
        type=int,
        default=MAX_REFERENCE_POINTS,
        metavar="N",
        help=f"reference points kept, thinning beams evenly (default {MAX_REFERENCE_POINTS})",
    )
    parser.set_defaults(func=run)


def estimated_poses(result: ReplayResult, robot: str, stamps: FloatArray) -> FloatArray:
    """(N, 3) the result's pose of each scan stamped ``stamps`` (NaN rows where unposed);
    AssociationError when a trajectory stamp matches no scan."""
    estimate = np.full((len(stamps), 3), np.nan)
    traj_stamps, traj_poses = result.trajectories.get(robot, (np.zeros(0), np.zeros((0, 3))))
    if len(traj_stamps) == 0:
        return estimate
    if len(stamps) == 0:
        raise AssociationError(f"{robot}: the result has poses, the bag no scan of this robot")
    scan_order = np.argsort(stamps, kind="stable")
    nearest, gap = nearest_stamps(stamps[scan_order], np.asarray(traj_stamps))
    if np.any(gap > STAMP_MATCH_S):
        bad = float(np.asarray(traj_stamps)[np.argmax(gap)])
        raise AssociationError(
            f"{robot}: trajectory stamp {bad:.9f} s matches no scan of the bag within "
            f"{STAMP_MATCH_S * 1e6:g} us (is it the bag that was replayed?)"
        )
    target = scan_order[nearest]
    if len(np.unique(target)) != len(target):
        raise AssociationError(f"{robot}: two trajectory stamps match the same scan")
    estimate[target] = traj_poses
    return estimate


def build_inputs(
    result: ReplayResult, recordings: Mapping[str, Any], max_points: int = MAX_REFERENCE_POINTS
) -> EvaluationInputs:
    """Tracks and reference points from a replay result and the bag's recordings.

    ``recordings`` maps robot -> an object with ``scans`` (``.stamp`` s, ``.scan``
    LaserScanData) and ``ground_truth`` (``.stamp`` s, ``.pose`` (x, y, theta),
    ``.frame_id``), as :func:`multi_robot_mapper.io.bags.read_recordings` returns.
    """
    missing = [r for r in result.robots if r not in recordings]
    if missing:
        raise AssociationError(
            f"robot(s) {', '.join(missing)} of the result are not in the bag "
            f"(bag robots: {', '.join(sorted(recordings)) or 'none'})"
        )
    robots = sorted(recordings)
    gt_frames = {g.frame_id for r in robots for g in recordings[r].ground_truth}
    if len(gt_frames) > 1:
        raise AssociationError(
            f"ground truth comes in several frames ({', '.join(sorted(gt_frames))}); "
            "the evaluation needs one reference frame"
        )
    tracks: dict[str, RobotTrack] = {}
    kept_scans: list[tuple[Any, FloatArray]] = []
    without: dict[str, int] = {}
    for robot in robots:
        rec = recordings[robot]
        if not rec.scans:
            continue
        if not rec.ground_truth:
            raise AssociationError(f"{robot} has scans but no ground truth in the bag")
        stamps = np.array([s.stamp for s in rec.scans], dtype=np.float64)
        estimate = estimated_poses(result, robot, stamps)
        reference_all, has_ref = reference_poses(rec, stamps)
        without[robot] = int(np.count_nonzero(~has_ref))
        if not np.any(has_ref):
            continue
        reference = reference_all[has_ref]
        scans = [s for s, ok in zip(rec.scans, has_ref, strict=True) if ok]
        tracks[robot] = RobotTrack(stamps[has_ref], reference, estimate[has_ref])
        kept_scans.extend(zip(scans, reference, strict=True))

    beams = sum(len(np.asarray(s.scan.ranges).ravel()) for s, _ in kept_scans)
    stride = max(1, math.ceil(beams / max(1, max_points)))
    chunks: list[FloatArray] = []
    for scan, pose in kept_scans:
        try:
            points = scan_points(scan.scan).points
        except ScanError:
            continue  # an unusable scan has no points to contribute
        chunks.append(se2.transform_points(se2.matrix_from_pose(*pose), points[::stride]))
    reference_points = np.vstack(chunks) if chunks else np.zeros((0, 2))
    return EvaluationInputs(tracks, reference_points, stride, without)


def _fmt(value: float | None, unit: str = "", scale: float = 1.0, digits: int = 3) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value * scale:.{digits}f}{unit}"


def format_table(metrics: Metrics, method: str = "") -> str:
    """A human-readable summary: one line per robot, then the totals."""
    deg = 180.0 / math.pi
    header = (
        f"{'robot':<12} {'scans':>6} {'unposed':>7} {'pairs ok':>8} {'strict':>7} "
        f"{'med dt':>8} {'med dθ':>7} {'RMSE':>8} {'own ATE':>8}  merged"
    )
    lines = ([f"method: {method}", ""] if method else []) + [header, "-" * len(header)]
    for name, m in metrics.robots.items():
        merged = "yes" if m.merged else ("no (reported unmerged)" if m.reported_unmerged else "no")
        lines.append(
            f"{name:<12} {m.scans:>6} {m.scans_unposed:>7} {_fmt(m.pair_success):>8} "
            f"{_fmt(m.pair_success_strict):>7} {_fmt(m.median_translation_error_m, ' m'):>8} "
            f"{_fmt(m.median_rotation_error_rad, '°', deg, 2):>7} {_fmt(m.rmse_m, ' m'):>8} "
            f"{_fmt(m.ate_own_frame_m, ' m'):>8}  {merged}"
        )
    lines += [
        "",
        f"robots merged      {metrics.robots_merged} / {metrics.robots_total}",
        f"scans              {metrics.scans_total} ({metrics.scans_unposed} unposed)",
        f"pair success       {_fmt(metrics.pair_success)} "
        f"(≤ {rules.PAIR_TRANSLATION_M:.2f} m, ≤ {math.degrees(rules.PAIR_ROTATION_RAD):g}°), "
        f"strict {_fmt(metrics.pair_success_strict)} "
        f"(≤ {rules.STRICT_TRANSLATION_M:.2f} m, ≤ {math.degrees(rules.STRICT_ROTATION_RAD):g}°)",
        f"median pair error  {_fmt(metrics.median_translation_error_m, ' m')}, "
        f"{_fmt(metrics.median_rotation_error_rad, '°', deg, 2)}",
        f"ATE merged robots  {_fmt(metrics.ate_rmse_m, ' m', digits=4)}",
        f"ATE all robots     {_fmt(metrics.ate_all_rmse_m, ' m', digits=4)}",
        f"map error          {_fmt(metrics.map_error_m, ' m', digits=4)} "
        f"(mean distance of {metrics.reference_points} reference points to "
        f"{metrics.map_segments} segments)",
        f"map coverage       {_fmt(metrics.map_coverage)} "
        f"(points within {rules.MAP_TOLERANCE_M:.2f} m of the map)",
        f"map precision      {_fmt(metrics.map_precision)} "
        f"(map length within {rules.MAP_TOLERANCE_M:.2f} m of a point)",
    ]
    return "\n".join(lines)


def relation_scores(
    result: ReplayResult,
    recordings: Mapping[str, Any],
    relations_path: Path,
    stamp_log: Path | None = None,
) -> RelationErrors:
    """Every robot's trajectory scored on the relations of ``relations_path``.

    A robot's scans are the bag's (``recordings``, as for :func:`build_inputs`), or, without a
    bag, the posed scans of its trajectory. With ``stamp_log`` (one robot only) scan k takes
    the timestamp of the log's k-th FLASER line.
    """
    from multi_robot_mapper.evaluation.relations import (
        RelationsFormatError,
        combine,
        read_relations,
        relation_errors,
    )

    try:
        relations = read_relations(relations_path)
    except RelationsFormatError as exc:
        raise CliError(str(exc)) from exc
    scores = []
    for robot in result.robots:
        if recordings:
            if robot not in recordings:
                raise AssociationError(f"robot {robot} of the result is not in the bag")
            stamps = np.array([s.stamp for s in recordings[robot].scans], dtype=np.float64)
            stamps.sort(kind="stable")
            poses = estimated_poses(result, robot, stamps)
        else:
            stamps, poses = result.trajectories.get(robot, (np.zeros(0), np.zeros((0, 3))))
        if stamp_log is not None:
            stamps = _log_stamps(stamp_log, len(stamps))
        scores.append(relation_errors(relations, stamps, poses))
    if not scores:
        raise AssociationError("the result has no robot")
    return combine(scores)


def _log_stamps(path: Path, count: int) -> FloatArray:
    """The timestamps of a CARMEN log's FLASER lines, which must be ``count``, all readable."""
    from multi_robot_mapper.io.carmen import CarmenFormatError, read_carmen

    try:
        log = read_carmen(path)
    except (CarmenFormatError, OSError, UnicodeError) as exc:
        raise CliError(f"cannot read {path}: {exc}") from exc
    if log.skipped or log.truncated or len(log) != count:
        raise CliError(
            f"{path}: {len(log)} readable FLASER lines for the bag's {count} scans "
            f"({'; '.join(log.skipped_summary()) or 'not one line per scan'}): --relation-stamps "
            "needs the log the bag was made from"
        )
    return np.array([s.timestamp for s in log], dtype=np.float64)


def format_relations(summary: Mapping[str, Any]) -> str:
    """The relations figures as the paper gives them (mean ± std), and what was matched."""
    return "\n".join(
        [
            f"relations          {summary['matched']} of {summary['relations']} matched "
            f"({summary['without_scan']} name no scan, {summary['unposed']} an unposed scan)",
            f"  translational    {_fmt(summary['translation_mean_m'], digits=4)} ± "
            f"{_fmt(summary['translation_std_m'], ' m', digits=4)}",
            f"  rotational       {_fmt(summary['rotation_mean_deg'], digits=3)} ± "
            f"{_fmt(summary['rotation_std_deg'], '°', digits=3)}",
        ]
    )


def _check_arguments(args: argparse.Namespace) -> None:
    check_limits(args, "max_points")
    if args.relation_stamps is not None and (args.relations is None or len(args.bags) != 1):
        raise CliError("--relation-stamps needs --relations and the one bag that was replayed")
    for path in (args.relations, args.relation_stamps):
        if path is not None and not Path(path).is_file():
            raise missing_input(path, "file")


def bags_to_read(
    args: argparse.Namespace, result: ReplayResult, directory: Path
) -> tuple[list[Path], argparse.Namespace]:
    """The bags to score against and the options to read them with: ``--bag`` as given; else,
    without ``--relations``, the bags ``mrm replay`` recorded in ``directory``, each option as
    recorded unless given; else none (relations need no bag)."""
    if args.bags or args.relations is not None:
        return list(args.bags), reading_options(args)
    replayed = result.replayed
    if replayed is None:
        raise CliError(
            "nothing to score against: give --bag (reference poses) or --relations (no "
            f"{directory / REPLAYED_FILE}: the replay that made the folder did not record the "
            "bags it read)"
        )
    options = recorded_options(replayed)
    for bag in replayed.bags:
        if not bag.exists():
            many = ", one --bag per bag in the replay's order" if len(replayed.bags) > 1 else ""
            read_with = f", and the options it was read with: {options}" if options else ""
            raise CliError(
                f"no such bag: {bag} (the bag mrm replay read for {directory}; if it moved, give "
                f"--bag with where it is now{many}{read_with})"
            )
    if not args.truth:
        for truth in replayed.truth_files:
            if not truth.exists():
                raise CliError(
                    f"no such truth file: {truth} (the truth file mrm replay read for {directory}; "
                    "if it moved, give --truth with where it is now, one per robot)"
                )
    return list(replayed.bags), reading_options(args, replayed)


def check_result_folder(directory: Path) -> None:
    """Refuse, naming what was expected, a ``directory`` that is not a replay's result folder:
    a bag given in its place, a file, a folder without ``map.json``."""
    from multi_robot_mapper.io.results import MAP_FILE

    expected = (
        f"mrm evaluate expects the folder that mrm replay --out wrote ({MAP_FILE}, robots.json, "
        "trajectories/)"
    )
    if not directory.exists():
        raise CliError(f"no such result folder: {directory} ({expected})")
    if (directory / MAP_FILE).is_file():
        return
    bag_files = (".mcap", ".db3", ".bag")
    if directory.is_file():
        bag = directory.suffix in bag_files
    else:
        bag = (directory / "metadata.yaml").is_file() or any(
            p.suffix in bag_files for p in directory.iterdir()
        )
    if bag:
        raise CliError(
            f"{directory} is a bag, not a replay result: {expected}; run mrm replay "
            f"{directory} --out DIR, then mrm evaluate DIR"
        )
    kind = "a file" if directory.is_file() else f"a folder without {MAP_FILE}"
    raise CliError(f"{directory} is {kind}: {expected}")


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.io.results import read_results

    directory = Path(args.directory)
    check_result_folder(directory)
    result = read_results(directory)
    _check_arguments(args)
    bags, options = bags_to_read(args, result, directory)
    check_output(directory / METRICS_FILE, kind="file")  # before the work
    if bags and not args.bags:
        # The table's stdout stays pure JSON with --json: the line goes to stderr then.
        print(
            f"scoring against the bag(s) mrm replay read: {', '.join(map(str, bags))}",
            file=sys.stderr if args.json else sys.stdout,
        )
    recordings = load_recordings(options, bags)[0] if bags else {}
    has_truth = any(r.ground_truth for r in recordings.values())
    report: dict[str, Any] = {"method": result.method}
    metrics, inputs = None, None
    try:
        if recordings and (has_truth or args.relations is None):
            inputs = build_inputs(result, recordings, args.max_points)
            if not inputs.tracks:
                raise CliError(
                    f"{', '.join(map(str, bags))} has no scan with a ground-truth pose to "
                    "evaluate against (--truth gives a truth file)"
                )
            metrics = evaluate(
                inputs.tracks, result.map_segments, inputs.reference_points, result.robot_frames
            )
            report = metrics.to_dict() | report
            report["reference_beam_stride"] = inputs.beam_stride
            report["scans_without_reference"] = inputs.scans_without_reference
        if args.relations is not None:
            scores = relation_scores(result, recordings, args.relations, args.relation_stamps)
            report["relations"] = {"file": str(args.relations), **scores.summary()}
    except AssociationError as exc:
        where = ", ".join(map(str, bags or [args.relations]))
        raise CliError(f"{directory} and {where}: {exc}") from exc
    if bags:
        report["bag"] = ", ".join(map(str, bags))
    atomic_write_text(directory / METRICS_FILE, json.dumps(report, indent=1) + "\n")
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    if metrics is not None and inputs is not None:
        print_table(metrics, inputs, result.method)
    if "relations" in report:
        print(("" if metrics is None else "\n") + format_relations(report["relations"]))
    print(f"-> {directory / METRICS_FILE}")
    return 0


def print_table(metrics: Metrics, inputs: EvaluationInputs, method: str) -> None:
    """The table, and how many scans it left out for want of a reference pose."""
    print(format_table(metrics, method))
    skipped = sum(inputs.scans_without_reference.values())
    if skipped:
        print(
            f"({skipped} scans without a reference pose within "
            f"{GROUND_TRUTH_MATCH_S * 1e3:g} ms were left out)"
        )
