"""Damaged bags through ``mrm replay`` (issue 15, item 5): a cut MCAP file is refused with its
name and salvaged on request ("read k of n"), a flipped bit is caught by the chunk checksums
and never decoded, and a bag that is readable in part is replayed in part, said, exit code 1."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import StoragePlugin, Writer
from test_bags import TYPESTORE

from multi_robot_mapper.cli.main import main
from multi_robot_mapper.io.bags import ReadReport, read_recordings
from multi_robot_mapper.io.mcap_chunks import Salvage, salvage


def mrm(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two simulated robots, 3 s at 40 Hz: a bag of several 256 KiB chunks."""
    path = tmp_path_factory.mktemp("bags") / "sim"
    assert main(["simulate", "--robots", "2", "--out", str(path), "--duration", "3"]) == 0
    return path


def copy_of(bag: Path, tmp_path: Path) -> tuple[Path, Path]:
    target = tmp_path / "bag"
    shutil.copytree(bag, target)
    (mcap,) = target.glob("*.mcap")
    return target, mcap


def chunk_offsets(mcap: Path) -> list[tuple[int, int]]:
    """(start, length) of every chunk record's data in the file."""
    from mcap.reader import make_reader

    with mcap.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return [(c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes]


def test_our_bags_carry_a_checksum_on_every_chunk(bag: Path) -> None:
    (mcap,) = bag.glob("*.mcap")
    report = Salvage()
    messages = list(salvage(mcap, report))
    assert report.chunks_read == report.chunks_total >= 3 and report.chunks_damaged == 0
    from mcap.reader import make_reader

    with mcap.open("rb") as stream:
        for chunk in make_reader(stream).get_summary().chunk_indexes:
            assert chunk.chunk_length > 0
    assert len(messages) == sum(
        len(r.scans) + len(r.ground_truth) for r in read_recordings(bag).values()
    )


def test_a_cut_mcap_is_refused_by_name_and_salvaged_on_request(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, bag: Path
) -> None:
    damaged, mcap = copy_of(bag, tmp_path)
    data = mcap.read_bytes()
    start, length = chunk_offsets(mcap)[2]
    mcap.write_bytes(data[: start + length // 2])  # cut in the middle of the third chunk
    code, _, err = mrm(capsys, "replay", damaged, "--out", tmp_path / "a", "--method", "reference")
    assert code == 2 and err.count("\n") == 1 and str(damaged) in err and "--salvage" in err
    args = ("replay", damaged, "--out", tmp_path / "b", "--method", "reference", "--salvage")
    code, _, err = mrm(capsys, *args)
    assert code == 1, err  # replayed, but not all of it
    assert "read 2 chunks" in err and "cut" in err
    assert "metadata.yaml counts 120 messages on /robot1/scan, the bag holds" in err
    assert (tmp_path / "b" / "map.json").is_file()
    assert "Traceback" not in err


def test_a_flipped_bit_in_a_chunk_is_detected_skipped_and_never_decoded(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, bag: Path
) -> None:
    original = read_recordings(bag)
    damaged, mcap = copy_of(bag, tmp_path)
    data = bytearray(mcap.read_bytes())
    start, length = chunk_offsets(mcap)[1]
    data[start + length // 2] ^= 0x04  # one bit, inside the second chunk's messages
    mcap.write_bytes(bytes(data))
    code, _, err = mrm(capsys, "replay", damaged, "--out", tmp_path / "a", "--method", "reference")
    assert code == 2 and "checksum mismatch" in err and str(damaged) in err
    report = ReadReport()
    salvaged = read_recordings(damaged, salvage=True, report=report)
    assert report.salvage is not None and report.salvage.chunks_damaged == 1
    assert report.salvage.chunks_read == report.salvage.chunks_total - 1
    assert any("1 damaged chunks skipped" in note for note in report.notes)
    for name, recording in salvaged.items():  # every scan kept is exactly an original one
        good = {s.stamp: s for s in original[name].scans}
        assert 0 < len(recording.scans) < len(good)
        for scan in recording.scans:
            np.testing.assert_array_equal(scan.scan.ranges, good[scan.stamp].scan.ranges)


def test_metadata_counts_that_disagree_are_said_and_the_bag_replayed(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, bag: Path
) -> None:
    damaged, _ = copy_of(bag, tmp_path)
    meta_path = damaged / "metadata.yaml"
    meta = yaml.safe_load(meta_path.read_text())
    for topic in meta["rosbag2_bagfile_information"]["topics_with_message_count"]:
        if topic["topic_metadata"]["name"] == "/robot2/scan":
            topic["message_count"] += 7
    meta_path.write_text(yaml.safe_dump(meta))
    code, _, err = mrm(capsys, "replay", damaged, "--out", tmp_path / "o", "--method", "reference")
    assert code == 1
    assert "metadata.yaml counts 127 messages on /robot2/scan, the bag holds 120" in err


def test_a_robot_of_an_unknown_message_type_is_left_out_and_the_others_replayed(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, bag: Path
) -> None:
    one_robot = tmp_path / "one"
    from multi_robot_mapper.io.bags import write_recordings

    write_recordings(one_robot, {"robot1": read_recordings(bag)["robot1"]})
    combined = tmp_path / "combined"
    from rosbags.rosbag2 import Reader

    with (
        Reader(one_robot) as reader,
        Writer(combined, version=9, storage_plugin=StoragePlugin.MCAP) as writer,
    ):
        out = {
            c.id: writer.add_connection(c.topic, c.msgtype, typestore=TYPESTORE)
            for c in reader.connections
        }
        for c, t, raw in reader.messages():
            writer.write(out[c.id], t, raw)
        odd = writer.add_connection("/robot9/scan", "std_msgs/msg/String", typestore=TYPESTORE)
        text = TYPESTORE.types["std_msgs/msg/String"](data="not a scan")
        writer.write(odd, 1, TYPESTORE.serialize_cdr(text, "std_msgs/msg/String"))
    code, _, err = mrm(capsys, "replay", combined, "--out", tmp_path / "o", "--method", "reference")
    assert code == 1, err
    assert "/robot9/scan has type std_msgs/msg/String, expected sensor_msgs/msg/LaserScan" in err
    assert "left out" in err
    robots = yaml.safe_load((tmp_path / "o" / "robots.json").read_text())
    assert list(robots) == ["robot1"]


@pytest.mark.parametrize("case", ["empty", "not a bag", "truncated db3", "no metadata.yaml"])
def test_unreadable_bags_exit_2_with_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, case: str
) -> None:
    if case in ("truncated db3", "no metadata.yaml"):
        path = tmp_path / "db"
        assert (
            main(
                [
                    "simulate",
                    "--robots",
                    "1",
                    "--out",
                    str(path),
                    "--duration",
                    "1",
                    "--storage",
                    "sqlite3",
                ]
            )
            == 0
        )
        capsys.readouterr()
        (db3,) = path.glob("*.db3")
        if case == "truncated db3":
            db3.write_bytes(db3.read_bytes()[: db3.stat().st_size // 3])
        else:
            (path / "metadata.yaml").unlink()
    else:
        path = tmp_path / "file.mcap"
        path.write_bytes(b"" if case == "empty" else b"not a bag at all\n" * 50)
    code, out, err = mrm(capsys, "replay", path, "--out", tmp_path / "o", "--method", "reference")
    assert code == 2 and err.count("\n") == 1 and str(path) in err
    assert "Traceback" not in err + out
