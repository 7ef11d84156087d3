"""Property-based fuzzing (Hypothesis) of everything the pipeline reads from outside.

Random LaserScans and partial maps, inside and outside their contracts, are fed to a
robot_mapper and a map_merger spun in this process (through their subscriptions' own
callbacks, timers run by the executor; one test also over real DDS topics); the file readers
get random bytes, truncations and bit flips. Properties:

- no exception reaches a callback's guard or an internal-error branch: every bad input is a
  clean rejection with a reason;
- nothing published holds NaN or inf, and the occupancy grid holds only -1, 0..100 in
  width x height cells;
- memory stays bounded: refused inputs allocate almost nothing, and state never grows from them;
- one robot's garbage leaves a good robot's map (and its placement) unchanged;
- a file gives clean data (every number finite) or its reader's own error, never a traceback.

Each test's settings come from :func:`fuzz` below: ``make test`` runs its examples on a fixed
seed (the same examples every run, under a minute in all); ``make fuzz`` (``MRM_FUZZ=1``) runs
``MRM_FUZZ_SCALE`` (default 25) times as many, on a new random seed each run.
"""

from __future__ import annotations

import copy
import gzip
import math
import os
import tracemalloc
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import Point, PoseStamped
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from nav_msgs.msg import OccupancyGrid
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from test_bad_maps_node import NAMES, message
from test_link_graph import SIMULATED_WORLD_JOIN_PROBABILITY
from test_robot_mapper import room_scan
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.io.messages import scan_to_msg, stamp_from_seconds
from multi_robot_mapper.ros.map_merger import MapMerger
from multi_robot_mapper.ros.merger_config import MapMergerConfig
from multi_robot_mapper.ros.robot_mapper import RobotMapper
from multi_robot_mapper.ros.testing import isolated_context, spin_until

# ``make fuzz`` sets MRM_FUZZ=1: many times the examples, a new random seed each run.
FUZZ = os.environ.get("MRM_FUZZ") == "1"
FUZZ_SCALE = int(os.environ.get("MRM_FUZZ_SCALE", "25")) if FUZZ else 1


def fuzz(examples: int) -> settings:
    """Settings of one fuzz test: ``examples`` in ``make test`` (a fixed seed: the same
    examples every run), ``FUZZ_SCALE`` times more under ``make fuzz`` (random)."""
    return settings(
        max_examples=examples * FUZZ_SCALE,
        derandomize=not FUZZ,
        # The nodes keep state from one example to the next, so a failure is reported as it
        # was found: shrinking would replay it on a node in another state.
        phases=[Phase.explicit, Phase.reuse, Phase.generate],
        database=None,
        deadline=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


# --- strategies ------------------------------------------------------------------------------

F32 = st.floats(width=32)  # every float32, NaN and infinities included
WILD = st.one_of(
    F32,
    st.sampled_from([0.0, -0.0, 1e-30, 1e-8, 1e-4, 1e30, math.pi, -math.pi, 2 * math.pi]),
)


@st.composite
def laser_scans(draw: st.DrawFn) -> LaserScan:
    """A LaserScan in contract (a room seen by a plausible laser, with dropouts), slightly
    broken (one field spoiled) or anything at all."""
    mode = draw(st.sampled_from(["good", "spoiled", "wild"]))
    stamp = draw(st.floats(1.0, 2.0e9, allow_nan=False))
    if mode == "wild":
        msg = LaserScan()
        msg.header.stamp.sec = draw(st.integers(-(2**31), 2**31 - 1))
        msg.header.stamp.nanosec = draw(st.integers(0, 2**32 - 1))
        n = draw(st.integers(0, 3000))
        msg.ranges = draw(st.lists(WILD, min_size=n, max_size=n)) if n < 200 else [draw(WILD)] * n
        for name in ("angle_min", "angle_max", "angle_increment", "range_min", "range_max"):
            setattr(msg, name, draw(WILD))
        msg.intensities = [draw(F32)] * draw(st.integers(0, 50))
        return msg
    beams = draw(st.integers(2, 2000))
    msg = scan_to_msg(room_scan(beams), "robot1/laser", stamp_from_seconds(stamp))
    ranges = np.asarray(msg.ranges, dtype=np.float32)
    holes = draw(st.lists(st.integers(0, beams - 1), max_size=20))
    ranges[holes] = draw(st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1e9]))
    msg.ranges = ranges.tolist()
    if mode == "spoiled":
        field = draw(
            st.sampled_from(["angle_min", "angle_max", "angle_increment", "range_min", "range_max"])
        )
        setattr(msg, field, draw(WILD))
        if draw(st.booleans()):
            msg.intensities = [1.0] * draw(st.integers(0, 3 * beams))
    return msg


