"""The options that say how to read the recordings a user brings, shared by ``mrm replay``,
``mrm evaluate`` and ``mrm import-bag``: robot names per bag, scan topics, beam geometry and
truth files (:mod:`multi_robot_mapper.io.recordings` does the work)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from multi_robot_mapper.cli.common import CliError, missing_input
from multi_robot_mapper.io.bags import DEFAULT_SCAN_TOPICS, ReadReport, RobotRecording

GEOMETRY_HELP = (
    "the beams' angles: 'bag' (default: as each scan states them), 'carmen' (CARMEN's "
    "convention for the beam count: 180 or 181 beams 1 deg apart, 360 or 361 beams 0.5 deg "
    "apart, from -90 deg; right for bags converted from CARMEN logs, see docs/bags.md) or "
    "FIRST,STEP in degrees (e.g. --beam-geometry=-90,1)"
)


def add_recording_options(parser: argparse.ArgumentParser, *, truth: bool = True) -> None:
    """``--names``, ``--scan-topics``, ``--beam-geometry`` and (with ``truth``) ``--truth``."""
    parser.add_argument(
        "--names",
        metavar="NAME,...",
        help="one robot name per bag, in the bags' order (default: each scan topic's "
        "namespace; several bags of a plain /scan are named after their files)",
    )
    parser.add_argument(
        "--scan-topics",
        default=DEFAULT_SCAN_TOPICS,
        metavar="PATTERNS",
        help="comma-separated fnmatch patterns of the scan topics, one robot each (default "
        f"{DEFAULT_SCAN_TOPICS})",
    )
    parser.add_argument("--beam-geometry", default="bag", metavar="SPEC", help=GEOMETRY_HELP)
    if truth:
        parser.add_argument(
            "--truth",
            action="append",
            default=[],
            type=Path,
            metavar="CSV",
            help="reference poses (index,stamp,x,y,theta: NAME.truth.csv) of a robot's scans, "
            "replacing its ground_truth topic; one per robot, in the robots' order (repeatable; "
            "default: the bag's ground_truth topics)",
        )


def load_recordings(
    args: argparse.Namespace, bags: Sequence[Path], *, salvage: bool = False
) -> tuple[dict[str, RobotRecording], ReadReport]:
    """The robots of ``bags`` as the options above say, and what reading left out."""
    from multi_robot_mapper.io.recordings import (
        BeamGeometry,
        attach_truth,
        read_bags,
        read_truth_csv,
        with_beam_geometry,
    )

    try:
        geometry = BeamGeometry.parse(args.beam_geometry)
    except ValueError as exc:
        raise CliError(f"--beam-geometry {exc}") from exc
    names = None if args.names is None else [n.strip() for n in args.names.split(",")]
    for path in bags:
        if not Path(path).exists():
            raise missing_input(path, "bag")
    report = ReadReport()
    recordings = read_bags(bags, names, args.scan_topics, salvage=salvage, report=report)
    recordings = with_beam_geometry(recordings, geometry)
    truth_files: list[Path] = getattr(args, "truth", [])
    if truth_files:
        if len(truth_files) != len(recordings):
            raise CliError(
                f"{len(truth_files)} --truth files for {len(recordings)} robots "
                f"({', '.join(recordings)}): give one per robot, in that order"
            )
        for name, path in zip(list(recordings), truth_files, strict=True):
            recordings[name] = attach_truth(recordings[name], read_truth_csv(path))
    return recordings, report
