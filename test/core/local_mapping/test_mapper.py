"""Odometry-free local mapping, the front end: known answers on simulated drives (tracking,
bad scans). The match attempts (tracking, search, confidence in context) are in
`test_attempts.py`; the back end in `test_loop_closer.py` and `test_joins.py`."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from local_mapping_drives import (
    EXTRACTION,
    ate,
    feed,
    looped_drive,
    stranger_scan,
)

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.local_mapping import (
    LocalMapper,
    LocalMapperConfig,
    LocalUpdate,
)
from multi_robot_mapper.core.local_mapping.held import OUTLIER
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import (
    LaserModel,
    clutter_for,
    simulate_robots,
    simulate_scan,
)
from multi_robot_mapper.core.worlds import WORLDS, box


def _tracked_within_centimetres(mapper: LocalMapper, stamps, scans, truth) -> list:  # type: ignore[no-untyped-def]
    """Every scan of the drive placed by ``mapper`` in its first piece within 5 cm and 1 deg
    of the truth (relative to the first scan); the poses as placed."""
    poses = [feed(mapper, float(t), s).pose for t, s in zip(stamps, scans, strict=True)]
    assert mapper.pieces_started == 0 and all(p is not None for p in poses)
    for pose, true_pose in zip(poses, truth, strict=True):
        expected = se2.between(truth[0], true_pose)
        assert pose is not None
        assert np.hypot(pose[0] - expected[0], pose[1] - expected[1]) < 0.05
        assert abs(se2.wrap_angle(pose[2] - expected[2])) < np.radians(1.0)
    return poses


@pytest.mark.parametrize(
    "tracking",
    [
        {"local_map_keyframes": 3},
        {"velocity_window": 0.5},
        {"motion_prior": True, "velocity_window": 0.5},
    ],
    ids=["local_map", "velocity_window", "motion_prior"],
)
def test_the_opt_in_tracking_of_corridors_tracks_a_drive_within_centimetres(  # type: ignore[no-untyped-def]
    office_drive, tracking: dict[str, object]
) -> None:
    # Issue 47 item 5, each off by default (docs/decisions.md, tracking in corridors): on
    # when asked, it tracks a drive through the office as well as the default does.
    stamps, scans, truth = office_drive
    mapper = LocalMapper(dataclasses.replace(LocalMapperConfig(), **tracking))  # type: ignore[arg-type]
    _tracked_within_centimetres(mapper, stamps, scans, truth)


def test_a_simulated_drive_is_tracked_within_centimetres(office_drive) -> None:  # type: ignore[no-untyped-def]
    stamps, scans, truth = office_drive
    mapper = LocalMapper()
    poses = _tracked_within_centimetres(mapper, stamps, scans, truth)
    assert mapper.scans_set_aside == 0
    # Keyframes every keyframe_distance / keyframe_angle, each placed where the scan was.
    keyframes = mapper.keyframes()
    travelled = np.hypot(*np.diff(truth[:, :2], axis=0).T).sum()
    assert 1 + travelled / 0.5 / 2 <= len(keyframes) <= len(scans)
    for keyframe in keyframes:
        assert keyframe.segments.shape[1] == 4 and keyframe.piece == 0
    assert [k.index for k in keyframes] == list(range(len(keyframes)))
    # Every keyframe has an edge to the one before; the graph holds them all.
    assert len(mapper.backend.closer.graph) == len(keyframes)
    # The trajectory follows the optimised keyframes: every scan, in the robot's map frame,
    # where the live poses were give or take what the graph moved since (millimetres here).
    trajectory_stamps, trajectory = mapper.trajectory()
    np.testing.assert_array_equal(trajectory_stamps, stamps)
    np.testing.assert_allclose(trajectory, np.array(poses), atol=5e-3)


def test_the_same_place_scanned_again_and_again_does_not_grow_the_map() -> None:
    walls = box(0.0, 0.0, 8.0, 6.0)
    laser = LaserModel()
    rng = np.random.default_rng(0)
    mapper = LocalMapper(dataclasses.replace(LocalMapperConfig(), keyframe_distance=0.0))
    sizes, raw = [], 0
    for k in range(20):
        scan = simulate_scan(walls, (0.5, 0.2, 0.1 + 1e-3 * k), laser, rng)
        update = feed(mapper, 100.0 + k * 0.025, scan)
        raw += len(extract_scan(scan, EXTRACTION)[0].segments)
        assert update.accepted
        sizes.append(len(mapper.map_segments))
    # Every scan is a keyframe (it turned a little each time), yet the walls seen twenty
    # times are fused (Alg. 5): the long walls are not duplicated.
    assert len(mapper.keyframes()) == 20
    assert sizes[-1] <= 0.35 * raw
    assert sizes[-1] <= 2 * sizes[0]
    fused = mapper.map_segments
    length = np.hypot(fused[:, 2] - fused[:, 0], fused[:, 3] - fused[:, 1])
    assert np.count_nonzero(length > 0.5) <= 5


def test_a_scan_of_another_place_is_not_integrated_and_the_map_is_kept(office_drive) -> None:  # type: ignore[no-untyped-def]
    stamps, scans, _ = office_drive
    mapper = LocalMapper()
    for t, s in zip(stamps[:40], scans[:40], strict=True):
        assert feed(mapper, float(t), s).piece == 0
    before = {kf.index: kf for kf in mapper.keyframes()}
    update = feed(mapper, float(stamps[40]), stranger_scan())
    # Not integrated: held until the next scan says whether the robot is lost.
    assert not update.accepted and not update.new_piece and mapper.scans_held == 1
    for keyframe in mapper.keyframes():  # the map is as it was
        np.testing.assert_array_equal(
            keyframe.T_robotmap_keyframe, before[keyframe.index].T_robotmap_keyframe
        )
    assert len(mapper.keyframes()) == len(before)
    # The drive goes on in the office map: the next scans are placed from it, and the
    # stranger, which none followed, is set aside. No piece started.
    assert feed(mapper, float(stamps[41]), scans[41]).piece == 0
    assert mapper.set_aside_reasons == {OUTLIER: 1} and mapper.scans_held == 0
    assert feed(mapper, float(stamps[42]), scans[42]).piece == 0
    assert mapper.main_piece() == 0 and mapper.pieces_started == 0
    assert all(kf.piece == 0 for kf in mapper.keyframes())
    assert float(stamps[40]) not in mapper.trajectory()[0]


def test_a_scan_without_structure_is_set_aside_before_anything_else() -> None:
    laser = LaserModel()
    post = np.array([[1.0, -0.2, 1.0, 0.2]])  # 0.4 m of wall: less than min_match_value
    empty = simulate_scan(post, (0.0, 0.0, 0.0), laser, np.random.default_rng(0))
    mapper = LocalMapper()
    update = feed(mapper, 1.0, empty)
    assert not update.accepted and update.pose is None
    assert mapper.set_aside_reasons == {"too little structure in the scan": 1}
    assert mapper.pose is None and mapper.keyframes() == []


def test_a_first_scan_nothing_confirms_stays_in_a_piece_of_its_own(office_drive) -> None:  # type: ignore[no-untyped-def]
    stamps, scans, truth = office_drive
    mapper = LocalMapper()
    assert feed(mapper, float(stamps[0]) - 1.0, stranger_scan(2)).piece == 0
    for t, s in zip(stamps[:20], scans[:20], strict=True):
        feed(mapper, float(t), s)
    main = mapper.main_piece()
    assert main != 0 and mapper.pieces_started == 1
    trajectory_stamps, poses = mapper.trajectory()
    np.testing.assert_array_equal(trajectory_stamps, stamps[:20])
    expected = np.array([se2.between(truth[0], p) for p in truth[:20]])
    np.testing.assert_allclose(poses[:, :2], expected[:, :2], atol=0.05)


def test_a_person_blocking_the_laser_does_not_break_the_map() -> None:
    # Three scans show nothing of the office (a person in front of the laser): they start a
    # piece of their own (the second confirms the first), and the office scans after them are
    # placed in the office map again.
    stamps, scans, truth = looped_drive(rate=4.0, laps=0.5, seed=4)
    blocked = range(30, 33)
    local = LocalMapper()
    updates = [
        feed(local, float(t), stranger_scan(k) if k in blocked else s)
        for k, (t, s) in enumerate(zip(stamps, scans, strict=True))
    ]
    assert not updates[30].accepted and updates[31].new_piece
    assert all(u.piece == 0 for k, u in enumerate(updates) if k not in blocked)
    times, poses = local.trajectory()
    kept = [k for k in range(len(stamps)) if k not in blocked]
    np.testing.assert_array_equal(times, stamps[kept])
    truth_at = {float(stamps[k]): np.asarray(se2.between(truth[0], truth[k])) for k in kept}
    assert ate(times, poses, truth_at) < 0.02


def test_a_cluttered_office_is_tracked_within_centimetres() -> None:
    # Chairs, tables, pillars and people walking to and fro: a third of the returns or more
    # fall in clusters too small for a segment. The drive is still tracked.
    clutter = clutter_for("office", 0.15, seed=2)
    run = simulate_robots("office", 1, LaserModel(), seed=2, duration=4.0, clutter=clutter)[0]
    segments = [extract_scan(s, EXTRACTION)[0] for s in run.scans[:5]]
    assert all(s.dropped_points > 20 for s in segments)
    mapper = LocalMapper()
    for t, s, true_pose in zip(run.stamps, run.scans, run.T_world_laser, strict=True):
        update = feed(mapper, float(t), s)
        assert update.accepted and update.piece == 0
        assert update.pose is not None
        expected = se2.between(run.T_world_laser[0], true_pose)
        assert np.hypot(update.pose[0] - expected[0], update.pose[1] - expected[1]) < 0.05
        assert abs(se2.wrap_angle(update.pose[2] - expected[2])) < np.radians(1.0)


def _degenerate(kind: str, pose: np.ndarray, seed: int) -> LaserScanData:
    """A 1081-beam scan from ``pose`` (world frame) whose angles make no sensible laser.

    ``misreported_*``: a real UTM-30LX scan (270 degrees) whose driver reports that tiny
    angle_increment, so its 1081 returns land in a wedge of 6 degrees (1e-4), on one ray
    (1e-8, 1e-30) or on one ray at the smallest increment a float holds (5e-324: every
    bearing divided by it overflows). ``narrow``: what a laser of 1081 beams at 1e-4 rad
    really sees (a piece of one wall). ``spot``: every range the same, on one ray.
    """
    rng = np.random.default_rng(seed)
    if kind == "narrow":
        return simulate_scan(
            WORLDS["office"](), tuple(pose), LaserModel(field_of_view=1e-4 * 1080), rng
        )
    real = simulate_scan(WORLDS["office"](), tuple(pose), LaserModel(), rng)
    ranges = 3.0 + rng.normal(0.0, 0.001, 1081) if kind == "spot" else real.ranges
    increment = {
        "misreported_1e-4": 1e-4,
        "misreported_1e-8": 1e-8,
        "misreported_1e-30": 1e-30,
        "misreported_5e-324": 5e-324,
        "spot": 1e-8,
    }[kind]
    # angle_min 0: at 5e-324 any other start would swallow the increments (angle_max ==
    # angle_min), a scan the boundary refuses for its beam count before it gets here.
    return LaserScanData(ranges, 0.0, increment * 1080, increment, real.range_min, real.range_max)


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_degenerate_scans_let_through_are_never_placed_in_the_map() -> None:
    # The boundary's field-of-view check turned off (min_field_of_view 0): the local mapper
    # on its own must not integrate a placement that such a scan cannot constrain. One
    # degenerate scan after every tenth scan of the drive, halfway to the next: each is set
    # aside or starts a piece of its own, none is placed in the map, and the drive is
    # tracked as well as without them (the person-blocking test's 2 cm).
    open_gate = dataclasses.replace(EXTRACTION, min_field_of_view=0.0)
    kinds = (
        "misreported_1e-4",
        "misreported_1e-8",
        "misreported_1e-30",
        "misreported_5e-324",
        "narrow",
        "spot",
    )
    stamps, scans, truth = looped_drive(rate=4.0, laps=0.5, seed=4)
    local = LocalMapper()
    degenerate: dict[float, tuple[str, LocalUpdate]] = {}
    for k, (t, s) in enumerate(zip(stamps, scans, strict=True)):
        local.add_scan(float(t), extract_scan(s, open_gate)[0], s)
        if k % 10 == 9 and k + 1 < len(stamps):
            kind = kinds[(k // 10) % len(kinds)]
            scan = _degenerate(kind, 0.5 * (truth[k] + truth[k + 1]), seed=k)
            stamp = 0.5 * float(stamps[k] + stamps[k + 1])
            update = local.add_scan(stamp, extract_scan(scan, open_gate)[0], scan)
            degenerate[stamp] = (kind, update)
    assert set(kind for kind, _ in degenerate.values()) == set(kinds)
    for kind, update in degenerate.values():
        # Set aside, or placed where nothing depends on it: a new piece of its own.
        assert not update.accepted or update.new_piece, kind
    assert local.main_piece() == 0
    times, poses = local.trajectory()
    assert not set(times.tolist()) & set(degenerate), "a degenerate scan is in the map"
    # Every good scan is in the map (the pieces the degenerate scans started do not take
    # them), where the simulator put it.
    np.testing.assert_array_equal(times, stamps)
    truth_at = {
        float(t): np.asarray(se2.between(truth[0], p)) for t, p in zip(stamps, truth, strict=True)
    }
    assert ate(times, poses, truth_at) < 0.02
