"""Bags as users record them: ROS 1 bags, one bag per robot, a plain ``/scan``, truth files,
a bag cut into K robots (the cut ``import-carmen`` makes; ``mrm import-bag``'s own tests are
test/cli/test_import_bag.py), and the beams' geometry.

Every bag here is written by the test (ROS 1 with rosbags' own rosbag1 writer), tiny, with
known contents; the shared bags are read only by the real-data test at the end (skipped when
../shared/data/bags is absent).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.typesys import Stores, get_typestore

from multi_robot_mapper.cli.main import main
from multi_robot_mapper.core.geometry import quaternion_from_yaw, split_stamp
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.core.worlds import polygon
from multi_robot_mapper.evaluation.metrics import point_segment_distances
from multi_robot_mapper.io.bags import (
    BagError,
    RobotRecording,
    TimedPose,
    TimedScan,
    read_recordings,
    write_recordings,
)
from multi_robot_mapper.io.recordings import (
    BeamGeometry,
    TruthFileError,
    attach_truth,
    cut_recording,
    name_from_file,
    read_bags,
    read_truth_csv,
)
from multi_robot_mapper.io.results import read_results

ROS1 = get_typestore(Stores.ROS1_NOETIC)
T0 = 1_000_000_000.0  # the shared bags' first stamp
ROOM = polygon([(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0)])
ONE_DEGREE = math.radians(1.0)


def mrm(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


# --- writing ROS 1 bags -----------------------------------------------------------------------


def _header(stamp: float, frame: str, seq: int) -> Any:
    types = ROS1.types
    sec, nanosec = split_stamp(stamp)
    time = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
    return types["std_msgs/msg/Header"](seq=seq, stamp=time, frame_id=frame)


def ros1_scan(stamp: float, scan: LaserScanData, seq: int = 0, frame: str = "laser") -> Any:
    return ROS1.types["sensor_msgs/msg/LaserScan"](
        header=_header(stamp, frame, seq),
        angle_min=scan.angle_min,
        angle_max=scan.angle_max,
        angle_increment=scan.angle_increment,
        time_increment=0.0,
        scan_time=0.1,
        range_min=scan.range_min,
        range_max=scan.range_max,
        ranges=np.asarray(scan.ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )


def ros1_pose(stamp: float, pose: Sequence[float], seq: int = 0) -> Any:
    types = ROS1.types
    qx, qy, qz, qw = (float(v) for v in quaternion_from_yaw(pose[2]))
    return types["geometry_msgs/msg/PoseStamped"](
        header=_header(stamp, "world", seq),
        pose=types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=pose[0], y=pose[1], z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
        ),
    )


def ros1_odometry(stamp: float) -> Any:
    """An odometry message, as the shared bags hold: never to be read."""
    types = ROS1.types
    pose = ros1_pose(stamp, (9.0, 9.0, 1.0)).pose
    twist = types["geometry_msgs/msg/Twist"](
        linear=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        angular=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
    )
    return types["nav_msgs/msg/Odometry"](
        header=_header(stamp, "odom", 0),
        child_frame_id="base_link",
        pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=types["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def write_ros1_bag(path: Path, topics: dict[str, list[tuple[float, Any]]]) -> Path:
    """A ROS 1 bag of ``topic -> [(stamp, message)]``, written in stamp order."""
    with Ros1Writer(path) as writer:
        connections = {
            topic: writer.add_connection(topic, items[0][1].__msgtype__, typestore=ROS1)
            for topic, items in topics.items()
        }
        order = sorted((t, topic, m) for topic, items in topics.items() for t, m in items)
        for stamp, topic, message in order:
            data = ROS1.serialize_ros1(message, message.__msgtype__)
            writer.write(connections[topic], round(stamp * 1e9), data)
    return path


def scan_reading(value: float, beams: int = 180) -> LaserScanData:
    """A scan reading ``value`` m on every beam, stated in CARMEN's geometry."""
    return LaserScanData(
        ranges=np.full(beams, value),
        angle_min=-math.pi / 2,
        angle_max=-math.pi / 2 + ONE_DEGREE * (beams - 1),
        angle_increment=ONE_DEGREE,
        range_min=0.0,
        range_max=80.0,
    )


