"""Recordings as users bring them: one bag per robot or one for all, ROS 1 or ROS 2, with the
robots' names, the beams' geometry and the reference poses set right; and one recording cut
into K robots' runs for tests and benchmarks (what ``mrm import-carmen`` and
``mrm import-bag`` both do).

- :func:`read_bags` reads several bags (:func:`~multi_robot_mapper.io.bags.read_recordings`
  each) into one set of robots. A robot is named by its scan topic's namespace, by the name
  given for its bag, or (several bags whose scans are a plain ``/scan``) by its bag's file name.
- :class:`BeamGeometry` overrides the beam angles a recording states, when they are wrong (a
  converter that spread CARMEN's 180 one-degree beams over 180 degrees instead of 179).
- :func:`read_truth_csv` and :func:`attach_truth` give scans reference poses from a
  ``NAME.truth.csv`` file (``index,stamp,x,y,theta``: the scan's position among the
  recording's scans in stamp order, its stamp, its laser pose in ``world``).
- :func:`cut_recording` cuts one robot's recording into K contiguous runs.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.io.bags import (
    DEFAULT_SCAN_TOPICS,
    GROUND_TRUTH_MATCH_S,
    UNNAMED_ROBOT,
    BagError,
    ReadReport,
    RobotRecording,
    TimedPose,
    TimedScan,
    read_recordings,
    valid_robot_name,
)
from multi_robot_mapper.io.carmen import beam_geometry

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

TRUTH_COLUMNS = ("index", "stamp", "x", "y", "theta")
TRUTH_FRAME = "world"  # the frame of a truth file's poses
_BAG_SUFFIXES = (".bag", ".mcap", ".db3")


class TruthFileError(BagError):
    """A truth file that cannot be read or does not fit the recording (message names it)."""


# --- several bags, one set of robots ----------------------------------------------------------


def name_from_file(path: str | Path) -> str:
    """A robot name from a bag's file name: ``robot2.bag`` -> ``robot2``, ``mit-csail.bag`` ->
    ``mit_csail`` (a ROS namespace allows letters, digits and underscores)."""
    path = Path(path)
    stem = path.stem if path.suffix in _BAG_SUFFIXES else path.name
    name = re.sub(r"[^A-Za-z0-9_]", "_", stem) or UNNAMED_ROBOT
    return f"_{name}" if name[0].isdigit() else name


def read_bags(
    paths: Sequence[str | Path],
    names: Sequence[str] | None = None,
    scan_pattern: str = DEFAULT_SCAN_TOPICS,
    *,
    salvage: bool = False,
    report: ReadReport | None = None,
) -> dict[str, RobotRecording]:
    """Every robot of every bag, by name (robots of one bag in its order, bags in the order
    given).

    ``names`` gives one robot name per bag (each bag must then hold one scan topic). Without
    it a robot is named by its scan topic's namespace; when several bags are given, a bag whose
    scans have no namespace (``/scan``) names its robot after the file (:func:`name_from_file`).
    Two robots of the same name are refused.
    """
    if not paths:
        raise BagError("no bag given")
    if names is not None:
        if len(names) != len(paths):
            raise BagError(f"{len(names)} robot names for {len(paths)} bags: give one per bag")
        bad = [n for n in names if not valid_robot_name(n)]
        if bad:
            raise BagError(
                f"robot name {bad[0]!r} cannot be a ROS namespace (letters, digits, _ and /)"
            )
    robots: dict[str, RobotRecording] = {}
    source: dict[str, Path] = {}
    for number, path in enumerate(map(Path, paths)):
        found = read_recordings(path, scan_pattern, salvage=salvage, report=report)
        if names is not None:
            if len(found) != 1:
                raise BagError(
                    f"{path}: holds {len(found)} robots ({', '.join(found)}); a name per bag "
                    "needs one scan topic per bag (--scan-topics picks one)"
                )
            found = {names[number]: next(iter(found.values()))}
        elif len(paths) > 1 and UNNAMED_ROBOT in found:
            found[name_from_file(path)] = found.pop(UNNAMED_ROBOT)
        for name, recording in found.items():
            if name in robots:
                raise BagError(
                    f"robot {name!r} is in both {source[name]} and {path}: name the robots "
                    "of each bag (--names)"
                )
            robots[name] = dataclasses.replace(recording, name=name)
            source[name] = path
    return robots


# --- beam geometry ----------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class BeamGeometry:
    """The beam angles of every scan: ``bag`` keeps what each scan states; ``carmen`` applies
    CARMEN's convention for the scan's beam count (:func:`~multi_robot_mapper.io.carmen.
    beam_geometry`: 180/181 beams 1 deg apart, 360/361 beams 0.5 deg apart, from -90 deg);
    ``fixed`` sets the first beam's angle and the step between beams (rad)."""

    kind: str = "bag"
    angle_min: float = 0.0  # rad, the first beam ("fixed" only)
    angle_increment: float = 0.0  # rad, between neighbouring beams ("fixed" only)

    @classmethod
    def parse(cls, text: str) -> BeamGeometry:
        """``bag``, ``carmen`` or ``FIRST,STEP`` in degrees (e.g. ``-90,1``); ValueError else."""
        words = text.strip().lower()
        if words in ("bag", "carmen"):
            return cls(kind=words)
        parts = words.split(",")
        try:
            first, step = (float(p) for p in parts)
        except ValueError:
            raise ValueError(
                f"{text!r}: expected 'bag', 'carmen' or 'FIRST,STEP' in degrees (e.g. -90,1)"
            ) from None
        if not (math.isfinite(first) and math.isfinite(step) and abs(first) <= 360.0):
            raise ValueError(f"{text!r}: the first beam must be a finite angle within +-360 deg")
        if not 0.0 < abs(step) <= 360.0:
            raise ValueError(f"{text!r}: the step must be non-zero and at most 360 deg")
        return cls("fixed", math.radians(first), math.radians(step))

    def describe(self) -> str:
        if self.kind == "fixed":
            return (
                f"first beam {math.degrees(self.angle_min):g} deg, every "
                f"{math.degrees(self.angle_increment):g} deg (given)"
            )
        return {"bag": "as recorded", "carmen": "CARMEN's FLASER geometry"}[self.kind]

    def apply(self, scan: LaserScanData) -> LaserScanData:
        """``scan`` with this geometry's angles (``angle_max`` the last beam's)."""
        beams = np.asarray(scan.ranges).size
        if self.kind == "bag" or beams < 2:
            return scan
        if self.kind == "carmen":
            first, step = beam_geometry(beams)
        else:
            first, step = self.angle_min, self.angle_increment
        return dataclasses.replace(
            scan, angle_min=first, angle_increment=step, angle_max=first + step * (beams - 1)
        )