POINT = st.one_of(
    st.floats(-50.0, 50.0),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e300, -1e300, 1e-300, 0.0]),
)


@st.composite
def partial_maps(draw: st.DrawFn) -> MarkerArray:
    """A partial map in contract (charlie's, or random finite segments), spoiled, or wild."""
    mode = draw(st.sampled_from(["good", "random", "spoiled", "wild"]))
    if mode in ("good", "spoiled"):
        msg = copy.deepcopy(message("charlie"))
        if mode == "spoiled":
            marker = msg.markers[draw(st.integers(0, len(msg.markers) - 1))]
            target = draw(st.sampled_from(["point", "position", "orientation", "points", "id"]))
            if target == "point" and marker.points:
                point = marker.points[draw(st.integers(0, len(marker.points) - 1))]
                point.x, point.y = draw(POINT), draw(POINT)
            elif target == "position":
                marker.pose.position.x, marker.pose.position.y = draw(POINT), draw(POINT)
            elif target == "orientation":
                q = marker.pose.orientation
                q.x, q.y, q.z, q.w = (draw(POINT) for _ in range(4))
            elif target == "points":
                marker.points = marker.points[: draw(st.integers(0, len(marker.points)))]
            else:
                marker.id = draw(st.integers(-(2**31), 2**31 - 1))
        return msg
    msg = MarkerArray()
    for k in range(draw(st.integers(0, 6))):
        marker = Marker(ns="partial_map", id=k, type=Marker.LINE_LIST, action=Marker.ADD)
        if mode == "wild":
            marker.ns = draw(st.sampled_from(["partial_map", "other", ""]))
            marker.type = draw(st.sampled_from([Marker.LINE_LIST, Marker.ARROW, 99]))
            marker.action = draw(st.sampled_from([Marker.ADD, Marker.DELETEALL, 7]))
            coordinates = POINT
        else:  # finite and within the limits, but geometry no robot would map
            coordinates = st.floats(-30.0, 30.0)
        count = draw(st.integers(0, 40))
        values = draw(st.lists(coordinates, min_size=2 * count, max_size=2 * count))
        marker.points = [
            Point(x=x, y=y, z=0.0) for x, y in zip(values[::2], values[1::2], strict=True)
        ]
        marker.pose.position.x, marker.pose.position.y = draw(coordinates), draw(coordinates)
        marker.pose.orientation.w = 1.0
        msg.markers.append(marker)
    return msg


# --- published messages hold no NaN or inf ---------------------------------------------------


def finite_message(msg: object) -> bool:
    """Every float a published message carries (poses, points, scales, colours) is finite."""
    if isinstance(msg, MarkerArray):
        return all(finite_message(marker) for marker in msg.markers)
    if isinstance(msg, Marker):
        values = [_pose_values(msg.pose), (msg.scale.x, msg.scale.y, msg.scale.z)]
        values.append((msg.color.r, msg.color.g, msg.color.b, msg.color.a))
        points = np.array([(p.x, p.y, p.z) for p in msg.points], dtype=np.float64)
        return bool(np.isfinite(np.concatenate([np.ravel(v) for v in values])).all()) and bool(
            np.isfinite(points).all()
        )
    if isinstance(msg, PoseStamped):
        return bool(np.isfinite(_pose_values(msg.pose)).all())
    if isinstance(msg, OccupancyGrid):  # cells -1 (unknown), 0 (free) .. 100 (occupied)
        cells = np.frombuffer(msg.data, dtype=np.int8)
        info = msg.info
        return (
            len(cells) == info.width * info.height
            and bool(((cells == -1) | ((cells >= 0) & (cells <= 100))).all())
            and math.isfinite(info.resolution)
            and info.resolution > 0.0
            and bool(np.isfinite(_pose_values(info.origin)).all())
        )
    raise AssertionError(f"no finiteness check for {type(msg).__name__}")


def _pose_values(pose: object) -> tuple[float, ...]:
    p, q = pose.position, pose.orientation  # type: ignore[attr-defined]
    return (p.x, p.y, p.z, q.x, q.y, q.z, q.w)


