"""rosbag2 recordings of several robots' laser scans (and ground truth), read and written.

A recording holds, per robot ``<name>``, ``/<name>/scan`` (``sensor_msgs/msg/LaserScan``) and
optionally ``/<name>/ground_truth`` (``geometry_msgs/msg/PoseStamped``); a bag of one robot may
call its scans plain ``/scan``. Bags are read and written with ``rosbags`` (pure Python, no ROS
installation): a rosbag2 directory with ``metadata.yaml`` in mcap or sqlite3 storage, or a bare
``.mcap`` file; a ROS 1 ``.bag`` file is read too (its messages decoded with the definitions it
carries). Written messages are the ``rosbags`` dataclasses of the ROS 2 Jazzy typestore, so no
rclpy is needed.

Every problem with a file becomes a :class:`BagError` subclass with a one-line message naming
the file; ``rosbags``' own exceptions never escape.
"""

from __future__ import annotations

import contextlib
import fnmatch
import re
import sqlite3
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

import apsw  # rosbags' sqlite3 storage reads through apsw
import numpy as np
import yaml
from mcap.exceptions import McapError
from rosbags.interfaces import Connection
from rosbags.rosbag1 import Reader as Ros1Reader
from rosbags.rosbag1 import ReaderError as Ros1ReaderError
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from multi_robot_mapper.core.geometry import (
    quaternion_from_yaw,
    split_stamp,
    stamp_seconds,
    yaw_from_quaternion,
)
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import SimulatedRobot
from multi_robot_mapper.io.mcap_chunks import Salvage, add_chunk_checksums
from multi_robot_mapper.io.mcap_chunks import salvage as salvage_chunks
from multi_robot_mapper.io.outputs import OutputError, staged_new

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"
GROUND_TRUTH = "ground_truth"
# The scan topics read unless told otherwise (comma-separated fnmatch patterns): every robot's
# namespaced scans, and the plain /scan of a bag that holds one robot.
DEFAULT_SCAN_TOPICS = "/*/scan,/scan"
# The robot of a scan topic without a namespace.
UNNAMED_ROBOT = "robot"
# builtin_interfaces/Time counts seconds in an int32, bags count ns since 1970 unsigned.
_MAX_STAMP_S = 2.0**31
# A ROS namespace: tokens of letters, digits and underscores, not starting with a digit.
_ROBOT_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")

# What rosbags (and the storage libraries under it) raise on damaged input. A broken file can
# fail deep inside a parser, so the usual low-level errors are included; programming errors
# (AttributeError, NameError, ...) are deliberately not.
_READ_ERRORS = (
    ReaderError,
    Ros1ReaderError,
    TypesysError,  # a ROS 1 bag's message definition that cannot be parsed
    SerdeError,
    OSError,
    EOFError,
    ValueError,
    LookupError,
    struct.error,
    sqlite3.Error,
    apsw.Error,
    OverflowError,  # a damaged length field
    MemoryError,  # a damaged length field asking for a huge buffer
    TypeError,  # e.g. ord() of a missing byte in a file cut short
    AssertionError,  # rosbags asserts on MCAP record layouts
)


class BagError(Exception):
    """A bag cannot be read or written; the message names the file and the problem."""


class BagNotFoundError(BagError):
    """The bag path does not exist."""


class BagCorruptError(BagError):
    """The file is empty, truncated, not a bag, or its metadata cannot be read."""


class UnknownMessageTypeError(BagError):
    """A selected topic carries a message type this module cannot read."""


class NoScanTopicsError(BagError):
    """No topic of the bag matches the scan pattern."""


@dataclass(frozen=True)
class TimedScan:
    """One LaserScan: header stamp, frame and geometry."""

    stamp: float  # header stamp, s
    frame_id: str
    scan: LaserScanData


@dataclass(frozen=True)
class TimedPose:
    """One pose of the robot's laser in ``frame_id``: ``(x, y, theta)`` in m, m, rad."""

    stamp: float  # header stamp, s
    pose: tuple[float, float, float]
    frame_id: str