def with_beam_geometry(
    recordings: Mapping[str, RobotRecording], geometry: BeamGeometry
) -> dict[str, RobotRecording]:
    """The recordings with every scan's angles set by ``geometry`` (unchanged for ``bag``)."""
    if geometry.kind == "bag":
        return dict(recordings)
    return {
        name: dataclasses.replace(
            rec,
            scans=[dataclasses.replace(s, scan=geometry.apply(s.scan)) for s in rec.scans],
        )
        for name, rec in recordings.items()
    }


def geometry_summary(recordings: Mapping[str, RobotRecording]) -> list[str]:
    """One line per beam layout the scans use: beams, first angle, step, how many scans."""
    layouts: dict[tuple[int, float, float], int] = {}
    for rec in recordings.values():
        for item in rec.scans:
            scan = item.scan
            key = (np.asarray(scan.ranges).size, scan.angle_min, scan.angle_increment)
            layouts[key] = layouts.get(key, 0) + 1
    return [
        f"beams: {beams} from {math.degrees(first):.4g} deg every {math.degrees(step):.5g} deg, "
        f"last {math.degrees(first + step * (beams - 1)):.4g} deg ({count} scans)"
        for (beams, first, step), count in sorted(layouts.items())
    ]


# --- reference poses from a truth file --------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class TruthTable:
    """The rows of a truth file: scan index, stamp (s), laser pose (x, y, theta) in ``world``."""

    path: Path
    index: IntArray  # (N,)
    stamp: FloatArray  # (N,)
    pose: FloatArray  # (N, 3)


