"""The options that say how to read the recordings a user brings, shared by ``mrm replay``,
``mrm evaluate`` and ``mrm import-bag``: robot names per bag, scan topics, beam geometry and
truth files (:mod:`multi_robot_mapper.io.recordings` does the work); and their record in a
replay's result folder, from which ``mrm evaluate`` reads the bags again alike."""

from __future__ import annotations

import argparse
import os
import shlex
from collections.abc import Sequence
from pathlib import Path

from multi_robot_mapper.cli.common import CliError, missing_input
from multi_robot_mapper.io.bags import DEFAULT_SCAN_TOPICS, ReadReport, RobotRecording
from multi_robot_mapper.io.results import ReplayedBags

DEFAULT_BEAM_GEOMETRY = "bag"

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
    parser.add_argument(
        "--beam-geometry", default=DEFAULT_BEAM_GEOMETRY, metavar="SPEC", help=GEOMETRY_HELP
    )
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
    names = _robot_names(args.names)
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


def _robot_names(text: str | None) -> list[str] | None:
    """``--names``' comma-separated robot names (None when not given)."""
    return None if text is None else [n.strip() for n in text.split(",")]


def _absolute(path: Path) -> Path:
    # abspath, not resolve: the path as the user named it (symlinks kept), anchored at the
    # folder mrm replay ran in, so that mrm evaluate finds it from anywhere.
    return Path(os.path.abspath(path))


def replayed_bags(args: argparse.Namespace, bags: Sequence[Path]) -> ReplayedBags:
    """The record of what ``mrm replay`` read: ``bags`` and the options above, as ``args`` has
    them."""
    names = _robot_names(args.names)
    return ReplayedBags(
        bags=tuple(_absolute(Path(b)) for b in bags),
        names=None if names is None else tuple(names),
        scan_topics=args.scan_topics,
        beam_geometry=args.beam_geometry,
        truth_files=tuple(_absolute(Path(t)) for t in getattr(args, "truth", [])),
    )


def read_as_usual(bags: Sequence[Path] = ()) -> ReplayedBags:
    """The record of ``bags`` read with every option at its usual default."""
    return ReplayedBags(tuple(bags), None, DEFAULT_SCAN_TOPICS, DEFAULT_BEAM_GEOMETRY)


def reading_options(
    args: argparse.Namespace, replayed: ReplayedBags | None = None
) -> argparse.Namespace:
    """The options above for :func:`load_recordings`: each one given in ``args`` as given; one
    not given (None, or no ``--truth``) as ``replayed`` recorded it, else its usual default."""
    if replayed is None:
        replayed = read_as_usual()
    recorded_names = None if replayed.names is None else ",".join(replayed.names)
    given_truth: list[Path] = getattr(args, "truth", [])

    def given_or(value: str | None, recorded: str | None) -> str | None:
        return recorded if value is None else value

    return argparse.Namespace(
        names=given_or(args.names, recorded_names),
        scan_topics=given_or(args.scan_topics, replayed.scan_topics),
        beam_geometry=given_or(args.beam_geometry, replayed.beam_geometry),
        truth=list(given_truth or replayed.truth_files),
    )


def recorded_options(replayed: ReplayedBags) -> str:
    """The options above that ``replayed`` differs from the defaults in, as a command line
    would give them (empty when none)."""
    words: list[str] = []
    if replayed.names is not None:
        words += ["--names", ",".join(replayed.names)]
    if replayed.scan_topics != DEFAULT_SCAN_TOPICS:
        words += ["--scan-topics", replayed.scan_topics]
    if replayed.beam_geometry != DEFAULT_BEAM_GEOMETRY:
        words.append(f"--beam-geometry={replayed.beam_geometry}")  # '=': a SPEC may start with -
    for path in replayed.truth_files:
        words += ["--truth", str(path)]
    return shlex.join(words)
