"""rosbag2 recordings: exact round trips in mcap and sqlite3, and one clear error per bad file."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.io.bags import (
    BagCorruptError,
    BagError,
    BagNotFoundError,
    NoScanTopicsError,
    ReadReport,
    RobotRecording,
    TimedPose,
    TimedScan,
    UnknownMessageTypeError,
    read_recordings,
    robot_name,
    write_recordings,
)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
STORAGES = ("mcap", "sqlite3")
T0 = 1_700_000_000.0  # a realistic epoch stamp: nanoseconds must survive the float round trip


def make_scan(seed: int, beams: int = 37, intensities: bool = False) -> LaserScanData:
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(0.2, 25.0, beams)
    ranges[3] = np.nan  # dropout
    ranges[5] = np.inf  # no return (REP-117)
    ranges[7] = 0.123456789  # not representable in float32
    return LaserScanData(
        ranges=ranges,
        angle_min=-2.35619449,
        angle_max=2.35619449,
        angle_increment=2 * 2.35619449 / (beams - 1),
        range_min=0.1,
        range_max=30.0,
        intensities=rng.uniform(0, 1000, beams) if intensities else None,
    )


def recordings() -> dict[str, RobotRecording]:
    """Two robots; robot2 without ground truth, with intensities, scans given out of order."""
    robot1 = RobotRecording(
        name="robot1",
        scans=[TimedScan(T0 + 0.025 * i, "robot1/laser", make_scan(i)) for i in range(5)],
        ground_truth=[
            TimedPose(T0 + 0.025 * i, (1.5 + i, -2.25 * i, yaw), "world")
            for i, yaw in enumerate((0.0, 1.0, -3.1, 3.14159, -math.pi / 2))
        ],
    )
    robot2 = RobotRecording(
        name="robot2",
        scans=[
            TimedScan(
                T0 + 0.000000001 * i + 0.5 * (2 - i), "robot2/laser", make_scan(10 + i, 11, True)
            )
            for i in range(3)
        ],
        ground_truth=[],
    )
    return {"robot1": robot1, "robot2": robot2}


def f32(values: object) -> np.ndarray:
    """What a float32 message field holds, as float64."""
    return np.asarray(values, dtype=np.float32).astype(np.float64)


@pytest.fixture(params=STORAGES)
def written(request: pytest.FixtureRequest, tmp_path: Path) -> Path:
    return write_recordings(tmp_path / f"bag_{request.param}", recordings(), request.param)


def assert_same(back: dict[str, RobotRecording], original: dict[str, RobotRecording]) -> None:
    assert list(back) == list(original)
    for name, rec in original.items():
        got = back[name]
        assert got.name == name
        expected_scans = sorted(rec.scans, key=lambda s: s.stamp)
        assert [s.stamp for s in got.scans] == pytest.approx(
            [s.stamp for s in expected_scans], abs=1e-9, rel=0
        )
        for a, b in zip(got.scans, expected_scans, strict=True):
            assert a.frame_id == b.frame_id
            np.testing.assert_array_equal(a.scan.ranges, f32(b.scan.ranges))  # NaN == NaN here
            assert a.scan.angle_min == f32(b.scan.angle_min)
            assert a.scan.angle_max == f32(b.scan.angle_max)
            assert a.scan.angle_increment == f32(b.scan.angle_increment)
            assert a.scan.range_min == f32(b.scan.range_min)
            assert a.scan.range_max == f32(b.scan.range_max)
            if b.scan.intensities is None:
                assert a.scan.intensities is None
            else:
                np.testing.assert_array_equal(a.scan.intensities, f32(b.scan.intensities))
        assert len(got.ground_truth) == len(rec.ground_truth)
        for a, b in zip(got.ground_truth, rec.ground_truth, strict=True):
            assert a.stamp == pytest.approx(b.stamp, abs=1e-9, rel=0)
            assert a.frame_id == "world"
            assert a.pose[:2] == b.pose[:2]  # float64 fields: exact
            wrapped = math.remainder(a.pose[2] - b.pose[2], 2 * math.pi)
            assert abs(wrapped) < 1e-12


def test_round_trip_keeps_ranges_stamps_frames_and_poses(written: Path) -> None:
    assert_same(read_recordings(written), recordings())


def test_round_trip_of_the_bare_mcap_file(tmp_path: Path) -> None:
    bag = write_recordings(tmp_path / "bag", recordings(), "mcap")
    (mcap,) = bag.glob("*.mcap")
    assert_same(read_recordings(mcap), recordings())


def test_scans_come_back_sorted_by_stamp(written: Path) -> None:
    stamps = [s.stamp for s in read_recordings(written)["robot2"].scans]
    assert stamps == sorted(stamps)
    assert stamps[0] == pytest.approx(T0 + 0.000000002, abs=1e-9, rel=0)


def test_a_plain_rosbags_anyreader_reads_the_bag(written: Path) -> None:
    """The bag is a standard rosbag2: another reader sees the topics, types and messages."""
    with AnyReader([written], default_typestore=TYPESTORE) as reader:
        topics = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        assert topics == {
            "/robot1/scan": ("sensor_msgs/msg/LaserScan", 5),
            "/robot1/ground_truth": ("geometry_msgs/msg/PoseStamped", 5),
            "/robot2/scan": ("sensor_msgs/msg/LaserScan", 3),
        }
        scans = [c for c in reader.connections if c.topic == "/robot1/scan"]
        received = []
        for connection, timestamp, raw in reader.messages(connections=scans):
            msg = reader.deserialize(raw, connection.msgtype)
            received.append((timestamp, msg))
    expected = recordings()["robot1"].scans
    assert len(received) == 5
    for (timestamp, msg), item in zip(received, expected, strict=True):
        # Receive time is the header stamp, in nanoseconds.
        assert timestamp == msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        assert timestamp == pytest.approx(item.stamp * 1e9, abs=1.0, rel=0)
        assert msg.header.frame_id == "robot1/laser"
        np.testing.assert_array_equal(msg.ranges, np.float32(item.scan.ranges))


def test_scan_pattern_selects_topics(written: Path) -> None:
    assert list(read_recordings(written, scan_pattern="/robot2/*")) == ["robot2"]
    assert list(read_recordings(written, scan_pattern="/robot?/scan")) == ["robot1", "robot2"]


def test_robot_name_is_the_topic_namespace() -> None:
    assert robot_name("/robot1/scan") == "robot1"
    assert robot_name("/scan") == "robot"
    assert robot_name("/team/robot7/scan") == "team/robot7"


def test_robots_sort_naturally(tmp_path: Path) -> None:
    scan = make_scan(0)
    recs = {
        f"robot{k}": RobotRecording(f"robot{k}", [TimedScan(T0, f"robot{k}/laser", scan)], [])
        for k in (10, 2, 1)
    }
    bag = write_recordings(tmp_path / "bag", recs)
    assert list(read_recordings(bag)) == ["robot1", "robot2", "robot10"]


# --- bad files ------------------------------------------------------------------------------


def raw_bag(path: Path, topics: dict[str, str], storage: str = "mcap") -> Path:
    """A bag with one default message on each ``topic: type``, written with plain rosbags."""
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as bag:
        for i, (topic, msgtype) in enumerate(topics.items()):
            connection = bag.add_connection(topic, msgtype, typestore=TYPESTORE)
            if msgtype == "std_msgs/msg/String":
                msg = TYPESTORE.types[msgtype](data="hello")
            else:
                header = TYPESTORE.types["std_msgs/msg/Header"](
                    stamp=TYPESTORE.types["builtin_interfaces/msg/Time"](sec=1, nanosec=0),
                    frame_id="odom",
                )
                msg = TYPESTORE.types["nav_msgs/msg/Odometry"](
                    header=header,
                    child_frame_id="base",
                    pose=TYPESTORE.types["geometry_msgs/msg/PoseWithCovariance"](
                        pose=TYPESTORE.types["geometry_msgs/msg/Pose"](
                            position=TYPESTORE.types["geometry_msgs/msg/Point"](x=0, y=0, z=0),
                            orientation=TYPESTORE.types["geometry_msgs/msg/Quaternion"](
                                x=0, y=0, z=0, w=1
                            ),
                        ),
                        covariance=np.zeros(36),
                    ),
                    twist=TYPESTORE.types["geometry_msgs/msg/TwistWithCovariance"](
                        twist=TYPESTORE.types["geometry_msgs/msg/Twist"](
                            linear=TYPESTORE.types["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                            angular=TYPESTORE.types["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                        ),
                        covariance=np.zeros(36),
                    ),
                )
            bag.write(connection, 1_000_000_000 + i, TYPESTORE.serialize_cdr(msg, msgtype))
    return path


def expect(error: type[BagError], path: Path, *words: str) -> str:
    with pytest.raises(error) as info:
        read_recordings(path)
    message = str(info.value)
    assert str(path) in message
    assert "\n" not in message
    for word in words:
        assert word in message
    return message


def test_missing_path(tmp_path: Path) -> None:
    expect(BagNotFoundError, tmp_path / "nothing_here", "no such")


@pytest.mark.parametrize("name", ["empty.mcap", "empty.db3"])
def test_empty_file(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.touch()
    expect(BagCorruptError, path, "empty")


@pytest.mark.parametrize("name", ["garbage.mcap", "garbage.db3", "garbage.bin"])
def test_garbage_file(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.write_bytes(bytes(range(256)) * 40)
    expect(BagCorruptError, path)


def test_truncated_mcap_file_and_bag(tmp_path: Path) -> None:
    bag = write_recordings(tmp_path / "bag", recordings(), "mcap")
    (mcap,) = bag.glob("*.mcap")
    data = mcap.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    expect(BagCorruptError, cut)
    mcap.write_bytes(data[: len(data) // 2])  # the same damage inside the bag directory
    expect(BagCorruptError, bag)


def test_bag_directory_without_metadata(tmp_path: Path) -> None:
    bag = write_recordings(tmp_path / "bag", recordings(), "sqlite3")
    (bag / "metadata.yaml").unlink()
    expect(BagCorruptError, bag, "metadata.yaml")


def test_damaged_metadata(tmp_path: Path) -> None:
    bag = write_recordings(tmp_path / "bag", recordings(), "mcap")
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: [")
    expect(BagCorruptError, bag)


@pytest.mark.parametrize("storage", STORAGES)
def test_scan_topic_of_another_type(tmp_path: Path, storage: str) -> None:
    bag = raw_bag(tmp_path / "bag", {"/robot1/scan": "std_msgs/msg/String"}, storage)
    expect(UnknownMessageTypeError, bag, "/robot1/scan", "std_msgs/msg/String")


def test_ground_truth_of_another_type_is_left_out_with_a_note(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.add_connection("/robot1/scan", "sensor_msgs/msg/LaserScan", typestore=TYPESTORE)
        writer.add_connection("/robot1/ground_truth", "nav_msgs/msg/Odometry", typestore=TYPESTORE)
    report = ReadReport()
    recordings = read_recordings(bag, report=report)
    assert list(recordings) == ["robot1"] and recordings["robot1"].ground_truth == []
    (note,) = report.notes
    assert "/robot1/ground_truth" in note and "nav_msgs/msg/Odometry" in note


@pytest.mark.parametrize("storage", STORAGES)
def test_bag_without_scan_topics(tmp_path: Path, storage: str) -> None:
    topics = {"/chatter": "std_msgs/msg/String", "/odom": "nav_msgs/msg/Odometry"}
    bag = raw_bag(tmp_path / "bag", topics, storage)
    message = expect(NoScanTopicsError, bag, "/*/scan")
    assert "/chatter" in message  # says what the bag does hold


def test_fuzzed_files_give_only_bag_errors(tmp_path: Path) -> None:
    """Damage anywhere (cuts, flipped bytes) is reported as a BagError, never another error."""
    bag = write_recordings(tmp_path / "bag", recordings(), "mcap")
    (mcap,) = bag.glob("*.mcap")
    data = np.frombuffer(mcap.read_bytes(), dtype=np.uint8)
    rng = np.random.default_rng(7)
    outcomes = set()
    for trial in range(120):
        damaged = data.copy()
        if trial % 2:
            damaged = damaged[: int(rng.integers(0, len(data)))]
        else:
            at = rng.integers(0, len(data), size=int(rng.integers(1, 30)))
            damaged[at] = rng.integers(0, 256, size=len(at), dtype=np.uint8)
        path = tmp_path / f"fuzz{trial}.mcap"
        path.write_bytes(damaged.tobytes())
        try:
            read_recordings(path)
            outcomes.add("read")
        except BagError as exc:
            assert str(path) in str(exc)
            outcomes.add("error")
    assert "error" in outcomes


# --- writing --------------------------------------------------------------------------------


def test_write_refuses_an_existing_path(tmp_path: Path) -> None:
    (tmp_path / "bag").mkdir()
    with pytest.raises(BagError, match="already exists"):
        write_recordings(tmp_path / "bag", recordings())


def test_write_into_a_file_fails_cleanly(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(BagError, match="cannot create") as info:
        write_recordings(blocker / "bag", recordings())
    assert str(blocker / "bag") in str(info.value)


@pytest.mark.parametrize("stamp", [-1.0, float("nan"), 2.0**32])
def test_write_refuses_stamps_a_bag_cannot_hold(tmp_path: Path, stamp: float) -> None:
    recs = {"robot1": RobotRecording("robot1", [TimedScan(stamp, "l", make_scan(0))], [])}
    with pytest.raises(BagError, match="outside what a bag stores"):
        write_recordings(tmp_path / "bag", recs)
    assert not (tmp_path / "bag").exists()


def test_write_refuses_names_that_are_not_namespaces(tmp_path: Path) -> None:
    recs = {"robot 1": RobotRecording("robot 1", [TimedScan(T0, "l", make_scan(0))], [])}
    with pytest.raises(BagError, match="robot name"):
        write_recordings(tmp_path / "bag", recs)