def room_drive(
    count: int, stamp0: float = T0
) -> tuple[np.ndarray, np.ndarray, list[LaserScanData]]:
    """A laser sweeping the room (noise-free scans, 180 beams one degree apart from -90 deg, as
    CARMEN logs them): stamps at 10 Hz, laser poses, scans stated in CARMEN's geometry."""
    laser = LaserModel(
        beams=180, field_of_view=179 * ONE_DEGREE, range_max=80.0, range_noise=0.0, dropout=0.0
    )
    stamps = stamp0 + 0.1 * np.arange(count)
    a = np.linspace(0.0, 1.5 * np.pi, count)
    poses = np.column_stack((3.0 + 1.2 * np.cos(a), 2.0 + 0.8 * np.sin(a), a + np.pi / 2))
    scans = []
    for pose in poses:
        # The simulator's beams are symmetric (-89.5 .. +89.5 deg): a laser turned half a degree
        # clockwise sees them at -90 .. +89 deg of the true pose, CARMEN's layout.
        turned = (pose[0], pose[1], pose[2] - ONE_DEGREE / 2)
        scan = simulate_scan(ROOM, turned, laser, np.random.default_rng(0))
        scans.append(BeamGeometry("carmen").apply(scan))
    return stamps, poses, scans


def as_converter_states(scan: LaserScanData) -> LaserScanData:
    """The scan as the shared bags' converter states it: beams spread over pi."""
    n = scan.ranges.size
    return BeamGeometry("fixed", -math.pi / 2, math.pi / (n - 1)).apply(scan)


def write_truth(path: Path, indices: Sequence[int], stamps: np.ndarray, poses: np.ndarray) -> Path:
    lines = ["index,stamp,x,y,theta"]
    lines += [f"{i},{stamps[i]:.6f}," + ",".join(repr(float(v)) for v in poses[i]) for i in indices]
    path.write_text("\n".join(lines) + "\n")
    return path


# --- ROS 1 bags -------------------------------------------------------------------------------


def test_a_ros1_bag_reads_like_a_rosbag2_bag(tmp_path: Path) -> None:
    scans = [
        (T0 + 0.1 * i, ros1_scan(T0 + 0.1 * i, scan_reading(1.0 + i), seq=i)) for i in range(4)
    ]
    truth = [(T0 + 0.1 * i, ros1_pose(T0 + 0.1 * i, (i, -2.0 * i, 0.1 * i))) for i in range(4)]
    odom = [(T0 + 0.1 * i, ros1_odometry(T0 + 0.1 * i)) for i in range(4)]
    bag = write_ros1_bag(
        tmp_path / "run.bag",
        {"/robot7/scan": scans, "/robot7/ground_truth": truth, "/robot7/odom": odom},
    )
    (robot,) = read_recordings(bag).values()
    assert robot.name == "robot7"
    assert [s.stamp for s in robot.scans] == pytest.approx(T0 + 0.1 * np.arange(4), abs=1e-9)
    assert [s.scan.ranges[0] for s in robot.scans] == [1.0, 2.0, 3.0, 4.0]
    first = robot.scans[0]
    assert first.frame_id == "laser" and first.scan.ranges.size == 180
    assert first.scan.angle_increment == pytest.approx(np.float32(ONE_DEGREE))
    assert first.scan.range_max == 80.0
    assert robot.ground_truth[3].pose == pytest.approx((3.0, -6.0, 0.3))
    assert {g.frame_id for g in robot.ground_truth} == {"world"}