@dataclass
class RobotRecording:
    """Everything one robot recorded, sorted by stamp."""

    name: str  # the topic namespace: "robot1" for /robot1/scan
    scans: list[TimedScan]
    ground_truth: list[TimedPose] = field(default_factory=list)


def recording_of(name: str, run: SimulatedRobot) -> RobotRecording:
    """A simulated run as a robot's recording: scans in frame ``<name>/laser`` and the true
    laser poses as ground truth in ``world``."""
    stamps = run.stamps.tolist()
    return RobotRecording(
        name=name,
        scans=[
            TimedScan(t, f"{name}/laser", scan) for t, scan in zip(stamps, run.scans, strict=True)
        ],
        ground_truth=[
            TimedPose(t, (x, y, theta), "world")
            for t, (x, y, theta) in zip(stamps, run.T_world_laser.tolist(), strict=True)
        ],
    )


@lru_cache(maxsize=1)
def _typestore() -> Typestore:
    return get_typestore(Stores.ROS2_JAZZY)


def robot_name(topic: str) -> str:
    """The robot a scan topic belongs to: its namespace ("/robot1/scan" -> "robot1").

    A scan topic without a namespace ("/scan") belongs to "robot".
    """
    namespace = topic.rsplit("/", 1)[0].strip("/")
    return namespace or UNNAMED_ROBOT


def valid_robot_name(name: str) -> bool:
    """Whether ``name`` can be a ROS topic namespace (what a robot's name becomes)."""
    return _ROBOT_NAME.fullmatch(name) is not None


def matches_scan_topics(topic: str, patterns: str) -> bool:
    """Whether ``topic`` matches one of the comma-separated fnmatch ``patterns``."""
    return any(fnmatch.fnmatchcase(topic, p.strip()) for p in patterns.split(",") if p.strip())


def _natural_key(name: str) -> list[tuple[int, int | str]]:
    """Sort key putting "robot2" before "robot10"."""
    return [(0, int(part)) if part.isdigit() else (1, part) for part in re.split(r"(\d+)", name)]


def _stamp_seconds(stamp: Any) -> float:
    return stamp_seconds(int(stamp.sec), int(stamp.nanosec))


def _stamp_msg(seconds: float) -> Any:
    sec, nanosec = split_stamp(seconds)
    return _typestore().types["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nanosec))


def _stamp_ns(seconds: float) -> int:
    stamp = _stamp_msg(seconds)
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _yaw(q: Any) -> float:
    """Rotation about z of a quaternion (the planar part of any orientation)."""
    return float(yaw_from_quaternion(q.x, q.y, q.z, q.w))


def _scan_from_msg(msg: Any) -> TimedScan:
    # Only the length is checked downstream: keep the stored float32 values, no copy.
    intensities = np.asarray(msg.intensities)
    ranges = np.asarray(msg.ranges, dtype=np.float64)
    return TimedScan(
        stamp=_stamp_seconds(msg.header.stamp),
        frame_id=str(msg.header.frame_id),
        scan=LaserScanData(
            ranges=ranges,
            angle_min=float(msg.angle_min),
            angle_max=float(msg.angle_max),
            angle_increment=float(msg.angle_increment),
            range_min=float(msg.range_min),
            range_max=float(msg.range_max),
            intensities=intensities if intensities.size else None,
        ),
    )


def _pose_from_msg(msg: Any) -> TimedPose:
    p = msg.pose.position
    return TimedPose(
        stamp=_stamp_seconds(msg.header.stamp),
        pose=(float(p.x), float(p.y), _yaw(msg.pose.orientation)),
        frame_id=str(msg.header.frame_id),
    )


def _scan_msg(item: TimedScan) -> Any:
    types = _typestore().types
    scan = item.scan
    intensities = (
        np.asarray(scan.intensities, dtype=np.float32).ravel()
        if scan.intensities is not None
        else np.zeros(0, dtype=np.float32)
    )
    return types[SCAN_TYPE](
        header=types["std_msgs/msg/Header"](stamp=_stamp_msg(item.stamp), frame_id=item.frame_id),
        angle_min=float(scan.angle_min),
        angle_max=float(scan.angle_max),
        angle_increment=float(scan.angle_increment),
        time_increment=0.0,  # unknown: the beams' own timing is not recorded
        scan_time=0.0,
        range_min=float(scan.range_min),
        range_max=float(scan.range_max),
        ranges=np.asarray(scan.ranges, dtype=np.float32).ravel(),
        intensities=intensities,
    )


def _pose_msg(item: TimedPose) -> Any:
    types = _typestore().types
    x, y, theta = item.pose
    return types[POSE_TYPE](
        header=types["std_msgs/msg/Header"](stamp=_stamp_msg(item.stamp), frame_id=item.frame_id),
        pose=types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](
                **dict(zip("xyzw", map(float, quaternion_from_yaw(theta)), strict=True))
            ),
        ),
    )


