"""MCAP files chunk by chunk (io/mcap_chunks.py), on a file written here: checksums added with
the messages unchanged; a flipped byte costs its chunk alone, counted; a cut file is read up to
the cut."""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

from multi_robot_mapper.io.mcap_chunks import CHUNK_BYTES, Salvage, add_chunk_checksums, salvage

# Five messages of 100 KiB, each its own byte: the first three fill a chunk, the last two the
# next.
PAYLOADS = [bytes([65 + k]) * (100 * 1024) for k in range(5)]


def written(path: Path) -> Path:
    """The file as rosbags writes one: chunks without a checksum."""
    with path.open("wb") as stream:
        writer = Writer(stream, chunk_size=CHUNK_BYTES, enable_crcs=False)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        channel = writer.register_channel("/robot1/note", "cdr", schema)
        for k, payload in enumerate(PAYLOADS):
            writer.add_message(channel, 1_000 + k, payload, 1_000 + k, k)
        writer.finish()
    return path


def chunk_crcs(path: Path) -> list[int]:
    with path.open("rb") as stream:
        records = StreamReader(stream, emit_chunks=True).records
        return [r.uncompressed_crc for r in records if isinstance(r, Chunk)]


def test_checksums_are_added_and_the_messages_kept(tmp_path: Path) -> None:
    path = written(tmp_path / "bag.mcap")
    assert set(chunk_crcs(path)) == {0}
    add_chunk_checksums(path)
    crcs = chunk_crcs(path)
    assert len(crcs) == 2 and 0 not in crcs
    with path.open("rb") as stream:
        messages = [
            (c.topic, m.log_time, m.data) for _, c, m in make_reader(stream).iter_messages()
        ]
    assert messages == [("/robot1/note", 1_000 + k, p) for k, p in enumerate(PAYLOADS)]
    assert [p.name for p in tmp_path.iterdir()] == ["bag.mcap"]  # no temporary left


def test_a_flipped_byte_costs_its_chunk_and_a_cut_file_is_read_to_the_cut(tmp_path: Path) -> None:
    path = written(tmp_path / "bag.mcap")
    add_chunk_checksums(path)
    data = bytearray(path.read_bytes())
    report = Salvage()
    intact = list(salvage(path, report))
    assert [m[3] for m in intact] == PAYLOADS and intact[0][:3] == (
        "/robot1/note",
        "std_msgs/msg/String",
        1_000,
    )
    assert report.chunks_damaged == 0 and report.chunks_read == report.chunks_total
    # One byte of the last message flipped: its chunk (the last two messages) is skipped, the
    # first chunk read.
    data[data.rindex(PAYLOADS[4][:16]) + 10] ^= 0x01
    path.write_bytes(data)
    report = Salvage()
    kept = [m[3] for m in salvage(path, report)]
    assert report.chunks_damaged == 1 and kept == PAYLOADS[:3]
    assert "1 damaged chunks skipped" in report.describe()
    # Cut in the middle of the last message (the second chunk): the first chunk is read whole,
    # then reading stops.
    path.write_bytes(data[: data.index(PAYLOADS[4][:16]) + 50_000])
    report = Salvage()
    assert [m[3] for m in salvage(path, report)] == PAYLOADS[:3]
    assert report.chunks_read == 1 and report.stopped and report.chunks_total is None
    assert report.describe() == (
        "read 1 chunks (3 messages); reading stopped where the file is cut (or its framing damaged)"
    )
