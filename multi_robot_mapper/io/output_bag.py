"""Outputs recorded as an MCAP file that Foxglove opens and ``ros2 bag play`` replays.

The file is rosbag2's ``mcap`` storage written by ``rosbags`` (profile ``ros2``, ROS 2 Jazzy
message definitions as ``ros2msg`` schemas, CDR messages, each topic's offered QoS), then
rewritten chunk by chunk with a CRC-32 and zstd compression
(:func:`~multi_robot_mapper.io.mcap_chunks.add_chunk_checksums`). Messages arrive already
serialised (``rclpy.serialization`` in the ROS layer), except ``tf2_msgs/TFMessage``, which no
PyPI package provides as a Python class: :func:`tf_message` serialises it with ``rosbags``'
own definition. Written in a temporary folder beside the target and moved there when complete:
an interrupted run leaves no half file.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shutil
import sqlite3
import struct
import tempfile
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path
from types import TracebackType

import numpy as np
from mcap.exceptions import McapError
from mcap.writer import CompressionType
from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from multi_robot_mapper.core.geometry import quaternion_from_yaw, split_stamp
from multi_robot_mapper.io.mcap_chunks import add_chunk_checksums
from multi_robot_mapper.io.outputs import OutputError

TF_TYPE = "tf2_msgs/msg/TFMessage"
_NEVER = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)  # rosbag2's "infinite" durations
_ERRORS = (WriterError, OSError, sqlite3.Error, ValueError, OverflowError, struct.error, McapError)


@lru_cache(maxsize=1)
def _typestore() -> Typestore:
    return get_typestore(Stores.ROS2_JAZZY)


def offered_qos(latched: bool, depth: int = 10) -> Qos:
    """The QoS a topic is offered with: reliable; ``latched``: transient local, depth 1 (what
    the merger's map topics offer, and what ``ros2 bag play`` gives a late subscriber)."""
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1 if latched else depth,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
        deadline=_NEVER,
        lifespan=_NEVER,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=_NEVER,
        avoid_ros_namespace_conventions=False,
    )


@dataclasses.dataclass(frozen=True)
class FrameTransform:
    """One transform of a TF tree: ``child`` in ``parent`` at (x, y, theta), stamped."""

    parent: str
    child: str
    pose: tuple[float, float, float]
    stamp: float  # s


def tf_message(transforms: Sequence[FrameTransform]) -> bytes:
    """``tf2_msgs/msg/TFMessage`` of ``transforms``, serialised (CDR)."""
    store = _typestore()
    types = store.types
    messages = []
    for item in transforms:
        sec, nanosec = split_stamp(item.stamp)
        qx, qy, qz, qw = (float(v) for v in quaternion_from_yaw(item.pose[2]))
        messages.append(
            types["geometry_msgs/msg/TransformStamped"](
                header=types["std_msgs/msg/Header"](
                    stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                    frame_id=item.parent,
                ),
                child_frame_id=item.child,
                transform=types["geometry_msgs/msg/Transform"](
                    translation=types["geometry_msgs/msg/Vector3"](
                        x=float(item.pose[0]), y=float(item.pose[1]), z=0.0
                    ),
                    rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
                ),
            )
        )
    return bytes(store.serialize_cdr(types[TF_TYPE](transforms=messages), TF_TYPE))


class OutputBag:
    """An MCAP file at ``path`` written message by message (module doc); use as a context
    manager: the file appears at ``path`` when the block ends without an error."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.counts: dict[str, int] = {}
        self._connections: dict[str, Connection] = {}
        self._folder: Path | None = None
        self._writer: Writer | None = None

    def __enter__(self) -> OutputBag:
        try:
            self._folder = Path(
                tempfile.mkdtemp(prefix=f".{self.path.name}.", dir=self.path.parent)
            )
            self._writer = Writer(
                self._folder / "bag",
                version=Writer.VERSION_LATEST,
                storage_plugin=StoragePlugin.MCAP,
            )
            self._writer.open()
        except _ERRORS as exc:
            self._discard()
            raise OutputError(f"cannot create {self.path}: {exc}") from None
        return self

    def write(self, topic: str, msgtype: str, stamp: float, data: bytes, latched: bool) -> None:
        """One serialised message of ``msgtype`` on ``topic``, logged at ``stamp`` (s)."""
        assert self._writer is not None, "OutputBag is used as a context manager"
        connection = self._connections.get(topic)
        if connection is None:
            connection = self._writer.add_connection(
                topic,
                msgtype,
                typestore=_typestore(),
                offered_qos_profiles=[offered_qos(latched)],
            )
            self._connections[topic] = connection
        sec, nanosec = split_stamp(stamp)
        self._writer.write(connection, sec * 1_000_000_000 + nanosec, data)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        try:
            if kind is not None:
                if self._writer is not None:
                    with contextlib.suppress(*_ERRORS):
                        self._writer.close()
                return
            assert self._writer is not None and self._folder is not None
            try:
                self._writer.close()
                written = next((self._folder / "bag").glob("*.mcap"))
                add_chunk_checksums(written, CompressionType.ZSTD)
                os.replace(written, self.path)
            except (*_ERRORS, StopIteration) as exc:
                raise OutputError(f"cannot write {self.path}: {exc}") from None
        finally:
            self._discard()

    def _discard(self) -> None:
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)
            self._folder = None


def thinned(count: int, most: int) -> np.typing.NDArray[np.int64]:
    """Indices of at most ``most`` of ``count`` items, evenly spread, the last always kept."""
    if count <= most:
        return np.arange(count, dtype=np.int64)
    return np.unique(np.linspace(0, count - 1, most).round().astype(np.int64))