def _open_reader(path: Path, hint: str = "") -> Reader | Ros1Reader:
    """A rosbags reader for a bag directory, a bare ``.mcap``/``.db3`` file or a ROS 1 bag."""
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise BagCorruptError(
                f"{path}: not a rosbag2 directory (no metadata.yaml; "
                "`ros2 bag reindex` can rebuild it)"
            )
    elif path.suffix not in (".mcap", ".db3", ".bag"):
        raise BagCorruptError(
            f"{path}: not a bag (expected a rosbag2 directory, a .mcap file or a ROS 1 .bag file)"
        )
    elif path.stat().st_size == 0:
        raise BagCorruptError(f"{path}: the file is empty")
    try:
        reader: Reader | Ros1Reader = Ros1Reader(path) if _is_ros1(path) else Reader(path)
        reader.open()
    except _READ_ERRORS as exc:
        raise BagCorruptError(f"{path}: cannot open the bag ({_reason(exc)}){hint}") from None
    return reader


def _is_ros1(path: Path) -> bool:
    return path.is_file() and path.suffix == ".bag"


def _ros1_decoder(connections: list[Connection]) -> Any:
    """``deserialize(raw, msgtype)`` for the messages of a ROS 1 bag, with the message
    definitions the bag carries (the standard ROS 1 Noetic ones if it carries none)."""
    types: dict[str, Any] = {}
    for connection in connections:
        if connection.msgdef.data:
            types.update(get_types_from_msg(connection.msgdef.data, connection.msgtype))
    if not types:
        return get_typestore(Stores.ROS1_NOETIC).deserialize_ros1
    typestore = get_typestore(Stores.EMPTY)
    typestore.register(types)
    return typestore.deserialize_ros1