def record_publications(node: Node) -> list[object]:
    """Every message ``node`` publishes from now on (its publishers' ``publish`` wrapped)."""
    sent: list[object] = []
    for publisher in node.publishers:
        if publisher.msg_type not in (Marker, MarkerArray, PoseStamped, OccupancyGrid):
            continue  # parameter events and the like: not the node's output
        original = publisher.publish

        def publish(msg: object, original=original) -> None:
            sent.append(msg)
            original(msg)

        publisher.publish = publish  # type: ignore[method-assign]
    return sent


def deliver_scan(node: RobotMapper, scan: LaserScan) -> None:
    """The scan subscription's callback, as the executor calls it (message info or not)."""
    callback = node._scan_sub.callback
    try:
        callback(scan, {})
    except TypeError:  # a callback without message info
        callback(scan)


def guard_errors(node: Node) -> dict[str, int]:
    """Exceptions a node's callback guard caught (none can escape it)."""
    guard = getattr(node, "guard", None)
    return dict(guard.errors) if guard is not None else {}


# --- robot_mapper ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def mapper_node() -> Iterator[tuple[RobotMapper, SingleThreadedExecutor, list[object]]]:
    with isolated_context() as context:
        node = RobotMapper(
            context=context,
            namespace="robot1",
            parameter_overrides=[Parameter("partial_map_period", value=0.05)],
        )
        node.warnings.log = lambda message: None
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        sent = record_publications(node)
        yield node, executor, sent
        executor.shutdown()
        node.destroy_node()


_NEXT_STAMP = [1.0e9]


@fuzz(150)
@given(scan=laser_scans(), in_order=st.booleans())
def test_fuzzed_scans_are_mapped_or_rejected_cleanly(
    mapper_node, scan: LaserScan, in_order: bool
) -> None:
    node, executor, sent = mapper_node
    if in_order:  # the stream goes on in order (else the drawn stamp: stale, future, zero ...)
        _NEXT_STAMP[0] += 0.025
        scan.header.stamp = stamp_from_seconds(_NEXT_STAMP[0])
    before = len(sent)
    deliver_scan(node, scan)  # the subscription's own callback (guard included)
    executor.spin_once(timeout_sec=0.0)  # timers: the partial map goes out when it changed
    assert guard_errors(node) == {}
    assert node.warnings.counts.get("internal_error", 0) == 0 and node.mapping_errors == 0
    assert all(finite_message(msg) for msg in sent[before:])
    if len(node.mapper.keyframes()) > 50:  # a long run maps junk for ever: start afresh
        node.mapper = type(node.mapper)(node.config.local_mapping)
        node.published_version = -1


def test_fuzzed_scans_over_real_topics(mapper_node) -> None:
    """A batch of random scans published on the real topic to the spinning node."""
    node, executor, sent = mapper_node
    driver = Node("fuzz_driver", context=node.context)
    publisher = driver.create_publisher(LaserScan, "/robot1/scan", qos_profile_sensor_data)
    scans: list[LaserScan] = []

    @fuzz(40)
    @given(scan=laser_scans())
    def collect(scan: LaserScan) -> None:
        scans.append(scan)

    collect()
    try:
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
        for scan in scans:
            before = node.scans_received
            publisher.publish(scan)
            spin_until(executor, lambda b=before: node.scans_received > b, timeout=2.0)
        assert guard_errors(node) == {} and node.mapping_errors == 0
        assert node.scans_received + getattr(node, "scans_lost", 0) >= len(scans)
        assert all(finite_message(msg) for msg in sent)
    finally:
        driver.destroy_node()


# --- map_merger ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def merger_node() -> Iterator[tuple[MapMerger, list[object], dict]]:
    with isolated_context() as context:
        node = MapMerger(
            context=context,
            parameter_overrides=[
                Parameter("robots", value=",".join(NAMES)),
                Parameter("merge_worker", value=False),
                # Every place matched in each merge: a time budget would make what a merge
                # links (and so the good robots' placements) depend on the machine's load.
                Parameter("merge.update_budget", value=0.0),
                Parameter("merge.join_probability", value=SIMULATED_WORLD_JOIN_PROBABILITY),
            ],
            config=MapMergerConfig(max_segments_per_map=3000),  # a fixed constant, lowered
        )
        node.warnings.log = node.notes.log = lambda message: None
        sent = record_publications(node)
        for name in ("alpha", "bravo"):
            node.robots[name].subscriptions[0].callback(message(name))
        assert node.merge_now() and node.result is not None
        good = {
            name: (node.robots[name].segments.copy(), node.result.placements[name])
            for name in ("alpha", "bravo")
        }
        assert all(placement is not None for _, placement in good.values())
        # The checks of every later publication cover the grid too.
        assert any(isinstance(m, OccupancyGrid) for m in sent)
        assert all(finite_message(m) for m in sent)
        yield node, sent, good
        node.destroy_node()


