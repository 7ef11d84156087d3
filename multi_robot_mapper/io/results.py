"""The replay output folder: what ``mrm replay`` writes and ``mrm evaluate`` reads.

Layout of ``DIR``:

- ``map.json``: ``{"method", "frame": "map", "robots": [...], "segments": [[x1, y1, x2, y2], ...],
  "segment_robot": [...]}``; segments in metres in the global ``map`` frame, ``segment_robot``
  the index into ``robots`` of the robot each segment came from;
- ``trajectories/<robot>.tum``: one line per posed scan, ``stamp x y z qx qy qz qw`` (TUM
  format; stamp in seconds, z = 0, a yaw-only quaternion), poses in ``map``. Stamps are written
  with ``%.9f``, enough digits to give back the same float64, so they associate exactly;
- ``robots.json``: ``{robot: {"x", "y", "theta", "probability"}}`` (the pose of ``<robot>/map``
  in ``map``, and the probability that it is right when the method says) or
  ``{robot: "unmerged: <why>"}`` (``"unmerged"`` alone where no reason is known);
- ``stats.json``: a JSON object of timings and counts;
- ``replay.json`` (written by ``mrm replay`` since issue 48; absent from older folders and from
  results not made from bags): what was read and how, so ``mrm evaluate DIR`` can read it again
  alike: ``{"bags": [absolute path, ...], "names": [name, ...] or null, "scan_topics":
  "PATTERNS", "beam_geometry": "SPEC", "truth": [absolute path, ...]}`` (the options of
  ``multi_robot_mapper.cli.recordings``; ``truth`` empty: the bags' ground_truth topics).

Pictures (``map.png``, ``map.svg``) live in the same folder but are not this module's business.
Every problem reading the folder raises :class:`ResultsError` with one line naming the file.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.geometry import quaternion_from_yaw, yaw_from_quaternion
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.io.outputs import atomic_file, atomic_write_text

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

MAP_FILE = "map.json"
ROBOTS_FILE = "robots.json"
STATS_FILE = "stats.json"
REPLAYED_FILE = "replay.json"
TRAJECTORY_DIR = "trajectories"
UNMERGED = "unmerged"


class ResultsError(Exception):
    """A result folder that is missing a file or holds a malformed one (message names the file)."""


@dataclasses.dataclass(frozen=True)
class ReplayedBags:
    """The bags ``mrm replay`` read and the options it read them with (``replay.json``)."""

    bags: tuple[Path, ...]  # absolute, in the order given
    names: tuple[str, ...] | None  # --names, one per bag; None: from the topics or files
    scan_topics: str  # --scan-topics
    beam_geometry: str  # --beam-geometry
    truth_files: tuple[Path, ...] = ()  # --truth, absolute; empty: the ground_truth topics


@dataclasses.dataclass
class ReplayResult:
    """Everything ``mrm replay`` writes except pictures, in the global ``map`` frame."""

    method: str  # "reference", "pivot", "ffs"
    robots: list[str]
    map_segments: FloatArray  # (M, 4) [x1, y1, x2, y2] in map
    segment_robot: IntArray  # (M,) index into robots
    # robot -> (stamps (N,) s, poses (N, 3) x, y, theta in map); posed scans only
    trajectories: dict[str, tuple[FloatArray, FloatArray]]
    robot_frames: dict[str, Pose | None]  # T_map_<robot>/map as (x, y, theta); None = unmerged
    stats: dict[str, Any]
    # robot -> P(its placement is right) (merged robots, when the method says); robot -> why
    # it is not placed (unmerged robots)
    probabilities: dict[str, float] = dataclasses.field(default_factory=dict)
    unmerged_reasons: dict[str, str] = dataclasses.field(default_factory=dict)
    # None: not made from bags, or by an mrm replay from before replay.json
    replayed: ReplayedBags | None = None


def trajectory_path(directory: Path, robot: str) -> Path:
    return Path(directory) / TRAJECTORY_DIR / f"{robot}.tum"


# --------------------------------------------------------------------------------------- write


def write_results(directory: Path, result: ReplayResult) -> None:
    """Write ``result`` into ``directory`` (created if needed; existing files are replaced)."""
    directory = Path(directory)
    segments = np.asarray(result.map_segments, dtype=np.float64).reshape(-1, 4)
    owners = np.asarray(result.segment_robot, dtype=np.int64).ravel()
    if len(owners) != len(segments):
        raise ValueError(f"{len(segments)} segments but {len(owners)} segment_robot entries")
    if len(owners) and (owners.min() < 0 or owners.max() >= len(result.robots)):
        raise ValueError("segment_robot holds an index outside robots")
    directory.mkdir(parents=True, exist_ok=True)
    (directory / TRAJECTORY_DIR).mkdir(exist_ok=True)
    _write_json(
        directory / MAP_FILE,
        {
            "method": result.method,
            "frame": "map",
            "robots": list(result.robots),
            # repr-exact floats: json writes the shortest string that reads back the same float
            "segments": segments.tolist(),
            "segment_robot": owners.tolist(),
        },
    )
    for robot in result.robots:
        stamps, poses = result.trajectories.get(robot, (np.zeros(0), np.zeros((0, 3))))
        write_tum(trajectory_path(directory, robot), stamps, poses)
    frames: dict[str, Any] = {}
    for robot in result.robots:
        frame = result.robot_frames.get(robot)
        if frame is None:
            why = result.unmerged_reasons.get(robot)
            frames[robot] = f"{UNMERGED}: {why}" if why else UNMERGED
            continue
        frames[robot] = {"x": float(frame[0]), "y": float(frame[1]), "theta": float(frame[2])}
        if robot in result.probabilities:
            frames[robot]["probability"] = float(result.probabilities[robot])
    _write_json(directory / ROBOTS_FILE, frames)
    _write_json(directory / STATS_FILE, result.stats)
    replayed_path = directory / REPLAYED_FILE
    if result.replayed is None:
        # A record left by an earlier write would name bags this result was not made from.
        replayed_path.unlink(missing_ok=True)
    else:
        _write_json(replayed_path, _replayed_json(result.replayed))


def _replayed_json(replayed: ReplayedBags) -> dict[str, Any]:
    return {
        "bags": [str(path) for path in replayed.bags],
        "names": None if replayed.names is None else list(replayed.names),
        "scan_topics": replayed.scan_topics,
        "beam_geometry": replayed.beam_geometry,
        "truth": [str(path) for path in replayed.truth_files],
    }


def write_tum(path: Path, stamps: FloatArray, poses: FloatArray) -> None:
    """Write planar poses ``(N, 3)`` as a TUM trajectory (z = 0, yaw-only quaternion)."""
    stamps = np.asarray(stamps, dtype=np.float64).ravel()
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(stamps) != len(poses):
        raise ValueError(f"{len(stamps)} stamps but {len(poses)} poses for {path}")
    qx, qy, qz, qw = quaternion_from_yaw(poses[:, 2])
    table = np.column_stack(
        (stamps, poses[:, 0], poses[:, 1], np.zeros(len(poses)), qx, qy, qz, qw)
    )
    # %.9f for stamps (nanoseconds; exact float64 round trip for epoch stamps), %.17g for the
    # rest (exact float64 round trip).
    fmt = ["%.9f"] + ["%.17g"] * 7
    with atomic_file(path) as stream:
        np.savetxt(stream, table, fmt=fmt, header="timestamp x y z qx qy qz qw", comments="# ")


def _write_json(path: Path, data: Any) -> None:
    atomic_write_text(path, json.dumps(data, indent=1, default=_json_default) + "\n")


def _json_default(value: Any) -> Any:
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


# ---------------------------------------------------------------------------------------- read


def read_results(directory: Path) -> ReplayResult:
    """Read a folder written by :func:`write_results`; raises :class:`ResultsError`."""
    directory = Path(directory)
    if not directory.is_dir():
        raise ResultsError(f"{directory}: no such result folder")
    method, robots, segments, owners = _read_map(directory / MAP_FILE)
    trajectories = {robot: read_tum(trajectory_path(directory, robot)) for robot in robots}
    frames, probabilities, reasons = _read_robot_frames(directory / ROBOTS_FILE, robots)
    stats_path = directory / STATS_FILE
    stats = _read_json(stats_path)
    if not isinstance(stats, dict):
        raise ResultsError(f"{stats_path}: expected a JSON object")
    return ReplayResult(
        method=method,
        robots=list(robots),
        map_segments=segments.astype(np.float64),
        segment_robot=owners.astype(np.int64),
        trajectories=trajectories,
        robot_frames=frames,
        stats=stats,
        probabilities=probabilities,
        unmerged_reasons=reasons,
        replayed=read_replayed(directory / REPLAYED_FILE),
    )


def _read_map(map_path: Path) -> tuple[str, list[str], FloatArray, FloatArray]:
    """``map.json``: the method, the robots, the segments and each segment's robot index
    (still as read: numbers, checked to be whole)."""
    data = _read_json(map_path)
    if not isinstance(data, dict):
        raise ResultsError(f"{map_path}: expected a JSON object")
    method = data.get("method")
    if not isinstance(method, str):
        raise ResultsError(f"{map_path}: 'method' must be a string")
    if data.get("frame", "map") != "map":
        raise ResultsError(f"{map_path}: 'frame' is {data.get('frame')!r}, expected 'map'")
    robots = data.get("robots")
    if (
        not isinstance(robots, list)
        or not all(isinstance(r, str) and _safe_name(r) for r in robots)
        or len(set(robots)) != len(robots)
    ):
        raise ResultsError(f"{map_path}: 'robots' must be a list of distinct robot names")
    segments = _number_array(data.get("segments"), map_path, "segments")
    if segments.size == 0:
        segments = segments.reshape(0, 4)
    if segments.ndim != 2 or segments.shape[1] != 4 or not np.all(np.isfinite(segments)):
        raise ResultsError(f"{map_path}: 'segments' must be a list of [x1, y1, x2, y2] numbers")
    owners = _number_array(data.get("segment_robot"), map_path, "segment_robot")
    if owners.ndim != 1 or len(owners) != len(segments):
        raise ResultsError(
            f"{map_path}: 'segment_robot' must hold one index per segment ({len(segments)})"
        )
    if len(owners) and (
        not np.all(owners == np.round(owners)) or owners.min() < 0 or owners.max() >= len(robots)
    ):
        raise ResultsError(
            f"{map_path}: 'segment_robot' holds an index outside 0..{len(robots) - 1}"
        )
    return method, robots, segments, owners


def _read_robot_frames(
    frames_path: Path, robots: list[str]
) -> tuple[dict[str, Pose | None], dict[str, float], dict[str, str]]:
    """``robots.json``: each robot's frame in ``map`` (None: unmerged), the probabilities of
    the merged robots that have one, and why each unmerged robot with a reason is."""
    frames_data = _read_json(frames_path)
    if not isinstance(frames_data, dict):
        raise ResultsError(f"{frames_path}: expected a JSON object robot -> pose or 'unmerged'")
    frames: dict[str, Pose | None] = {}
    probabilities: dict[str, float] = {}
    reasons: dict[str, str] = {}
    for robot in robots:
        if robot not in frames_data:
            raise ResultsError(f"{frames_path}: robot {robot!r} is missing")
        entry = frames_data[robot]
        frames[robot] = _parse_frame(entry, frames_path, robot)
        if isinstance(entry, dict) and _finite_number(entry.get("probability")):
            probabilities[robot] = float(entry["probability"])
        if isinstance(entry, str) and entry.startswith(f"{UNMERGED}: "):
            reasons[robot] = entry[len(UNMERGED) + 2 :]
    return frames, probabilities, reasons


def read_replayed(path: Path) -> ReplayedBags | None:
    """``replay.json``: the bags and options ``mrm replay`` read (None when the file is absent:
    a folder from before the record, or a result not made from bags)."""
    if not path.exists():
        return None
    data = _read_json(path)
    if not isinstance(data, dict):
        raise ResultsError(f"{path}: expected a JSON object with 'bags' and the reading options")
    bags = _absolute_paths(data.get("bags"), path, "bags")
    if not bags:
        raise ResultsError(f"{path}: 'bags' must name at least one bag")
    names = data.get("names")
    if names is not None and not (
        isinstance(names, list) and all(isinstance(n, str) and n for n in names)
    ):
        raise ResultsError(f"{path}: 'names' must be null or a list of robot names")
    texts = {key: data.get(key) for key in ("scan_topics", "beam_geometry")}
    for key, value in texts.items():
        if not isinstance(value, str) or not value:
            raise ResultsError(f"{path}: '{key}' must be a non-empty string")
    return ReplayedBags(
        bags=bags,
        names=None if names is None else tuple(names),
        scan_topics=str(texts["scan_topics"]),
        beam_geometry=str(texts["beam_geometry"]),
        truth_files=_absolute_paths(data.get("truth"), path, "truth"),
    )


def _absolute_paths(value: Any, path: Path, key: str) -> tuple[Path, ...]:
    # Relative paths would be read from wherever mrm evaluate happens to run: refused.
    if not isinstance(value, list) or not all(
        isinstance(v, str) and Path(v).is_absolute() for v in value
    ):
        raise ResultsError(f"{path}: '{key}' must be a list of absolute paths")
    return tuple(Path(v) for v in value)


def read_tum(path: Path) -> tuple[FloatArray, FloatArray]:
    """A TUM trajectory as ``(stamps (N,), poses (N, 3))``; yaw from the quaternion.

    Blank lines and lines starting with ``#`` are skipped. Raises :class:`ResultsError`.
    """
    path = Path(path)
    text = _read_text(path, "missing trajectory file")
    rows: list[list[float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = stripped.split()
        if len(fields) != 8:
            raise ResultsError(
                f"{path}:{number}: expected 8 fields 'stamp x y z qx qy qz qw', got {len(fields)}"
            )
        try:
            values = [float(f) for f in fields]
        except ValueError:
            raise ResultsError(f"{path}:{number}: not a number in {stripped!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise ResultsError(f"{path}:{number}: non-finite value in {stripped!r}")
        rows.append(values)
    table = np.asarray(rows, dtype=np.float64).reshape(-1, 8)
    stamps = table[:, 0]
    if np.any(np.diff(stamps) <= 0.0):
        raise ResultsError(f"{path}: stamps are not strictly increasing")
    qx, qy, qz, qw = table[:, 4], table[:, 5], table[:, 6], table[:, 7]
    norm = np.sqrt(qx**2 + qy**2 + qz**2 + qw**2)
    if np.any(np.abs(norm - 1.0) > 1e-6):
        raise ResultsError(f"{path}: a quaternion is not of unit length")
    yaw = yaw_from_quaternion(qx, qy, qz, qw)
    poses = np.column_stack((table[:, 1], table[:, 2], yaw))
    return stamps.copy(), poses


def _read_text(path: Path, missing: str = "missing") -> str:
    """The text of ``path``; :class:`ResultsError` (``"<path>: <missing>"``) when it is absent."""
    try:
        return path.read_text()
    except FileNotFoundError:
        raise ResultsError(f"{path}: {missing}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ResultsError(f"{path}: cannot read: {exc}") from None


def _read_json(path: Path) -> Any:
    text = _read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ResultsError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None


def _number_array(value: Any, path: Path, key: str) -> FloatArray:
    if not isinstance(value, list):
        raise ResultsError(f"{path}: '{key}' must be a list")
    try:
        array: FloatArray = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ResultsError(f"{path}: '{key}' must hold only numbers") from None
    if any(isinstance(v, bool) for v in np.ravel(np.asarray(value, dtype=object))):
        raise ResultsError(f"{path}: '{key}' must hold only numbers")
    return array


def _finite_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _parse_frame(value: Any, path: Path, robot: str) -> Pose | None:
    if value == UNMERGED or (isinstance(value, str) and value.startswith(f"{UNMERGED}: ")):
        return None
    if isinstance(value, dict) and {"x", "y", "theta"} <= set(value):
        pose = (value["x"], value["y"], value["theta"])
        if all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in pose
        ):
            return (float(pose[0]), float(pose[1]), float(pose[2]))
    raise ResultsError(
        f"{path}: robot {robot!r} must be {{'x', 'y', 'theta'}} numbers or 'unmerged[: why]'"
    )


def _safe_name(name: str) -> bool:
    """A robot name usable as a file name (namespaces like 'robot1', never a path)."""
    return bool(name) and "/" not in name and "\\" not in name and name not in (".", "..")