def _reason(exc: BaseException) -> str:
    """One line for an exception from rosbags or the storage layers."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


@dataclass
class ReadReport:
    """What :func:`read_recordings` left out of a bag it could read: empty when it read all."""

    notes: list[str] = field(default_factory=list)
    salvage: Salvage | None = None


def read_recordings(
    path: str | Path,
    scan_pattern: str = DEFAULT_SCAN_TOPICS,
    *,
    salvage: bool = False,
    report: ReadReport | None = None,
) -> dict[str, RobotRecording]:
    """Every robot's scans (and ground truth, when recorded) from a rosbag2 or ROS 1 bag.

    ``scan_pattern`` is one or more comma-separated ``fnmatch`` patterns on topic names; each
    matching topic is one robot, named by its namespace (:func:`robot_name`). Ground truth is
    read from
    ``<namespace>/ground_truth`` when that topic exists. Lists are sorted by header stamp.
    A topic of another message type is left out (and said in ``report``) while others remain;
    a damaged MCAP file is refused unless ``salvage``, which reads every intact chunk.
    """
    path = Path(path)
    report = report if report is not None else ReadReport()
    if not path.exists():
        raise BagNotFoundError(f"{path}: no such bag file or directory")
    if salvage:
        return _read_salvaged(path, scan_pattern, report)
    hint = "; --salvage reads every intact chunk" if _mcap_file(path) is not None else ""
    if _is_ros1(path):
        hint = "; `rosbag reindex` rebuilds the index of a ROS 1 bag whose recording was cut short"
    reader = _open_reader(path, hint)
    try:
        topics: dict[str, list[Connection]] = {}
        for connection in reader.connections:
            topics.setdefault(connection.topic, []).append(connection)
        types = {topic: {c.msgtype for c in conns} for topic, conns in topics.items()}
        wanted = _select(types, path, scan_pattern, report)
        selected = [c for topic in wanted for c in topics[topic]]
        messages = (
            (c.topic, c.msgtype, raw) for c, _, raw in reader.messages(connections=selected)
        )
        expected = {t: sum(c.msgcount for c in topics[t]) for t in wanted}
        if isinstance(reader, Ros1Reader):
            decode = _ros1_decoder(selected)
            return _decode(messages, wanted, expected, "the bag's index", report, decode)
        return _decode(messages, wanted, expected, "metadata.yaml", report)
    except BagError:
        raise
    except _READ_ERRORS as exc:
        raise BagCorruptError(f"{path}: cannot read the bag ({_reason(exc)}){hint}") from None
    finally:
        # Closing a damaged file may fail too; the read error above is the one to report.
        with contextlib.suppress(*_READ_ERRORS):
            reader.close()


def _mcap_file(path: Path) -> Path | None:
    """The MCAP file of a bag (a bare ``.mcap``, or the one in a bag directory), if any."""
    if path.is_file():
        return path if path.suffix == ".mcap" else None
    files = sorted(path.glob("*.mcap")) if path.is_dir() else []
    return files[0] if len(files) == 1 else None


def _read_salvaged(path: Path, scan_pattern: str, report: ReadReport) -> dict[str, RobotRecording]:
    """:func:`read_recordings` on whatever chunks of a damaged MCAP file are intact."""
    mcap = _mcap_file(path)
    if mcap is None:
        raise BagError(f"{path}: --salvage reads MCAP bags (one .mcap file) only")
    report.salvage = Salvage()
    try:
        messages = list(salvage_chunks(mcap, report.salvage))
    except OSError as exc:
        raise BagCorruptError(f"{path}: cannot read ({_reason(exc)})") from None
    types: dict[str, set[str]] = {}
    for topic, msgtype, _, _ in messages:
        types.setdefault(topic, set()).add(msgtype)
    wanted = _select(types, path, scan_pattern, report)
    report.notes.append(f"{mcap.name}: {report.salvage.describe()}")
    expected = _metadata_counts(path) if path.is_dir() else {}
    picked = ((t, m, raw) for t, m, _, raw in messages if t in wanted)
    try:
        return _decode(picked, wanted, expected, "metadata.yaml", report)
    except _READ_ERRORS as exc:
        raise BagCorruptError(
            f"{path}: cannot decode a salvaged message ({_reason(exc)})"
        ) from None


def _metadata_counts(path: Path) -> dict[str, int]:
    """Messages per topic as a bag directory's metadata.yaml has them ({} if unreadable)."""
    try:
        info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        return {
            str(t["topic_metadata"]["name"]): int(t["message_count"])
            for t in info["topics_with_message_count"]
        }
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError):
        return {}