def assert_good_robots_unchanged(node: MapMerger, good: dict) -> None:
    """The good robots' maps untouched, and each still placed where it was: within 5 cm and
    0.5 deg, not exactly, because the joint graph optimises every robot's keyframes together
    (a third robot's links move the others' optimum by millimetres; a wrong link would move
    them by metres)."""
    for name, (segments, placement) in good.items():
        np.testing.assert_array_equal(node.robots[name].segments, segments)
        assert node.result is not None
        now = node.result.placements[name]
        assert now is not None, name
        assert np.hypot(now[0] - placement[0], now[1] - placement[1]) < 0.05, (name, now)
        assert abs(np.remainder(now[2] - placement[2] + np.pi, 2 * np.pi) - np.pi) < np.radians(
            0.5
        ), (name, now)


@fuzz(300)
@given(msg=partial_maps(), pose=st.tuples(POINT, POINT, POINT, POINT))
def test_fuzzed_partial_maps_and_poses_leave_the_good_robots_alone(
    merger_node, msg: MarkerArray, pose: tuple[float, ...]
) -> None:
    node, _, good = merger_node
    charlie = node.robots["charlie"]
    tracemalloc.start()
    try:
        charlie.subscriptions[0].callback(msg)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    from multi_robot_mapper.io.messages import pose_stamped

    position = pose_stamped((0.0, 0.0, 0.0), stamp_from_seconds(1.0), "charlie/map")
    position.pose.position.x, position.pose.position.y = pose[0], pose[1]
    position.pose.orientation.z, position.pose.orientation.w = pose[2], pose[3]
    charlie.subscriptions[1].callback(position)
    assert guard_errors(node) == {}
    assert np.isfinite(charlie.segments).all() and np.isfinite(charlie.keyframe_poses).all()
    assert charlie.pose is None or np.isfinite(charlie.pose).all()
    assert len(charlie.segments) <= node.config.max_segments_per_map
    # What one map costs to check is bounded by its own size, never by its numbers.
    points = sum(len(m.points) for m in msg.markers)
    assert peak < 2_000_000 + 200 * points
    assert_good_robots_unchanged(node, good)


@fuzz(12)
@given(msg=partial_maps())
def test_fuzzed_maps_through_the_merge_leave_the_good_robots_alone(
    merger_node, msg: MarkerArray
) -> None:
    node, sent, good = merger_node
    node.robots["charlie"].subscriptions[0].callback(msg)
    node.robots["bravo"].subscriptions[0].callback(message("bravo"))  # a merge is due
    before = len(sent)
    node._merge_timer.callback()  # the merge timer's own callback, guard included
    assert guard_errors(node) == {} and node.merge_errors == 0
    assert_good_robots_unchanged(node, good)
    assert all(finite_message(m) for m in sent[before:])


# --- files -----------------------------------------------------------------------------------


def _mutations() -> st.SearchStrategy[tuple[str, int, int]]:
    """(how, where, bit): random bytes, a cut at a fraction, or one flipped bit."""
    return st.tuples(
        st.sampled_from(["random", "truncate", "flip", "flip"]),
        st.integers(0, 2**31),
        st.integers(0, 7),
    )


def _mutate(data: bytes, how: str, where: int, bit: int, rng_bytes: bytes) -> bytes:
    if how == "random":
        return rng_bytes
    if not data:
        return data
    if how == "truncate":
        return data[: where % len(data)]
    position = where % len(data)
    return data[:position] + bytes([data[position] ^ (1 << bit)]) + data[position + 1 :]