def test_a_single_scan_bag_just_works(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A ROS 1 bag of one robot's plain /scan (and odometry, unread): replayed with no option,
    scored with its truth file."""
    stamps, poses, scans = room_drive(60)
    bag = write_ros1_bag(
        tmp_path / "mine.bag",
        {
            "/scan": [
                (t, ros1_scan(t, s, i)) for i, (t, s) in enumerate(zip(stamps, scans, strict=True))
            ],
            "/odom": [(t, ros1_odometry(t)) for t in stamps],
        },
    )
    truth = write_truth(tmp_path / "mine.truth.csv", range(0, 60, 3), stamps, poses)
    out = tmp_path / "out"
    code, printed, err = mrm(capsys, "replay", bag, "--out", out)  # the local method
    assert code == 0, err
    assert "1 robots, 60 scans" in printed
    code, _, err = mrm(capsys, "evaluate", out, "--bag", bag, "--truth", truth, "--json")
    assert code == 0, err
    metrics = json.loads((out / "metrics.json").read_text())
    assert list(metrics["robots"]) == ["robot"]
    assert metrics["scans_total"] == 20  # the scans with a reference pose
    assert metrics["ate_all_rmse_m"] < 0.05


@pytest.mark.parametrize("damage", ["junk", "cut"])
def test_a_damaged_ros1_bag_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], damage: str
) -> None:
    scans = [(T0 + 0.1 * i, ros1_scan(T0 + 0.1 * i, scan_reading(1.0))) for i in range(20)]
    data = write_ros1_bag(tmp_path / "whole.bag", {"/scan": scans}).read_bytes()
    bag = tmp_path / "bad.bag"
    bag.write_bytes(b"not a bag at all" if damage == "junk" else data[: len(data) // 2])
    code, _, err = mrm(capsys, "replay", bag, "--out", tmp_path / "out")
    assert code == 2 and err.count("\n") == 1 and str(bag) in err, err
    if damage == "cut":
        assert "rosbag reindex" in err


# --- one bag per robot ------------------------------------------------------------------------


def two_robot_bags(tmp_path: Path) -> tuple[Path, Path]:
    """robot1.bag and robot2.bag, each one robot's plain /scan and /ground_truth, recorded on
    its own (different stamps, different stretches of the room)."""
    bags = []
    for k, (start, first) in enumerate(((T0, 0), (T0 + 0.05, 20))):
        stamps, poses, scans = room_drive(40, start)
        topics = {
            "/scan": [(stamps[i], ros1_scan(stamps[i], scans[i], i)) for i in range(first, 40)],
            "/ground_truth": [
                (stamps[i], ros1_pose(stamps[i], poses[i])) for i in range(first, 40)
            ],
        }
        bags.append(write_ros1_bag(tmp_path / f"robot{k + 1}.bag", topics))
    return bags[0], bags[1]


def test_two_bags_for_two_robots(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag1, bag2 = two_robot_bags(tmp_path)
    recordings = read_bags([bag1, bag2])
    assert {n: len(r.scans) for n, r in recordings.items()} == {"robot1": 40, "robot2": 20}
    named = read_bags([bag1, bag2], names=["alpha", "team/beta"])
    assert list(named) == ["alpha", "team/beta"] and named["alpha"].name == "alpha"

    out = tmp_path / "out"
    code, _, err = mrm(capsys, "replay", bag1, bag2, "--out", out, "--method", "reference")
    assert code == 0, err
    assert read_results(out).robots == ["robot1", "robot2"]
    code, _, err = mrm(capsys, "evaluate", out, "--bag", bag1, "--bag", bag2, "--json")
    assert code == 0, err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["robots_merged"] == 2 and metrics["ate_rmse_m"] < 1e-4
    assert metrics["scans_total"] == 60

    # A ROS 1 bag and a rosbag2 bag of another robot, side by side.
    mcap = write_recordings(tmp_path / "other", {"robot3": recordings["robot2"]})
    both = read_bags([bag1, mcap])
    assert list(both) == ["robot1", "robot3"]


@pytest.mark.parametrize(
    ("names", "words"),
    [
        (None, "robot 'run' is in both"),  # two bags of a plain /scan, both files run.bag
        (["a"], "1 robot names for 2 bags"),
        (["a", "b c"], "cannot be a ROS namespace"),
        (["a", "a"], "robot 'a' is in both"),
    ],
)
def test_robot_names_that_cannot_be(tmp_path: Path, names: list[str] | None, words: str) -> None:
    bag1, _ = two_robot_bags(tmp_path)
    copies = []
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        copies.append(tmp_path / folder / "run.bag")
        copies[-1].write_bytes(bag1.read_bytes())
    with pytest.raises(BagError, match=words):
        read_bags(copies, names=names)


def test_names_from_files() -> None:
    assert name_from_file("/data/robot2.bag") == "robot2"
    assert name_from_file("mit-csail.bag") == "mit_csail"
    assert name_from_file("2024-run") == "_2024_run"


def test_a_bag_holding_two_robots_cannot_take_one_name(tmp_path: Path) -> None:
    scans = [(T0, ros1_scan(T0, scan_reading(1.0)))]
    bag = write_ros1_bag(tmp_path / "two.bag", {"/r1/scan": scans, "/r2/scan": scans})
    assert list(read_bags([bag])) == ["r1", "r2"]
    with pytest.raises(BagError, match="holds 2 robots"):
        read_bags([bag], names=["x"])
    assert list(read_bags([bag], names=["x"], scan_pattern="/r2/scan")) == ["x"]


# --- truth files ------------------------------------------------------------------------------


def test_truth_file_gives_the_scans_reference_poses(tmp_path: Path) -> None:
    stamps, poses, scans = room_drive(10)
    recording = RobotRecording(
        "robot", [TimedScan(t, "laser", s) for t, s in zip(stamps, scans, strict=True)]
    )
    table = read_truth_csv(write_truth(tmp_path / "t.csv", [1, 4, 9], stamps, poses))
    posed = attach_truth(recording, table)
    assert [g.stamp for g in posed.ground_truth] == [stamps[1], stamps[4], stamps[9]]
    assert posed.ground_truth[1].pose == pytest.approx(tuple(poses[4]), abs=1e-12)
    assert {g.frame_id for g in posed.ground_truth} == {"world"}


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("x,y\n", "first line must be index,stamp,x,y,theta"),
        ("index,stamp,x,y,theta\n1,2,3\n", "line 2: expected 5 numbers"),
        ("index,stamp,x,y,theta\n1.5,2,3,4,5\n", "line 2: not finite, or an index"),
        ("index,stamp,x,y,theta\n3,1000000000.3,0,0,nan\n", "line 2: not finite"),
        ("index,stamp,x,y,theta\n3,1000000000.3,0,0,0\n1,1000000000.1,0,0,0\n", "increasing"),
        ("index,stamp,x,y,theta\n12,1000000001.2,0,0,0\n", "beyond the 10 scans"),
        ("index,stamp,x,y,theta\n2,1000000000.5,0,0,0\n", "line 2: scan 2 is stamped"),
    ],
)
def test_truth_files_that_do_not_fit(tmp_path: Path, text: str, words: str) -> None:
    stamps, _, scans = room_drive(10)
    recording = RobotRecording(
        "robot", [TimedScan(t, "laser", s) for t, s in zip(stamps, scans, strict=True)]
    )
    path = tmp_path / "t.csv"
    path.write_text(text)
    with pytest.raises(TruthFileError, match=words) as info:
        attach_truth(recording, read_truth_csv(path))
    assert str(path) in str(info.value)


def test_cli_truth_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stamps, _, scans = room_drive(5)
    bag = write_ros1_bag(
        tmp_path / "b.bag",
        {"/scan": [(t, ros1_scan(t, s)) for t, s in zip(stamps, scans, strict=True)]},
    )
    bad = tmp_path / "bad.csv"
    bad.write_text("index,stamp,x,y,theta\n9,1,0,0,0\n")
    for args in (
        ("replay", bag, "--out", tmp_path / "o", "--method", "reference", "--truth", bad),
        ("import-bag", bag, "--robots", 2, "--out", tmp_path / "cut", "--truth", bad),
        ("replay", bag, "--out", tmp_path / "o", "--truth", bad, "--truth", bad),
        ("replay", bag, "--out", tmp_path / "o", "--beam-geometry", "sideways"),
    ):
        code, _, err = mrm(capsys, *args)
        assert code == 2 and err.count("\n") == 1, err
        assert not (tmp_path / "cut").exists()


# --- one bag cut into K robots ----------------------------------------------------------------


def test_cut_keeps_a_truth_topic_at_its_own_rate() -> None:
    """Ground truth at 4 Hz beside scans at 10 Hz: each run keeps the poses of its stretch,
    shifted as its scans are."""
    scans = [TimedScan(10.0 + 0.1 * i, "laser", scan_reading(1.0)) for i in range(20)]
    truth = [TimedPose(10.0 + 0.25 * k, (k, 0.0, 0.0), "map") for k in range(8)]
    runs = cut_recording(RobotRecording("r", scans, truth), 2)
    assert [g.pose[0] for g in runs["robot1"].ground_truth] == [0, 1, 2, 3]
    assert [g.pose[0] for g in runs["robot2"].ground_truth] == [4, 5, 6, 7]
    # robot2's run starts at scan 10 (11.0 s), moved to 10.0 s: pose 4 (11.0 s) at 10.0 s.
    assert runs["robot2"].ground_truth[0].stamp == pytest.approx(10.0)
    assert {g.frame_id for g in runs["robot2"].ground_truth} == {"map"}


# --- beam geometry ----------------------------------------------------------------------------


def test_beam_geometry_options() -> None:
    scan = as_converter_states(scan_reading(2.0))
    assert scan.angle_increment == pytest.approx(math.pi / 179)
    carmen = BeamGeometry.parse("carmen").apply(scan)
    assert (carmen.angle_min, carmen.angle_increment) == (-math.pi / 2, ONE_DEGREE)
    assert carmen.angle_max == pytest.approx(math.radians(89.0))
    fixed = BeamGeometry.parse("-135, 0.25").apply(scan)
    assert fixed.angle_min == pytest.approx(math.radians(-135.0))
    assert fixed.angle_max == pytest.approx(math.radians(-135.0 + 0.25 * 179))
    assert BeamGeometry.parse("bag").apply(scan) is scan
    for bad in ("sideways", "1,0", "1,2,3", "nan,1", "-90,inf"):
        with pytest.raises(ValueError, match=repr(bad)):
            BeamGeometry.parse(bad)


def test_a_wrong_beam_geometry_bends_the_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The room scanned in CARMEN's geometry, written as the shared bags' converter states it
    (180 beams over pi): placed at their true poses, the scans draw the room's walls only with
    --beam-geometry carmen; as stated, the walls the last beams see are drawn up to a degree
    turned (about 5 cm at the room's 3-4 m)."""
    stamps, poses, scans = room_drive(30)
    bag = write_ros1_bag(
        tmp_path / "converted.bag",
        {
            "/scan": [
                (t, ros1_scan(t, as_converter_states(s)))
                for t, s in zip(stamps, scans, strict=True)
            ],
            "/ground_truth": [(t, ros1_pose(t, p)) for t, p in zip(stamps, poses, strict=True)],
        },
    )
    offsets = {}
    for geometry in ("bag", "carmen"):
        out = tmp_path / geometry
        args = ("--out", out, "--method", "reference", "--beam-geometry", geometry)
        code, _, err = mrm(capsys, "replay", bag, *args)
        assert code == 0, err
        ends = read_results(out).map_segments.reshape(-1, 2)
        offsets[geometry] = point_segment_distances(ends, ROOM)
    assert np.percentile(offsets["carmen"], 99) < 0.005
    # A beam up to 1 deg off moves its point by at most range x 1 deg (the room's diagonal is
    # 7.2 m); half the segment ends lie more than a centimetre off the walls.
    assert np.median(offsets["bag"]) > 0.01
    assert offsets["bag"].max() < 7.3 * ONE_DEGREE


# --- the real bags (skipped without ../shared/data/bags) --------------------------------------


def shared_bags() -> Path:
    """../shared/data/bags beside this clone (or beside the folder of worktrees holding it)."""
    here = Path(__file__).resolve()
    for folder in here.parents[3:5]:
        if (folder / "shared" / "data" / "bags").is_dir():
            return folder / "shared" / "data" / "bags"
    pytest.skip("real-data bags not found (../shared/data/bags is not beside this clone)")


@pytest.mark.realdata
def test_the_mit_csail_bag_and_its_raw_log_line_up() -> None:
    """mit-csail.bag read as a ROS 1 bag: every scan, the converter's geometry, its truth file
    attached, and the raw log's k-th line is the bag's k-th scan (how its relations match)."""
    from multi_robot_mapper.evaluation.relations import UNPOSED, read_relations, relation_errors
    from multi_robot_mapper.io.carmen import read_carmen

    folder = shared_bags()
    (robot,) = read_recordings(folder / "mit-csail.bag").values()
    assert robot.name == "robot" and len(robot.scans) == 1988
    assert robot.scans[5].stamp == pytest.approx(T0 + 0.5)
    scan = robot.scans[0].scan
    assert scan.ranges.size == 361 and scan.angle_increment == pytest.approx(math.pi / 360)
    posed = attach_truth(robot, read_truth_csv(folder / "mit-csail.truth.csv"))
    assert len(posed.ground_truth) == 406
    log = read_carmen(folder / "mit-csail.clf.gz")
    assert len(log) == 1988
    for k in range(0, 300, 7):
        np.testing.assert_array_equal(
            np.float32(log[k].ranges), np.float32(robot.scans[k].scan.ranges)
        )
    relations = read_relations(folder / "mit-csail.relations")
    clock = np.array([s.timestamp for s in log])
    errors = relation_errors(relations, clock, np.full((1988, 3), np.nan))
    assert np.all(errors.status == UNPOSED)  # every stamp names a scan; none is posed here