def _select(
    types: dict[str, set[str]], path: Path, scan_pattern: str, report: ReadReport
) -> dict[str, tuple[str, str]]:
    """topic -> (robot, "scan" or "truth") of the topics to read; a topic of another message
    type is left out with a note, and an error only when no scan topic remains."""
    scan_topics = sorted(t for t in types if matches_scan_topics(t, scan_pattern))
    if not scan_topics:
        known = ", ".join(sorted(types)) or "none"
        raise NoScanTopicsError(f"{path}: no topic matches {scan_pattern!r} (topics: {known})")
    wanted: dict[str, tuple[str, str]] = {}
    refused: list[str] = []
    for topic in scan_topics:
        name = robot_name(topic)
        for other, (robot, _) in wanted.items():
            if robot == name:
                raise BagError(f"{path}: topics {other} and {topic} both name robot {name!r}")
        truth = f"{topic.rsplit('/', 1)[0]}/{GROUND_TRUTH}"
        for candidate, kind, expected in ((topic, "scan", SCAN_TYPE), (truth, "truth", POSE_TYPE)):
            if candidate not in types:
                continue
            odd = sorted(types[candidate] - {expected})
            if odd:
                refused.append(f"topic {candidate} has type {', '.join(odd)}, expected {expected}")
                if kind == "scan":
                    break  # no scans: no robot (and its ground truth is of no use)
                continue
            wanted[candidate] = (name, kind)
    if not any(kind == "scan" for _, kind in wanted.values()):
        raise UnknownMessageTypeError(f"{path}: {'; '.join(refused)}")
    report.notes.extend(f"{path}: {reason}: left out" for reason in refused)
    return wanted


def _decode(
    messages: Iterable[tuple[str, str, bytes]],
    wanted: dict[str, tuple[str, str]],
    expected: dict[str, int],
    source: str,
    report: ReadReport,
    deserialize: Any = None,
) -> dict[str, RobotRecording]:
    recordings = {
        name: RobotRecording(name=name, scans=[], ground_truth=[])
        for name, kind in wanted.values()
        if kind == "scan"
    }
    counts: dict[str, int] = dict.fromkeys(wanted, 0)
    deserialize = deserialize or _typestore().deserialize_cdr
    for topic, msgtype, raw in messages:
        name, kind = wanted[topic]
        msg = deserialize(raw, msgtype)
        counts[topic] += 1
        if kind == "scan":
            recordings[name].scans.append(_scan_from_msg(msg))
        else:
            recordings[name].ground_truth.append(_pose_from_msg(msg))
    for topic, count in counts.items():
        if topic in expected and expected[topic] != count:
            report.notes.append(
                f"{source} counts {expected[topic]} messages on {topic}, the bag holds {count}"
            )
    for recording in recordings.values():
        recording.scans.sort(key=lambda item: item.stamp)  # stable: equal stamps keep bag order
        recording.ground_truth.sort(key=lambda item: item.stamp)
    return dict(sorted(recordings.items(), key=lambda item: _natural_key(item[0])))


def write_recordings(
    path: str | Path,
    recordings: Mapping[str, RobotRecording],
    storage: Literal["mcap", "sqlite3"] = "mcap",
) -> Path:
    """Write recordings as a new rosbag2 directory at ``path``; returns ``path``.

    Per robot ``/<name>/scan`` (LaserScan, ``header.frame_id`` of each :class:`TimedScan`) and,
    when there is ground truth, ``/<name>/ground_truth`` (PoseStamped, ``frame_id`` of each
    :class:`TimedPose`). Receive timestamps are the header stamps, so replay keeps the timing.
    An existing ``path`` is never overwritten.
    """
    path = Path(path)
    plugins = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
    if storage not in plugins:
        raise BagError(f"{path}: unknown storage {storage!r} (mcap or sqlite3)")
    if path.exists() or path.is_symlink():
        raise BagError(f"{path}: already exists; not overwriting it")
    # Messages go in stamp order across robots, as a recorder would have received them.
    messages: list[tuple[int, int, str, Any]] = []  # (ns, order, topic, message)
    for name, recording in recordings.items():
        if not valid_robot_name(name):
            raise BagError(f"{path}: robot name {name!r} cannot be a ROS topic namespace")
        topics = (
            (f"/{name}/scan", recording.scans),
            (f"/{name}/{GROUND_TRUTH}", recording.ground_truth),
        )
        for topic, items in topics:
            for item in items:
                if not 0.0 <= item.stamp < _MAX_STAMP_S:  # also refuses NaN
                    raise BagError(
                        f"{path}: a message of {topic} has stamp {item.stamp} s, outside what "
                        f"a bag stores (0 .. 2^31 s)"
                    )
                messages.append((_stamp_ns(item.stamp), len(messages), topic, item))
    messages.sort(key=lambda m: (m[0], m[1]))
    try:
        with staged_new(path) as staging:  # an interrupted write leaves no half bag at path
            _write_messages(staging, path, recordings, messages, plugins[storage])
            for mcap in staging.glob("*.mcap"):  # rosbags writes chunks without checksums
                add_chunk_checksums(mcap)
    except (OSError, OutputError, McapError) as exc:
        raise BagError(f"{path}: cannot create the bag ({_reason(exc)})") from None
    return path