def read_truth_csv(path: str | Path) -> TruthTable:
    """A ``NAME.truth.csv`` file (header ``index,stamp,x,y,theta``); TruthFileError naming the
    file and line for anything else."""
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as stream:
            rows = list(csv.reader(stream))
    except (OSError, UnicodeError, csv.Error) as exc:
        raise TruthFileError(f"{path}: cannot read the truth file ({exc})") from None
    if not rows or [c.strip() for c in rows[0]] != list(TRUTH_COLUMNS):
        raise TruthFileError(f"{path}: the first line must be {','.join(TRUTH_COLUMNS)}")
    values = np.zeros((len(rows) - 1, 5))
    for line, row in enumerate(rows[1:], start=2):
        try:
            values[line - 2] = [float(c) for c in row]
        except ValueError:
            raise TruthFileError(f"{path}, line {line}: expected 5 numbers, got {row!r}") from None
        if not np.isfinite(values[line - 2]).all() or values[line - 2, 0] != int(
            values[line - 2, 0]
        ):
            raise TruthFileError(f"{path}, line {line}: not finite, or an index not an integer")
    index = values[:, 0].astype(np.int64)
    if len(index) and (index.min() < 0 or np.any(np.diff(index) <= 0)):
        raise TruthFileError(f"{path}: indices must be non-negative and increasing")
    return TruthTable(path, index, values[:, 1], values[:, 2:5])


def attach_truth(recording: RobotRecording, table: TruthTable) -> RobotRecording:
    """``recording`` with the table's poses as its ground truth (frame ``world``), replacing any
    it had: row ``index`` belongs to the recording's ``index``-th scan (in stamp order), whose
    stamp must agree with the row's within GROUND_TRUTH_MATCH_S."""
    count = len(recording.scans)
    if len(table.index) and table.index[-1] >= count:
        raise TruthFileError(
            f"{table.path}: index {int(table.index[-1])} is beyond the {count} scans of robot "
            f"{recording.name!r}: is it this recording's truth file?"
        )
    stamps = np.array([recording.scans[i].stamp for i in table.index], dtype=np.float64)
    gap = np.abs(stamps - table.stamp)
    if len(gap) and gap.max() > GROUND_TRUTH_MATCH_S:
        row = int(np.argmax(gap))
        raise TruthFileError(
            f"{table.path}, line {row + 2}: scan {int(table.index[row])} is stamped "
            f"{stamps[row]:.6f} s in the recording, {table.stamp[row]:.6f} s in the file: is it "
            "this recording's truth file?"
        )
    truth = [
        TimedPose(float(t), (float(x), float(y), float(theta)), TRUTH_FRAME)
        for t, (x, y, theta) in zip(stamps, table.pose, strict=True)
    ]
    return dataclasses.replace(recording, ground_truth=truth)


# --- one recording cut into K robots ----------------------------------------------------------


def split_runs(count: int, robots: int, overlap: int) -> list[tuple[int, int]]:
    """``[start, stop)`` scan indices of each robot's run: K contiguous runs of ``count`` scans,
    each but the first extended ``overlap`` scans back (never before the first scan)."""
    bounds = np.linspace(0, count, robots + 1).round().astype(np.int64).tolist()
    return [(max(0, bounds[k] - overlap), bounds[k + 1]) for k in range(robots)]


def cut_recording(
    recording: RobotRecording, robots: int, overlap: int = 0
) -> dict[str, RobotRecording]:
    """One robot's recording as ``robots`` robots ``robot1`` .. ``robotK`` exploring consecutive
    parts of it at the same time (:func:`split_runs`): each run's stamps are shifted so that it
    starts at the recording's first stamp, its scans are in frame ``robotK/laser``, and it keeps
    the ground truth stamped within its stretch (shifted alike, frame kept).

    The recording's scan stamps must increase strictly (ValueError otherwise).
    """
    count = len(recording.scans)
    if not 1 <= robots <= count:
        raise ValueError(f"cannot cut {count} scans into {robots} runs")
    stamps = np.array([s.stamp for s in recording.scans], dtype=np.float64)
    if np.any(np.diff(stamps) <= 0.0):
        raise ValueError("the scan stamps must increase strictly to cut a recording into runs")
    truth_stamps = np.array([g.stamp for g in recording.ground_truth], dtype=np.float64)
    runs: dict[str, RobotRecording] = {}
    for k, (start, stop) in enumerate(split_runs(count, robots, overlap)):
        name = f"robot{k + 1}"
        shift = stamps[start] - stamps[0]  # every run starts at the first run's start
        scans = [
            TimedScan(float(stamps[i] - shift), f"{name}/laser", recording.scans[i].scan)
            for i in range(start, stop)
        ]
        within = (truth_stamps >= stamps[start] - GROUND_TRUTH_MATCH_S) & (
            truth_stamps <= stamps[stop - 1] + GROUND_TRUTH_MATCH_S
        )
        truth = [
            TimedPose(float(truth_stamps[j] - shift), g.pose, g.frame_id)
            for j, g in enumerate(recording.ground_truth)
            if within[j]
        ]
        runs[name] = RobotRecording(name=name, scans=scans, ground_truth=truth)
    return runs
