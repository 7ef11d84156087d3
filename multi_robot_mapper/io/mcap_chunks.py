"""MCAP files chunk by chunk: checksums written, and what is intact of a damaged file read.

``rosbags`` writes MCAP chunks without a checksum, so a flipped bit in a chunk would be decoded
as if nothing had happened. :func:`add_chunk_checksums` rewrites a file through the ``mcap``
library with a CRC-32 per chunk (chunks of 256 KiB, so damage costs little), which every
reader (``rosbags``, ``ros2 bag``, Foxglove) checks. :func:`salvage` reads a damaged or cut
file record by record: every chunk whose checksum holds is kept, the others are skipped and
counted, and reading stops cleanly where a cut file ends.
"""

from __future__ import annotations

import dataclasses
import os
import struct
from collections.abc import Iterator
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Footer, Message, Schema, Statistics
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

CHUNK_BYTES = 256 * 1024
# What a damaged record can raise while being parsed (lengths, compression, text).
_DAMAGE = (McapError, CRCValidationError, struct.error, ValueError, EOFError, UnicodeError)


def add_chunk_checksums(path: Path, compression: CompressionType = CompressionType.NONE) -> None:
    """Rewrite the MCAP file ``path`` with a CRC-32 on every chunk (same messages, order,
    profile, schemas and channels; written under a temporary name, then renamed), its chunks
    compressed by ``compression`` (default none: what the bags this project writes use)."""
    temporary = path.with_name(f".{path.name}.crc")
    with path.open("rb") as source, temporary.open("wb") as target:
        reader = make_reader(source)
        header = reader.get_header()
        writer = Writer(target, chunk_size=CHUNK_BYTES, compression=compression, enable_crcs=True)
        writer.start(profile=header.profile, library=header.library)
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schema_ids:
                schema_ids[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channel_ids:
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic,
                    channel.message_encoding,
                    schema_ids.get(channel.schema_id, 0),
                    dict(channel.metadata),
                )
            writer.add_message(
                channel_ids[channel.id],
                message.log_time,
                message.data,
                message.publish_time,
                message.sequence,
            )
        writer.finish()
    os.replace(temporary, path)


@dataclasses.dataclass
class Salvage:
    """What :func:`salvage` read of a file."""

    chunks_read: int = 0
    chunks_damaged: int = 0  # skipped: checksum or layout wrong
    chunks_total: int | None = None  # from the file's statistics, when its end was reached
    stopped: bool = False  # reading stopped at a record it could not frame (a cut file)
    messages: int = 0

    def describe(self) -> str:
        total = f" of {self.chunks_total}" if self.chunks_total is not None else ""
        parts = [f"read {self.chunks_read}{total} chunks ({self.messages} messages)"]
        if self.chunks_damaged:
            parts.append(f"{self.chunks_damaged} damaged chunks skipped (checksum or layout)")
        if self.stopped:
            parts.append("reading stopped where the file is cut (or its framing damaged)")
        return "; ".join(parts)


def salvage(path: Path, report: Salvage) -> Iterator[tuple[str, str, int, bytes]]:
    """``(topic, message type, log time ns, CDR bytes)`` of every message in an intact chunk
    of the MCAP file ``path``, in file order; ``report`` is filled in as reading goes."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    with path.open("rb") as stream:
        records = StreamReader(stream, emit_chunks=True, record_size_limit=1 << 30).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except _DAMAGE:  # the end of a cut file, or a record too damaged to frame
                report.stopped = True
                return
            if isinstance(record, Chunk):
                try:  # a chunk without a checksum (older writers) is read as it is
                    inside = breakup_chunk(record, validate_crc=True)
                except _DAMAGE:
                    report.chunks_damaged += 1
                    continue
                report.chunks_read += 1
                yield from _messages(inside, schemas, channels, report)
            elif isinstance(record, Statistics):
                report.chunks_total = record.chunk_count
            elif isinstance(record, Footer):
                return
            else:
                yield from _messages([record], schemas, channels, report)


def _messages(
    records: list[object],
    schemas: dict[int, Schema],
    channels: dict[int, Channel],
    report: Salvage,
) -> Iterator[tuple[str, str, int, bytes]]:
    for record in records:
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Message):
            channel = channels.get(record.channel_id)
            schema = schemas.get(channel.schema_id) if channel is not None else None
            if channel is None or schema is None:
                continue  # its channel was in a damaged chunk: nothing to decode it with
            report.messages += 1
            yield channel.topic, schema.name, record.log_time, record.data