def _write_messages(
    staging: Path,
    path: Path,
    recordings: Mapping[str, RobotRecording],
    messages: list[tuple[int, int, str, Any]],
    plugin: StoragePlugin,
) -> None:
    serialize = _typestore().serialize_cdr
    write_errors = (WriterError, OSError, sqlite3.Error, ValueError, OverflowError, struct.error)
    try:
        bag = Writer(staging, version=Writer.VERSION_LATEST, storage_plugin=plugin)
        bag.open()
    except write_errors as exc:
        raise BagError(f"{path}: cannot create the bag ({_reason(exc)})") from None
    try:
        connections: dict[str, Connection] = {}
        for name, recording in recordings.items():
            topic = f"/{name}/scan"
            connections[topic] = bag.add_connection(topic, SCAN_TYPE, typestore=_typestore())
            if recording.ground_truth:
                topic = f"/{name}/{GROUND_TRUTH}"
                connections[topic] = bag.add_connection(topic, POSE_TYPE, typestore=_typestore())
        for ns, _, topic, item in messages:
            if isinstance(item, TimedScan):
                data = serialize(_scan_msg(item), SCAN_TYPE)
            else:
                data = serialize(_pose_msg(item), POSE_TYPE)
            bag.write(connections[topic], ns, data)
        bag.close()
    except (*write_errors, SerdeError) as exc:
        with contextlib.suppress(*write_errors):  # the first error is the one to report
            bag.abort()
        raise BagError(f"{path}: cannot write the bag ({_reason(exc)})") from None


# A scan takes the ground-truth pose stamped nearest to it when within this (replay, evaluate).
GROUND_TRUTH_MATCH_S = 0.02


def nearest_stamps(
    sorted_stamps: np.typing.NDArray[np.float64], query: np.typing.NDArray[np.float64]
) -> tuple[np.typing.NDArray[np.int64], np.typing.NDArray[np.float64]]:
    """Index of the nearest of ``sorted_stamps`` for each query stamp, and the absolute gap."""
    right = np.clip(np.searchsorted(sorted_stamps, query), 0, len(sorted_stamps) - 1)
    left = np.maximum(right - 1, 0)
    use_left = np.abs(sorted_stamps[left] - query) <= np.abs(sorted_stamps[right] - query)
    index = np.where(use_left, left, right).astype(np.int64)
    return index, np.abs(sorted_stamps[index] - query)


def reference_poses(
    recording: RobotRecording, stamps: np.typing.NDArray[np.float64]
) -> tuple[np.typing.NDArray[np.float64], np.typing.NDArray[np.bool_]]:
    """Ground-truth pose of each stamp (nearest, within GROUND_TRUTH_MATCH_S) and which have one."""
    poses = np.full((len(stamps), 3), np.nan)
    if not recording.ground_truth or len(stamps) == 0:
        return poses, np.zeros(len(stamps), dtype=bool)
    gt_stamps = np.array([g.stamp for g in recording.ground_truth], dtype=np.float64)
    gt_poses = np.array([g.pose for g in recording.ground_truth], dtype=np.float64).reshape(-1, 3)
    order = np.argsort(gt_stamps, kind="stable")
    index, gap = nearest_stamps(gt_stamps[order], stamps)
    found = gap <= GROUND_TRUTH_MATCH_S
    poses[found] = gt_poses[order][index[found]]
    return poses, found
