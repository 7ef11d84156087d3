"""The merger's saved map: every robot's partial map and placement, and the global map.

One JSON file (``map_merger``'s ``save_map`` / ``load_map`` services and ``save_on_shutdown``)::

    {"format": "multi_robot_mapper.saved_map", "version": 1,
     "map_frame": "map", "reference": "robot1" | null,
     "robots": {"robot1": {"map_frame": "robot1/map", "session": 1000000000.0 | null,
                           "map_stamp": [sec, nanosec] | null,
                           "placement": [x, y, theta] | null,
                           "probability": 0.97 | null,  # that the placement is right
                           "segments": [[x1, y1, x2, y2], ...],     # the robot's own map frame
                           "keyframe_poses": [[x, y, theta], ...],  # the robot's own map frame
                           "session_of": null | "robot1"},  # an earlier session of robot1
                ...},
     "global": {"segments": [[x1, y1, x2, y2], ...], "segment_robot": [0, ...]}}  # in map_frame

A robot's ``placement`` is ``T_map_robot`` (its map frame in ``map_frame``) or null when it
was unmerged, ``probability`` the merge's probability that it is right (null: not known, as in
files written before it was saved; a loaded placement is published at once only with it);
``session`` is the stamp of its first keyframe (what tells a restarted robot's new map from
the old one). The file is written under a temporary name and renamed when
complete: an interrupted save leaves the previous file. Reading checks every field and raises
:class:`SavedMapError` with one line naming the file and the field.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

FORMAT = "multi_robot_mapper.saved_map"
VERSION = 1


class SavedMapError(Exception):
    """A saved map that cannot be written or read (the message names the file and why)."""


@dataclasses.dataclass
class SavedRobot:
    """One robot's partial map as the merger holds it."""

    map_frame: str
    session: float | None  # stamp of the first keyframe (s)
    map_stamp: tuple[int, int] | None  # header stamp of its last partial map (sec, nanosec)
    placement: Pose | None  # T_map_robot; None = unmerged
    segments: FloatArray  # (N, 4) in the robot's map frame
    keyframe_poses: FloatArray  # (K, 3) in the robot's map frame
    session_of: str | None = None  # an earlier session of this robot (never updated again)
    probability: float | None = None  # that ``placement`` is right (None: not known)


@dataclasses.dataclass
class SavedMap:
    """Everything ``save_map`` writes."""

    map_frame: str
    reference: str | None
    robots: dict[str, SavedRobot]
    segments: FloatArray  # (M, 4) global map in map_frame
    segment_robot: IntArray  # (M,) index into sorted(robots)


def write_saved_map(path: str | Path, saved: SavedMap) -> Path:
    """Write ``saved`` to ``path`` (folders created), atomically; returns the path."""
    path = Path(path).expanduser()
    data = {
        "format": FORMAT,
        "version": VERSION,
        "map_frame": saved.map_frame,
        "reference": saved.reference,
        "robots": {
            name: {
                "map_frame": robot.map_frame,
                "session": robot.session,
                "map_stamp": None if robot.map_stamp is None else list(robot.map_stamp),
                "placement": None if robot.placement is None else list(robot.placement),
                "segments": np.asarray(robot.segments, dtype=np.float64).tolist(),
                "keyframe_poses": np.asarray(robot.keyframe_poses, dtype=np.float64).tolist(),
                "session_of": robot.session_of,
                "probability": robot.probability,
            }
            for name, robot in saved.robots.items()
        },
        "global": {
            "segments": np.asarray(saved.segments, dtype=np.float64).tolist(),
            "segment_robot": np.asarray(saved.segment_robot, dtype=np.int64).tolist(),
        },
    }
    try:
        text = json.dumps(data, allow_nan=False)
    except ValueError as exc:
        raise SavedMapError(f"{path}: the map holds a NaN or infinite value ({exc})") from None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        try:
            with os.fdopen(handle, "w", encoding="utf-8") as stream:
                stream.write(text + "\n")
            os.replace(temporary, path)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise
    except OSError as exc:
        raise SavedMapError(f"{path}: cannot write the map ({exc.strerror or exc})") from None
    return path