@pytest.fixture(scope="module")
def carmen_sources(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    folder = tmp_path_factory.mktemp("carmen")
    lines = ["# log", "PARAM robot_front_laser_max 80.0 h 0"]
    for i in range(30):
        ranges = " ".join(f"{2.0 + 0.01 * (i + b):.2f}" for b in range(180))
        lines.append(f"FLASER 180 {ranges} {i * 0.1:.2f} 0 0 0 0 0 {100 + i * 0.2:.2f} h 0")
        lines.append(f"ODOM 0 0 0 0 0 0 {100 + i * 0.2:.2f} h 0")
    text = "\n".join(lines) + "\n"
    gz = folder / "x.log.gz"
    with gzip.open(gz, "wt") as stream:
        stream.write(text)
    return {".log": text.encode(), ".log.gz": gz.read_bytes()}


@fuzz(200)
@given(
    suffix=st.sampled_from([".log", ".log.gz"]),
    mutation=_mutations(),
    noise=st.binary(max_size=3000),
)
def test_fuzzed_carmen_logs_give_clean_scans_or_a_format_error(
    carmen_sources, tmp_path_factory, suffix: str, mutation: tuple[str, int, int], noise: bytes
) -> None:
    from multi_robot_mapper.io.carmen import CarmenFormatError, carmen_scan_data, read_carmen

    path = tmp_path_factory.mktemp("fuzzed") / f"f{suffix}"
    path.write_bytes(_mutate(carmen_sources[suffix], *mutation, noise))
    try:
        log = read_carmen(path)
    except CarmenFormatError:
        return
    assert math.isfinite(log.no_return.range_max) and log.no_return.range_max > 0
    for scan in log:
        assert np.isfinite(scan.ranges).all() and np.isfinite(scan.reference_pose).all()
        assert math.isfinite(scan.timestamp) and scan.ranges.size >= 2
        carmen_scan_data(scan)  # a LaserScan the front end accepts or refuses with a reason


@pytest.fixture(scope="module")
def bag_sources(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    from multi_robot_mapper.core.simulation import LaserModel, simulate_robots
    from multi_robot_mapper.io.bags import RobotRecording, TimedPose, TimedScan, write_recordings

    run = simulate_robots("office", 1, LaserModel(beams=181, rate=10.0), seed=0, duration=1.0)[0]
    recording = RobotRecording(
        "robot1",
        [
            TimedScan(float(t), "robot1/laser", s)
            for t, s in zip(run.stamps, run.scans, strict=True)
        ],
        [
            TimedPose(float(t), tuple(p), "world")
            for t, p in zip(run.stamps, run.T_world_laser, strict=True)
        ],
    )
    sources = {}
    for storage, suffix in (("mcap", ".mcap"), ("sqlite3", ".db3")):
        folder = tmp_path_factory.mktemp(storage) / "bag"
        write_recordings(folder, {"robot1": recording}, storage=storage)
        sources[suffix] = next(folder.glob(f"*{suffix}")).read_bytes()
    return sources


@fuzz(120)
@given(
    suffix=st.sampled_from([".mcap", ".db3"]), mutation=_mutations(), noise=st.binary(max_size=3000)
)
def test_fuzzed_bags_give_their_messages_or_a_bag_error(
    bag_sources, tmp_path_factory, suffix: str, mutation: tuple[str, int, int], noise: bytes
) -> None:
    from multi_robot_mapper.io.bags import BagError, read_recordings

    path = tmp_path_factory.mktemp("fuzzed") / f"bag{suffix}"
    path.write_bytes(_mutate(bag_sources[suffix], *mutation, noise))
    try:
        recordings = read_recordings(path)
    except BagError:
        return
    for recording in recordings.values():
        for item in recording.ground_truth:
            assert len(item.pose) == 3


@fuzz(200)
@given(mutation=_mutations(), noise=st.binary(max_size=2000))
def test_fuzzed_params_files_give_a_config_or_one_config_error(
    tmp_path_factory, mutation: tuple[str, int, int], noise: bytes
) -> None:
    from multi_robot_mapper.core.config import ConfigError
    from multi_robot_mapper.io.config_files import load_config
    from multi_robot_mapper.ros.mapper_config import RobotMapperConfig

    shipped = (Path(__file__).resolve().parents[2] / "config" / "robot_mapper.yaml").read_bytes()
    path = tmp_path_factory.mktemp("yaml") / "params.yaml"
    path.write_bytes(_mutate(shipped, *mutation, noise))
    try:
        config = load_config(RobotMapperConfig, path, node_name="robot_mapper")
    except ConfigError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)
        return
    assert isinstance(config, RobotMapperConfig)