def read_saved_map(path: str | Path) -> SavedMap:
    """Read a file :func:`write_saved_map` wrote; every field is checked."""
    path = Path(path).expanduser()
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SavedMapError(f"{path}: no such saved map") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SavedMapError(f"{path}: cannot read the map ({exc})") from None
    except json.JSONDecodeError as exc:
        raise SavedMapError(f"{path}: not a saved map (invalid JSON: {exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise SavedMapError(f"{path}: not a saved map of multi_robot_mapper (no 'format')")
    if data.get("version") != VERSION:
        raise SavedMapError(f"{path}: saved map version {data.get('version')!r}, not {VERSION}")
    robots_data = _field(data, "robots", dict, path)
    robots = {
        str(name): _robot(entry, f"robots.{name}", path) for name, entry in robots_data.items()
    }
    reference = data.get("reference")
    if reference is not None and reference not in robots:
        raise SavedMapError(f"{path}: 'reference' {reference!r} is not one of the robots")
    global_map = _field(data, "global", dict, path)
    segments = _numbers(global_map.get("segments"), 4, "global.segments", path)
    owners = np.asarray(global_map.get("segment_robot", []))
    if owners.ndim != 1 or len(owners) != len(segments) or owners.dtype.kind not in "iu":
        raise SavedMapError(f"{path}: 'global.segment_robot' needs one index per segment")
    if len(owners) and (owners.min() < 0 or owners.max() >= len(robots)):
        raise SavedMapError(f"{path}: 'global.segment_robot' holds an index outside the robots")
    return SavedMap(
        map_frame=str(_field(data, "map_frame", str, path)),
        reference=reference,
        robots=robots,
        segments=segments,
        segment_robot=owners.astype(np.int64),
    )


def _field(data: dict[str, Any], key: str, kind: type, path: Path) -> Any:
    value = data.get(key)
    if not isinstance(value, kind):
        raise SavedMapError(f"{path}: '{key}' missing or not a {kind.__name__}")
    return value


def _numbers(value: Any, width: int, name: str, path: Path) -> FloatArray:
    """A finite ``(N, width)`` float array from a JSON list of rows."""
    try:
        array = np.asarray([] if value is None else value, dtype=np.float64).reshape(-1, width)
    except (TypeError, ValueError):
        raise SavedMapError(f"{path}: '{name}' must be rows of {width} numbers") from None
    if not np.all(np.isfinite(array)):
        raise SavedMapError(f"{path}: '{name}' holds a NaN or infinite value")
    return array


def _robot(entry: Any, name: str, path: Path) -> SavedRobot:
    if not isinstance(entry, dict):
        raise SavedMapError(f"{path}: '{name}' is not an object")
    placement = entry.get("placement")
    pose: Pose | None = None
    if placement is not None:
        values = _numbers(placement, 3, f"{name}.placement", path)
        if len(values) != 1:
            raise SavedMapError(f"{path}: '{name}.placement' must be [x, y, theta] or null")
        pose = (float(values[0, 0]), float(values[0, 1]), float(values[0, 2]))
    stamp = entry.get("map_stamp")
    map_stamp: tuple[int, int] | None = None
    if stamp is not None:
        if not (
            isinstance(stamp, list)
            and len(stamp) == 2
            and all(isinstance(v, int) and v >= 0 for v in stamp)
        ):
            raise SavedMapError(f"{path}: '{name}.map_stamp' must be [sec, nanosec] or null")
        map_stamp = (int(stamp[0]), int(stamp[1]))
    session = entry.get("session")
    if session is not None and not (
        isinstance(session, int | float) and math.isfinite(float(session))
    ):
        raise SavedMapError(f"{path}: '{name}.session' must be a number or null")
    frame = entry.get("map_frame", "")
    if not isinstance(frame, str):
        raise SavedMapError(f"{path}: '{name}.map_frame' must be a string")
    session_of = entry.get("session_of")
    if session_of is not None and not isinstance(session_of, str):
        raise SavedMapError(f"{path}: '{name}.session_of' must be a robot name or null")
    probability = entry.get("probability")
    if probability is not None and not (
        isinstance(probability, int | float) and 0.0 <= float(probability) <= 1.0
    ):
        raise SavedMapError(f"{path}: '{name}.probability' must be a number in [0, 1] or null")
    return SavedRobot(
        map_frame=frame,
        session=None if session is None else float(session),
        map_stamp=map_stamp,
        placement=pose,
        segments=_numbers(entry.get("segments"), 4, f"{name}.segments", path),
        keyframe_poses=_numbers(entry.get("keyframe_poses"), 3, f"{name}.keyframe_poses", path),
        session_of=session_of,
        probability=None if probability is None else float(probability),
    )
