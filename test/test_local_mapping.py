"""Odometry-free local mapping: known answers on simulated drives, pieces, loop closures."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import (
    LocalMapper,
    LocalMapperConfig,
    LocalUpdate,
    attempts,
    context_model,
    keyframe_map,
    loop_closer,
    mapper,
    windows,
)
from multi_robot_mapper.core.local_mapping import joins as piece_joins
from multi_robot_mapper.core.matching import MatchResult, integrate
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE
from multi_robot_mapper.core.pose_graph import ReachBound
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import (
    LaserModel,
    clutter_for,
    drive_path,
    route_section,
    simulate_robots,
    simulate_scan,
)
from multi_robot_mapper.core.worlds import ROUTES, WORLDS, box

EXTRACTION = ExtractionConfig()


@pytest.fixture(scope="module")
def office_drive() -> tuple[np.ndarray, list[LaserScanData], np.ndarray]:
    """4 s of a simulated UTM-30LX at 40 Hz driving through the office world."""
    run = simulate_robots("office", 1, LaserModel(), seed=1, duration=4.0)[0]
    return run.stamps, run.scans, run.T_world_laser


def _relative(first: np.ndarray, pose: np.ndarray) -> np.ndarray:
    T = se2.invert(se2.matrix_from_pose(*first)) @ se2.matrix_from_pose(*pose)
    return np.asarray(se2.pose_from_matrix(T))


def _feed(mapper: LocalMapper, stamp: float, scan: LaserScanData) -> LocalUpdate:
    segments, _ = extract_scan(scan, EXTRACTION)
    return mapper.add_scan(stamp, segments, scan)


def _mapped(stamps: np.ndarray, scans: list[LaserScanData]) -> LocalMapper:
    """A LocalMapper (defaults, back end in line) fed every scan of a drive."""
    local = LocalMapper()
    for t, s in zip(stamps, scans, strict=True):
        _feed(local, float(t), s)
    return local


def _stranger(seed: int = 5) -> LaserScanData:
    """A round room with a pillar, nothing like the office."""
    octagon = np.array(
        [
            [6 * np.cos(a), 6 * np.sin(a), 6 * np.cos(a + np.pi / 4), 6 * np.sin(a + np.pi / 4)]
            for a in np.arange(8) * np.pi / 4 + 0.3
        ]
    )
    return simulate_scan(
        np.vstack((octagon, box(2.0, 1.0, 0.4, 0.4))),
        (0.0, 0.0, 0.0),
        LaserModel(),
        np.random.default_rng(seed),
    )


@pytest.fixture
def as_matched(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Every context keeps the match confidence as it is: a fake INTEGRATE's confidences are
    then the ones the front end decides on."""
    monkeypatch.setattr(context_model, "CALIBRATION", {c: (1.0, 0.0) for c in attempts.CONTEXTS})


def _match(
    pose: tuple[float, float, float], confidence: float, judged: object = None
) -> MatchResult:
    """A match that places the new scan at ``pose`` with ``confidence`` (for a fake
    INTEGRATE; as the real one, confidence 0 where ``judged`` does not want it)."""
    x, y, theta = pose
    T_1_2 = np.array([theta, x, y])
    if callable(judged) and not judged(T_1_2):
        confidence = 0.0
    return MatchResult(T_1_2, 5.0, 0.9, True, 1, 1, confidence)


def _only_the_last_scan(segments: np.ndarray, scan: LaserScanData) -> attempts.References:
    """References of a robot whose only scan (keyframe 0) is the last one, at the origin."""
    return attempts.References(
        here=(0.0, 0.0, 0.0),
        last=attempts.Reference(segments, scan, attempts.Anchor(0, (0.0, 0.0, 0.0)), 0.0),
        keyframe=0,
        older=[],
        poses={0: (0.0, 0.0, 0.0)},
        pieces={0: 0},
        scans={0: keyframe_map.KeyframeScan(0, 0.0, segments, scan)},
    )


def _track_half_a_metre_ahead() -> tuple[attempts.Attempt, bool, bool]:
    """:func:`attempts.match_scan` of a scan tracked from a prediction 0.5 m ahead, against
    only the last scan (with a fake INTEGRATE installed by the test)."""
    scan = _stranger()
    segments, _ = extract_scan(scan, EXTRACTION)
    references = _only_the_last_scan(segments.segments, scan)
    motions = [(0.5, 0.0, 0.0), (0.0, 0.0, 0.0)]
    return attempts.match_scan(
        LocalMapperConfig(), references, segments.segments, scan, motions, True, lambda *_: None
    )


def _ate(stamps: np.ndarray, poses: np.ndarray, truth: dict[float, np.ndarray]) -> float:
    """RMSE of the positions after the best rigid alignment (Umeyama without scale)."""
    est = poses[:, :2]
    ref = np.array([truth[float(s)][:2] for s in stamps])
    est_c, ref_c = est - est.mean(axis=0), ref - ref.mean(axis=0)
    u, _, vt = np.linalg.svd(ref_c.T @ est_c)
    d = np.sign(np.linalg.det(u @ vt))
    R = u @ np.diag([1.0, d]) @ vt
    return float(np.sqrt(np.mean(np.sum((est_c @ R.T - ref_c) ** 2, axis=1))))


def test_a_simulated_drive_is_tracked_within_centimetres(office_drive) -> None:  # type: ignore[no-untyped-def]
    stamps, scans, truth = office_drive
    mapper = LocalMapper()
    poses = [_feed(mapper, float(t), s).pose for t, s in zip(stamps, scans, strict=True)]
    assert mapper.scans_set_aside == 0 and mapper.pieces_started == 0
    assert all(p is not None for p in poses)
    for pose, true_pose in zip(poses, truth, strict=True):
        expected = _relative(truth[0], true_pose)
        assert pose is not None
        assert np.hypot(pose[0] - expected[0], pose[1] - expected[1]) < 0.05
        assert abs(se2.wrap_angle(pose[2] - expected[2])) < np.radians(1.0)
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
        update = _feed(mapper, 100.0 + k * 0.025, scan)
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
        assert _feed(mapper, float(t), s).piece == 0
    before = {kf.index: kf for kf in mapper.keyframes()}
    update = _feed(mapper, float(stamps[40]), _stranger())
    # Not integrated: the robot is lost and the stranger starts a piece of its own.
    assert update.new_piece and update.piece != 0
    assert mapper.set_aside_reasons == {"lost: no confident match": 1}
    for keyframe in mapper.keyframes():
        if keyframe.index in before:
            np.testing.assert_array_equal(
                keyframe.T_robotmap_keyframe, before[keyframe.index].T_robotmap_keyframe
            )
            assert keyframe.piece == 0
    # The drive goes on in the office map: the next scans match its keyframes again.
    assert _feed(mapper, float(stamps[41]), scans[41]).piece == 0
    assert _feed(mapper, float(stamps[42]), scans[42]).piece == 0
    assert mapper.main_piece() == 0


def test_a_scan_without_structure_is_set_aside_before_anything_else() -> None:
    laser = LaserModel()
    post = np.array([[1.0, -0.2, 1.0, 0.2]])  # 0.4 m of wall: less than min_match_value
    empty = simulate_scan(post, (0.0, 0.0, 0.0), laser, np.random.default_rng(0))
    mapper = LocalMapper()
    update = _feed(mapper, 1.0, empty)
    assert not update.accepted and update.pose is None
    assert mapper.set_aside_reasons == {"too little structure in the scan": 1}
    assert mapper.pose is None and mapper.keyframes() == []


def test_a_first_scan_nothing_confirms_stays_in_a_piece_of_its_own(office_drive) -> None:  # type: ignore[no-untyped-def]
    stamps, scans, truth = office_drive
    mapper = LocalMapper()
    assert _feed(mapper, float(stamps[0]) - 1.0, _stranger(2)).piece == 0
    for t, s in zip(stamps[:20], scans[:20], strict=True):
        _feed(mapper, float(t), s)
    main = mapper.main_piece()
    assert main != 0 and mapper.pieces_started == 1
    trajectory_stamps, poses = mapper.trajectory()
    np.testing.assert_array_equal(trajectory_stamps, stamps[:20])
    expected = np.array([_relative(truth[0], p) for p in truth[:20]])
    np.testing.assert_allclose(poses[:, :2], expected[:, :2], atol=0.05)


def _looped_drive(rate: float, laps: float, seed: int) -> tuple[np.ndarray, list, np.ndarray]:
    """The office tour driven ``laps`` times at 0.8 m/s, scanned at ``rate`` Hz (361 beams)."""
    route = np.asarray(ROUTES["office"], dtype=np.float64)
    lap = route_section(route, 0.0, 1e9)
    length = float(np.hypot(*np.diff(lap, axis=0).T).sum())
    waypoints = np.vstack([lap] + [lap[1:]] * (int(np.ceil(laps)) - 1))
    poses = drive_path(waypoints, 0.8, rate, laps * length / 0.8)
    laser = LaserModel(rate=rate, beams=361, range_noise=0.01)
    rng = np.random.default_rng(seed)
    walls = WORLDS["office"]()
    scans = [simulate_scan(walls, tuple(p), laser, rng) for p in poses]
    return 1000.0 + np.arange(len(poses)) / rate, scans, poses


def _biased(*args: object, **kwargs: object) -> MatchResult:
    """INTEGRATE turning 1 degree per metre of motion too far."""
    result = integrate(*args, **kwargs)  # type: ignore[arg-type]
    T = result.T_1_2.copy()
    T[0] += np.radians(1.0) * float(np.hypot(T[1], T[2]))
    return dataclasses.replace(result, T_1_2=T)


def test_a_heading_bias_is_straightened_by_loop_closures(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # Every match the front end accepts turns 1 degree per metre of motion too far: the map
    # bends by tens of degrees over a lap. Driving the office round twice, the back end (its
    # local edges and loop closures, matched without the bias) pulls it straight again.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=2.0, seed=3)

    monkeypatch.setattr(attempts, "integrate", _biased)
    local = _mapped(stamps, scans)
    assert local.pieces_started == 0
    assert len(local.closures) >= 10
    times, poses = local.trajectory()
    truth_at = {
        float(t): np.asarray(_relative(truth[0], p)) for t, p in zip(stamps, truth, strict=True)
    }
    assert _ate(times, poses, truth_at) < 0.05
    # Without the back end's edges the same bias bends the map by metres.
    monkeypatch.setattr(windows, "integrate", _biased)
    unclosed = LocalMapper(
        dataclasses.replace(LocalMapperConfig(), loop_candidates=0, local_edges=0)
    )
    for t, s in zip(stamps, scans, strict=True):
        _feed(unclosed, float(t), s)
    assert _ate(*unclosed.trajectory(), truth_at) > 0.5


def test_a_person_blocking_the_laser_does_not_break_the_map() -> None:
    # Three scans show nothing of the office (a person in front of the laser): they start a
    # piece of their own, and the office scans after them are placed in the office map again.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=0.5, seed=4)
    blocked = range(30, 33)
    local = LocalMapper()
    updates = [
        _feed(local, float(t), _stranger(k) if k in blocked else s)
        for k, (t, s) in enumerate(zip(stamps, scans, strict=True))
    ]
    assert updates[30].new_piece
    assert all(u.piece == 0 for k, u in enumerate(updates) if k not in blocked)
    times, poses = local.trajectory()
    kept = [k for k in range(len(stamps)) if k not in blocked]
    np.testing.assert_array_equal(times, stamps[kept])
    truth_at = {float(stamps[k]): np.asarray(_relative(truth[0], truth[k])) for k in kept}
    assert _ate(times, poses, truth_at) < 0.02


def _mapped_losing_the_robot_at(
    monkeypatch: pytest.MonkeyPatch, stamps: np.ndarray, scans: list, lost_at: set[int]
) -> tuple[LocalMapper, list[LocalUpdate]]:
    """The scans mapped by a LocalMapper whose front end fails on the scans ``lost_at`` (a
    match not confident enough: each starts a new piece from its best match's guess)."""
    original = mapper.LocalMapper._match
    count = {"scan": 0}

    def failing(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        chosen, integrated = original(self, *args, **kwargs)
        return chosen, integrated and count["scan"] not in lost_at

    monkeypatch.setattr(mapper.LocalMapper, "_match", failing)
    local = LocalMapper()
    updates = []
    for k, (t, s) in enumerate(zip(stamps, scans, strict=True)):
        count["scan"] = k
        updates.append(_feed(local, float(t), s))
    return local, updates


def _ate_of_one_map(local: LocalMapper, stamps: np.ndarray, truth: np.ndarray) -> float:
    """Every scan in the map's one piece: its ATE against the truth (m)."""
    assert set(local.backend.map.pieces.tolist()) == {0}
    times, poses = local.trajectory()
    np.testing.assert_array_equal(times, stamps)
    truth_at = {
        float(t): np.asarray(_relative(truth[0], p)) for t, p in zip(stamps, truth, strict=True)
    }
    return _ate(times, poses, truth_at)


def test_a_lost_robot_maps_on_in_a_piece_that_joins_the_map_again(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # The front end fails on two scans (a match not confident enough): each starts a new
    # piece from its best match's guess. The next keyframes of the piece confirm the guess and
    # the back end joins the piece to the map; in the end every scan is in one map.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=0.5, seed=4)
    lost_at = {25, 60}
    local, updates = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, lost_at)
    assert [u.new_piece for u in updates] == [k in lost_at for k in range(len(stamps))]
    assert local.pieces_started == 2
    assert [c.kind for c in local.closures].count("join") == 2
    assert _ate_of_one_map(local, stamps, truth) < 0.02


def test_a_join_bounds_the_robots_motion_across_the_loss(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # The robot is lost once. When its piece joins the map, the loss becomes a bound in the
    # graph: the piece's first keyframe lies within the robot's reach of its last placed
    # scan (it does not jump). The truth keeps it.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=0.5, seed=4)
    lost_at = 25
    seen: list[piece_joins.LostFrom] = []
    original_add = loop_closer.LoopCloser.add_keyframe

    def recorded(self, scan, pose, piece, odometry, lost_from=None):  # type: ignore[no-untyped-def]
        if lost_from is not None:
            seen.append(lost_from)
        return original_add(self, scan, pose, piece, odometry, lost_from)

    monkeypatch.setattr(loop_closer.LoopCloser, "add_keyframe", recorded)
    local, updates = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {lost_at})
    closer = local.backend.closer
    assert len(seen) == 1 and seen[0].reach is not None
    lost = seen[0]
    assert closer.motion_bounds == 1
    (bound,) = closer.graph.bounds.values()
    x, y, _ = lost.T_last_keyframe_scan
    assert bound == ReachBound(
        lost.last_keyframe, updates[lost_at].piece, (x, y), lost.reach, RIGHT_DISTANCE
    )
    assert np.hypot(*_relative(truth[lost_at - 1], truth[lost_at])[:2]) < lost.reach
    assert _ate_of_one_map(local, stamps, truth) < 0.02


@pytest.mark.parametrize("search_back", [True, False])
def test_a_piece_the_robot_left_joins_when_the_robot_comes_back_to_it(
    monkeypatch, search_back: bool
) -> None:  # type: ignore[no-untyped-def]
    # The robot is lost at scan 25 (the second piece starts) and again at scan 200, near the
    # end of its lap (the third piece); the second piece's own searches never join (made to
    # fail). The third joins the first through the chain of losses, and the robot drives on
    # into the second piece's ground: the first piece's new keyframes find it, and the map is
    # one piece again. Without that search the second piece stays apart.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=1.3, seed=4)
    second_piece: list[int] = []
    original_lost = piece_joins.PieceJoins._lost
    original_join = piece_joins.PieceJoins._join_through_guess

    def lost(self, piece, lost_from):  # type: ignore[no-untyped-def]
        second_piece.append(piece)
        return original_lost(self, piece, lost_from)

    def not_the_second(self, index, piece, keyframe, T_other_piece, depth):  # type: ignore[no-untyped-def]
        if second_piece[0] in (piece, self.keyframes.piece(keyframe)):
            return []
        return original_join(self, index, piece, keyframe, T_other_piece, depth)

    monkeypatch.setattr(piece_joins.PieceJoins, "_lost", lost)
    monkeypatch.setattr(piece_joins.PieceJoins, "_join_through_guess", not_the_second)
    if not search_back:
        monkeypatch.setattr(
            piece_joins.PieceJoins, "_join_pieces_lost_here", lambda self, index, piece: []
        )
    local, _ = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {25, 200})
    if search_back:
        assert [c.kind for c in local.closures].count("join") == 2
        assert local.backend.closer.motion_bounds == 2
        assert _ate_of_one_map(local, stamps, truth) < 0.03
    else:
        assert set(local.backend.map.pieces.tolist()) == {0, second_piece[0]}


@pytest.mark.parametrize("turn_limit", [piece_joins._TURN_BETWEEN_SCANS, 2.0 * np.pi])
def test_a_join_that_turns_the_robot_round_is_refused(monkeypatch, turn_limit) -> None:  # type: ignore[no-untyped-def]
    # The robot is lost once; every match between the two pieces is then made the half-turned
    # look-alike of the right one (the piece turned round about its first scan, consistently,
    # confidence 0.99): what a symmetric corridor offers. The robot turned far less than a
    # quarter turn between its last placed scan and the piece's first, so the joins are refused
    # and the piece stays apart; without the limit (2 pi) the look-alike joins the map.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=0.5, seed=4)
    original_windows = loop_closer.LoopCloser._match_windows

    def turned_round(self, first, second, predicted, search=True):  # type: ignore[no-untyped-def]
        result = original_windows(self, first, second, predicted, search)
        keyframes = self.keyframes
        if keyframes.piece(first) == keyframes.piece(second):
            return result
        theta, x, y = result.T_1_2
        T_other_second = se2.compose(keyframes.pose(first), (x, y, theta))
        T_other_piece = se2.compose(T_other_second, se2.between(keyframes.pose(second), (0, 0, 0)))
        wrong = se2.compose(se2.compose(T_other_piece, (0.0, 0.0, np.pi)), keyframes.pose(second))
        dx, dy, dtheta = se2.between(keyframes.pose(first), wrong)
        return dataclasses.replace(result, T_1_2=np.array([dtheta, dx, dy]), confidence=0.99)

    monkeypatch.setattr(loop_closer.LoopCloser, "_match_windows", turned_round)
    monkeypatch.setattr(piece_joins, "_TURN_BETWEEN_SCANS", turn_limit)
    local, _ = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {25})
    assert local.pieces_started == 1
    joins = [c for c in local.closures if c.kind == "join"]
    if turn_limit < np.pi:
        assert joins == []
        assert local.backend.closer.refused["turned round from the robot's last pose (join)"] > 0
        assert len(set(local.backend.map.pieces.tolist())) == 2
    else:
        # The look-alike joined: the map is decimetres off (the right join: under 2 cm, the
        # test above).
        assert len(joins) == 1
        assert _ate_of_one_map(local, stamps, truth) > 0.1


def _guessing_wrong(monkeypatch: pytest.MonkeyPatch, reach_known: bool) -> None:
    """Every loss's guess made 4 m and 30 degrees off (and its reach unknown, unless
    ``reach_known``)."""
    original_add = loop_closer.LoopCloser.add_keyframe

    def wrong_guess(self, scan, pose, piece, odometry, lost_from=None):  # type: ignore[no-untyped-def]
        if lost_from is not None:
            x, y, theta = lost_from.T_keyframe_piece
            lost_from = lost_from._replace(
                T_keyframe_piece=(x + 4.0, y, theta + np.radians(30.0)),
                reach=lost_from.reach if reach_known else None,
            )
        return original_add(self, scan, pose, piece, odometry, lost_from)

    monkeypatch.setattr(loop_closer.LoopCloser, "add_keyframe", wrong_guess)


@pytest.mark.parametrize("reach_known", [True, False])
def test_a_piece_whose_guess_is_wrong_joins_where_the_robot_can_have_driven(
    monkeypatch, reach_known: bool
) -> None:  # type: ignore[no-untyped-def]
    # The robot is lost once and the front end's guess of the new piece is 4 m and 30 degrees
    # off, so nothing is found near it. The robot's motion still bounds the piece: its first
    # scan lies within the robot's reach of its last placed scan. Searched on the ring of the
    # old piece's keyframes that this allows, two keyframes of the new piece find the same
    # placement and the piece joins the map where it belongs. Without a known reach (no
    # speed yet) only the guess is searched, and the piece stays apart.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=0.5, seed=4)
    _guessing_wrong(monkeypatch, reach_known)
    local, _ = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {25})
    assert local.pieces_started == 1
    joins = [c for c in local.closures if c.kind == "join"]
    if reach_known:
        assert len(joins) == 1
        assert _ate_of_one_map(local, stamps, truth) < 0.02
    else:
        assert joins == []
        assert len(set(local.backend.map.pieces.tolist())) == 2


def _joining_far_from_the_loss(monkeypatch: pytest.MonkeyPatch, keyframes: int = 40) -> None:
    """The piece a robot was lost into matches nothing of the piece before it until it has
    ``keyframes`` keyframes (the place of the loss is hard to match): it joins where the
    robot comes back, far from the loss."""
    original = piece_joins.PieceJoins._join_through_guess

    def held(self, index, piece, keyframe, T_other_piece, depth):  # type: ignore[no-untyped-def]
        if index - piece < keyframes:
            return []
        return original(self, index, piece, keyframe, T_other_piece, depth)

    monkeypatch.setattr(piece_joins.PieceJoins, "_join_through_guess", held)


@pytest.mark.parametrize("heading", [True, False])
def test_the_heading_across_a_loss_closes_the_loop_where_the_join_is_far_from_it(
    monkeypatch, heading: bool
) -> None:  # type: ignore[no-untyped-def]
    # Every match the front end accepts turns 1 degree per metre too far. The robot is lost
    # at scan 25, and its piece joins the map only where it comes back to its start, a lap
    # later: the loop is open at the loss, where nothing but the reach bound ties the two
    # sides. The front end's guess across the loss (its best match, not confident enough to
    # integrate) gives the graph its heading there: an edge with the heading information of
    # the two scans at the guess and none in position (a wrong guess is mostly a corridor
    # slid along itself). With it the loop closes and the bias is straightened out.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=1.2, seed=3)

    monkeypatch.setattr(attempts, "integrate", _biased)
    _joining_far_from_the_loss(monkeypatch)
    if not heading:
        monkeypatch.setattr(loop_closer.LoopCloser, "_bridge_headings", lambda self: [])
    local, updates = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {25})
    closer = local.backend.closer
    (join,) = [c for c in local.closures if c.kind == "join"]
    assert join.second - updates[25].piece >= 40  # found where the robot came back
    if heading:
        (bridge,) = closer.headings
        assert (bridge.second, bridge.kind) == (updates[25].piece, "heading")
        (edge,) = [
            e
            for e in closer.graph.edges.values()
            if (e.first, e.second, e.T_first_second)
            == (bridge.first, bridge.second, bridge.T_first_second)
        ]
        assert np.all(np.diag(edge.information)[:2] <= 1e-6)
        assert edge.information[2, 2] > 1.0 / np.radians(5.0) ** 2
        assert _ate_of_one_map(local, stamps, truth) < 0.03
    else:
        assert _ate_of_one_map(local, stamps, truth) > 0.04


def test_a_heading_across_a_loss_that_disagrees_with_the_joined_map_is_refused(
    monkeypatch,
) -> None:  # type: ignore[no-untyped-def]
    # The guess is 4 m and 30 degrees off; the piece joins a lap later, where the robot comes
    # back (on the ring its motion allows). The joined map knows the heading across the loss
    # far better than 30 degrees, so the guess's heading is refused and the map is right.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=1.2, seed=3)
    _joining_far_from_the_loss(monkeypatch)
    _guessing_wrong(monkeypatch, reach_known=True)
    local, _ = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {25})
    closer = local.backend.closer
    assert [c.kind for c in local.closures].count("join") == 1
    assert closer.headings == []
    assert closer.refused["heading far from the graph's (loss)"] == 1
    assert _ate_of_one_map(local, stamps, truth) < 0.02


def test_a_loss_its_join_spans_gets_no_second_heading(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # The piece joins at the loss itself (its first keyframes' window against the window of
    # the keyframe the robot was lost near): that join's edge already closes the loss, from
    # the same scans as the guess, so the guess's heading is not added on top.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=0.5, seed=4)
    local, _ = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {25})
    closer = local.backend.closer
    assert [c.kind for c in local.closures].count("join") == 1
    assert closer.headings == []
    assert closer.refused["loss spanned by its join (heading)"] == 1
    assert _ate_of_one_map(local, stamps, truth) < 0.02


@pytest.mark.parametrize("reach_known", [True, False])
def test_a_piece_joins_through_a_chain_of_losses_where_the_robot_can_have_driven(
    monkeypatch, reach_known: bool
) -> None:  # type: ignore[no-untyped-def]
    # A person blocks the laser at scan 25 (a piece of one scan that matches nothing) and the
    # robot is lost again at scan 26; both guesses are 4 m and 30 degrees off, so the third
    # piece's guess, composed through the second, is 8 m off. The robot's motion still bounds
    # it: its first scan lies within two reaches, plus the second piece's extent (none), of
    # the last scan placed in the first piece. Searched there, the third piece joins the first
    # and the map is whole but for the blocked scan. Without a known reach it stays apart.
    stamps, scans, truth = _looped_drive(rate=4.0, laps=0.5, seed=4)
    blocked = 25
    scans = [_stranger(k) if k == blocked else s for k, s in enumerate(scans)]
    _guessing_wrong(monkeypatch, reach_known)
    local, updates = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {blocked, blocked + 1})
    assert local.pieces_started == 2
    pieces = local.backend.map.pieces
    kept = [k for k in range(len(stamps)) if k != blocked]
    if reach_known:
        assert [c.kind for c in local.closures].count("join") == 1
        assert set(pieces.tolist()) == {0, updates[blocked].piece}
        times, poses = local.trajectory(0)
        np.testing.assert_array_equal(times, stamps[kept])
        truth_at = {float(stamps[k]): np.asarray(_relative(truth[0], truth[k])) for k in kept}
        assert _ate(times, poses, truth_at) < 0.02
    else:
        assert [c.kind for c in local.closures].count("join") == 0
        assert len(set(pieces.tolist())) == 3


@pytest.mark.usefixtures("as_matched")
@pytest.mark.parametrize(
    ("search_finds", "integrated"),
    [
        ((0.52, 0.01, np.pi / 2 + 0.02), True),  # the search confirms the tracked placement
        ((0.50, 0.00, 0.0), False),  # a likely rival a quarter turn away: neither alone
    ],
)
def test_a_tracked_placement_far_from_the_prediction_needs_the_search_to_agree(
    monkeypatch,  # type: ignore[no-untyped-def]
    search_finds: tuple[float, float, float],
    integrated: bool,
) -> None:
    # The prediction (0.5 m ahead) refined alone is not confident; refined with its rivals it
    # lands a quarter turn away at confidence 0.95 (a room that fits four ways). The search
    # with no guess against the last scan (placed where the keyframe is) either confirms it
    # or finds a likely rival; then neither settles alone and, with no other reference to
    # corroborate one, the scan is not integrated.
    tracked = (0.5, 0.0, np.pi / 2)
    searched: list[bool] = []

    def fake(reference, new, config, heuristics=(), extra_hypotheses=None, views=None, judged=None):  # type: ignore[no-untyped-def]
        searched.append(bool(heuristics))
        if heuristics:
            pose, confidence = search_finds, 0.9
        elif len(extra_hypotheses) == 1:
            pose, confidence = (0.5, 0.0, 0.0), 0.3  # the prediction alone
        else:
            pose, confidence = tracked, 0.95
        return _match(pose, confidence, judged)

    monkeypatch.setattr(attempts, "integrate", fake)
    chosen, placed, _ = _track_half_a_metre_ahead()
    assert placed == integrated
    assert searched == [False, False, True]  # the prediction, with its rivals, the search
    if integrated:
        assert chosen.stage == "track"
        np.testing.assert_allclose(chosen.pose, tracked)


@pytest.mark.usefixtures("as_matched")
@pytest.mark.parametrize(
    ("refined_to", "confidence", "matches"),
    [
        ((0.55, 0.05, 0.02), 0.95, 1),  # 0.07 m, 1.1 deg from the prediction: settled alone
        ((0.75, 0.05, 0.06), 0.95, 2),  # 0.25 m, 3.4 deg: the rivals, which do not move it
        ((0.85, 0.0, 0.0), 0.95, 3),  # 0.35 m: the rivals, then the search
        ((0.5, 0.0, 0.1), 0.95, 3),  # 5.7 deg: the rivals, then the search
        ((0.85, 0.0, 0.0), 0.9999, 2),  # 0.35 m but sure (attempts.SURE): no search
        ((0.75, 0.05, 0.06), 0.9999, 1),  # 0.25 m, 3.4 deg and sure: settled alone
    ],
)
def test_a_confident_track_within_the_tolerance_of_its_prediction_needs_no_search(
    monkeypatch,  # type: ignore[no-untyped-def]
    refined_to: tuple[float, float, float],
    confidence: float,
    matches: int,
) -> None:
    # The prediction (0.5 m ahead), refined alone and with its rivals, lands at
    # ``refined_to`` with ``confidence``. Within a third of the correctness tolerance it
    # settles alone, and when sure within all of it; within the tolerance (0.30 m, 5 deg) the
    # rivals are tried and, when they do not move it, the motion model and the match agree
    # and no search is made; beyond it the search with no guess (which confirms it here) is
    # made too, unless the track is sure.
    calls: list[bool] = []

    def fake(reference, new, config, heuristics=(), extra_hypotheses=None, views=None, judged=None):  # type: ignore[no-untyped-def]
        calls.append(bool(heuristics))
        return _match(refined_to, confidence, judged)

    monkeypatch.setattr(attempts, "integrate", fake)
    chosen, placed, tracked = _track_half_a_metre_ahead()
    assert placed and tracked and chosen.stage == "track"
    np.testing.assert_allclose(chosen.pose, refined_to)
    assert len(calls) == matches
    assert calls[-1] == (matches == 3)  # the last one the search, when made


@pytest.mark.usefixtures("as_matched")
def test_a_rival_moves_a_confident_track_that_stayed_near_a_wrong_prediction(
    monkeypatch,  # type: ignore[no-untyped-def]
) -> None:
    # aces: the robot started to turn between two scans; the prediction refined alone stays
    # 3.4 deg from it, confident (0.81), but 17 deg from the truth. Its rivals (turned copies)
    # find the truth, which the search confirms: that placement is kept.
    truth = (0.5, 0.0, 0.3)
    calls: list[bool] = []

    def fake(reference, new, config, heuristics=(), extra_hypotheses=None, views=None, judged=None):  # type: ignore[no-untyped-def]
        calls.append(bool(heuristics))
        if len(extra_hypotheses) == 1:
            return _match((0.5, 0.0, 0.06), 0.81, judged)  # the prediction alone
        return _match(truth, 0.95, judged)  # with the rivals, and the search

    monkeypatch.setattr(attempts, "integrate", fake)
    chosen, placed, _ = _track_half_a_metre_ahead()
    assert placed
    np.testing.assert_allclose(chosen.pose, truth)
    assert calls == [False, False, True]


@pytest.mark.parametrize("turn", [0.3, 0.15])
def test_a_turn_that_started_between_scans_is_found_by_the_rivals(
    monkeypatch,  # type: ignore[no-untyped-def]
    turn: float,
) -> None:
    # The robot drove straight, then turned 9-17 deg between two scans: the constant-velocity
    # prediction (straight on) is far off in angle. With the real INTEGRATE, the prediction
    # refined alone lands beyond the tolerance (its confidence is not even computed), and the
    # rivals pass (the prediction and its turned copies) places the scan within centimetres.
    rng = np.random.default_rng(7)
    walls = WORLDS["office"]()
    laser = LaserModel(beams=361, range_noise=0.01)
    start, truth = (6.0, 3.0, 0.0), (0.4, 0.05, turn)
    scans = [simulate_scan(walls, pose, laser, rng) for pose in (start, se2.compose(start, truth))]
    first, second = (extract_scan(scan, EXTRACTION)[0].segments for scan in scans)
    confidences: list[tuple[int, float]] = []

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        result = integrate(*args, **kwargs)
        confidences.append((len(kwargs["extra_hypotheses"]), result.confidence))
        return result

    monkeypatch.setattr(attempts, "integrate", counted)
    chosen, placed, tracked = attempts.match_scan(
        LocalMapperConfig(),
        _only_the_last_scan(first, scans[0]),
        second,
        scans[1],
        [(0.4, 0.0, 0.0), (0.0, 0.0, 0.0)],
        True,
        lambda *_: None,
    )
    # the prediction alone (not judged), then with its rivals (confident)
    assert [count for count, _ in confidences] == [1, 13]
    assert confidences[0][1] == 0.0 and confidences[1][1] > 0.99
    assert placed and tracked
    error = se2.between(truth, chosen.pose)
    assert np.hypot(error[0], error[1]) < 0.05 and abs(error[2]) < np.radians(1.0)


def test_a_cluttered_office_is_tracked_within_centimetres() -> None:
    # Chairs, tables, pillars and people walking to and fro: a third of the returns or more
    # fall in clusters too small for a segment. The drive is still tracked.
    clutter = clutter_for("office", 0.15, seed=2)
    run = simulate_robots("office", 1, LaserModel(), seed=2, duration=4.0, clutter=clutter)[0]
    segments = [extract_scan(s, EXTRACTION)[0] for s in run.scans[:5]]
    assert all(s.dropped_points > 20 for s in segments)
    mapper = LocalMapper()
    for t, s, true_pose in zip(run.stamps, run.scans, run.T_world_laser, strict=True):
        update = _feed(mapper, float(t), s)
        assert update.accepted and update.piece == 0
        assert update.pose is not None
        expected = _relative(run.T_world_laser[0], true_pose)
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
    stamps, scans, truth = _looped_drive(rate=4.0, laps=0.5, seed=4)
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
        float(t): np.asarray(_relative(truth[0], p)) for t, p in zip(stamps, truth, strict=True)
    }
    assert _ate(times, poses, truth_at) < 0.02


def test_closures_of_one_new_keyframe_are_not_each_others_partner() -> None:
    # Pairwise consistency needs independent matches: the new keyframe's window matched to
    # two neighbouring old keyframes is one scan's evidence twice (a look-alike place fools
    # both alike), so neither is the other's partner, however well they agree.
    local = LocalMapper()
    closure = loop_closer.Closure(10, 50, (1.0, 0.0, 0.0), 0.99, "loop", True, "", found_by=50)
    neighbour = dataclasses.replace(closure, first=11, T_first_second=(0.5, 0.0, 0.0))
    assert local.backend.closer._pairwise(closure, neighbour) is None
    assert local.backend.closer._pairwise(neighbour, closure) is None


def test_two_closures_agree_in_heading_within_the_drift_of_their_cycle(
    office_drive,  # type: ignore[no-untyped-def]
) -> None:
    # Two closures between neighbouring keyframes, consistent with the graph; then one of them
    # turned. Just inside the correctness tolerance they still agree; beyond it by 0.1 deg per
    # metre of the cycle's path (about twice the local maps' heading drift) they do not:
    # metres of path must not buy radians one for one.
    stamps, scans, _ = office_drive
    local = _mapped(stamps, scans)
    keyframes = local.backend.closer.keyframes
    last = len(keyframes.scans) - 1
    assert last >= 3

    def closure(first: int, second: int, turn: float) -> loop_closer.Closure:
        x, y, theta = se2.between(keyframes.pose(first), keyframes.pose(second))
        return loop_closer.Closure(
            first, second, (x, y, theta + turn), 0.99, "loop", True, "", found_by=second
        )

    other = closure(1, last - 1, 0.0)
    path = float(
        np.hypot(*se2.between(keyframes.pose(0), keyframes.pose(1))[:2])
        + np.hypot(*se2.between(keyframes.pose(last - 1), keyframes.pose(last))[:2])
    )
    assert path > 0.5
    inside = RIGHT_ANGLE - np.radians(0.5)
    beyond = RIGHT_ANGLE + np.radians(0.1 * path)
    assert local.backend.closer._pairwise(closure(0, last, inside), other) is True
    assert local.backend.closer._pairwise(closure(0, last, beyond), other) is False


@pytest.mark.usefixtures("as_matched")
@pytest.mark.parametrize(("placed_at", "integrated"), [(1.5, True), (6.0, False)])
def test_a_lost_robot_is_put_back_only_where_it_can_have_driven(
    monkeypatch,  # type: ignore[no-untyped-def]
    placed_at: float,
    integrated: bool,
) -> None:
    # The robot got lost 7 s ago in piece 0, at its origin; it never drove faster than
    # 0.3 m/s, so it is within 0.3 * 7 + 0.30 = 2.4 m of there. Two likely matches against
    # two keyframes of piece 0 agree on one placement: 1.5 m away they put it back; 6 m away
    # they are a look-alike place (agreeing as well as two right ones) and the robot stays
    # lost in its own piece, its guess the best placement it can have driven to.
    scan = _stranger()
    segments, _ = extract_scan(scan, EXTRACTION)
    own, first, second = (segments.segments.copy() for _ in range(3))

    def fake(reference, new, config, heuristics=(), extra_hypotheses=None, views=None, judged=None):  # type: ignore[no-untyped-def]
        if reference is first:
            pose, confidence = (placed_at, 0.0, 0.0), 0.7  # keyframe 0 at the origin
        elif reference is second:
            pose, confidence = (placed_at - 1.0, 0.0, 0.0), 0.6  # keyframe 2, 1 m along x
        else:
            pose, confidence = (0.0, 0.0, 0.0), 0.2  # the last scan: no idea
        return _match(pose, confidence, judged)

    monkeypatch.setattr(attempts, "integrate", fake)
    references = attempts.References(
        here=(0.0, 0.0, 0.0),
        last=attempts.Reference(own, scan, attempts.Anchor(1, (0.0, 0.0, 0.0)), 0.0),
        keyframe=1,
        older=[2, 0],
        poses={0: (0.0, 0.0, 0.0), 1: (0.0, 0.0, 0.0), 2: (1.0, 0.0, 0.0)},
        pieces={0: 0, 1: 1, 2: 0},
        scans={
            k: keyframe_map.KeyframeScan(k, 0.0, s, scan)
            for k, s in ((0, first), (1, own), (2, second))
        },
        left={0: ((0.0, 0.0, 0.0), 7.0)},
        top_speed=0.3,
    )
    chosen, placed, _ = attempts.match_scan(
        LocalMapperConfig(), references, own, scan, [(0.0, 0.0, 0.0)], False, lambda *_: None
    )
    assert placed == integrated
    if integrated:
        assert chosen.piece == 0
        np.testing.assert_allclose(chosen.pose, (placed_at, 0.0, 0.0))
    else:
        # Nor is the look-alike the guess the new piece is joined from.
        assert chosen.piece == 1


@pytest.mark.usefixtures("as_matched")
@pytest.mark.parametrize(("second_confidence", "kept"), [(0.9, "second"), (0.1, "first")])
def test_a_search_that_is_not_confident_is_searched_again_with_the_shapes(
    monkeypatch,  # type: ignore[no-untyped-def]
    second_confidence: float,
    kept: str,
) -> None:
    # The search with no guess is not confident (0.3): it is searched again with the shape
    # matching's placements as more hypotheses, and that second result is kept only when it
    # is more confident.
    scan = _stranger()
    segments, _ = extract_scan(scan, EXTRACTION)
    calls: list[int] = []

    def fake(reference, new, config, heuristics=(), extra_hypotheses=None, views=None, judged=None):  # type: ignore[no-untyped-def]
        calls.append(len(extra_hypotheses))
        if len(calls) == 1:
            pose, confidence = (0.2, 0.0, 0.0), 0.3
        else:
            pose, confidence = (0.5, 0.1, 0.0), second_confidence
        return _match(pose, confidence, judged)

    monkeypatch.setattr(attempts, "integrate", fake)
    references = _only_the_last_scan(segments.segments, scan)
    stages: list[str] = []
    chosen, placed, _ = attempts.match_scan(
        LocalMapperConfig(),
        references,
        segments.segments,
        scan,
        [(0.0, 0.0, 0.0)],
        False,
        lambda stage, _: stages.append(stage),
        attempts.Shapes(LocalMapperConfig().shape),
    )
    assert len(calls) == 2 and calls[1] > calls[0]  # the shape placements came in
    assert "shape" in stages
    assert placed == (kept == "second")
    expected = (0.5, 0.1, 0.0) if kept == "second" else (0.2, 0.0, 0.0)
    np.testing.assert_allclose(chosen.pose, expected)


@pytest.mark.parametrize("context", attempts.CONTEXTS)
def test_a_context_shifts_the_odds_by_its_prior(monkeypatch, context: str) -> None:  # type: ignore[no-untyped-def]
    # Bayes' rule: a context whose matches are right four times as often at the same evidence
    # multiplies the odds by 4 (intercept log 4, slope 1); no shift keeps the confidence.
    monkeypatch.setattr(context_model, "CALIBRATION", {context: (1.0, float(np.log(4.0)))})
    assert attempts.in_context(0.5, context) == pytest.approx(0.8)
    assert attempts.in_context(0.2, context) == pytest.approx(0.5)  # odds 1/4 -> 1
    monkeypatch.setattr(context_model, "CALIBRATION", {context: (1.0, 0.0)})
    for p in (0.01, 0.3, 0.77, 0.999):
        assert attempts.in_context(p, context) == pytest.approx(p)


@given(
    st.sampled_from(attempts.CONTEXTS),
    st.floats(0.0, 1.0),
    st.floats(0.0, 1.0),
)
def test_more_evidence_never_means_less_confidence_in_any_context(
    context: str, p: float, q: float
) -> None:
    # The fitted calibration is monotone (a positive slope in every context), and a
    # probability stays one.
    low, high = sorted((p, q))
    assert context_model.CALIBRATION[context][0] > 0.0
    assert 0.0 <= attempts.in_context(low, context) <= attempts.in_context(high, context) <= 1.0


@pytest.mark.parametrize(("search_prior", "integrated"), [(4.0, True), (1.0, False)])
def test_the_front_end_decides_on_the_confidence_in_context(
    monkeypatch,  # type: ignore[no-untyped-def]
    search_prior: float,
    integrated: bool,
) -> None:
    # A search against the last scan finds a placement at match confidence 0.6. Where such
    # matches are right four times as often (odds x 4: 0.857 >= integrate_confidence 0.8) the
    # scan is integrated; with the confidence as matched it is not, and the robot is lost.
    shift = {"search": float(np.log(search_prior))}
    calibration = {c: (1.0, shift.get(c, 0.0)) for c in attempts.CONTEXTS}
    monkeypatch.setattr(context_model, "CALIBRATION", calibration)
    monkeypatch.setattr(attempts, "integrate", lambda *a, **k: _match((0.4, 0.0, 0.0), 0.6))
    scan = _stranger()
    segments, _ = extract_scan(scan, EXTRACTION)
    record: list[attempts.Attempt] = []
    chosen, placed, _ = attempts.match_scan(
        LocalMapperConfig(),
        _only_the_last_scan(segments.segments, scan),
        segments.segments,
        scan,
        [(0.0, 0.0, 0.0)],
        False,
        lambda *_: None,
        record=record,
    )
    assert placed == integrated
    assert chosen.context == "search" and chosen.result.confidence == 0.6
    assert chosen.confidence == pytest.approx(0.6 * search_prior / (0.4 + 0.6 * search_prior))
    assert chosen in record


def test_a_closure_edge_is_the_windows_placement_between_the_members_that_see_most(
    office_drive,  # type: ignore[no-untyped-def]
    monkeypatch,  # type: ignore[no-untyped-def]
) -> None:
    # Two keyframes' windows agree on a placement; the closure's edge keeps it as it is (the
    # two scans alone refined it to worse placements on the shared logs), expressed between
    # one member of each window through their poses in the windows: the pair whose own scans
    # constrain it most, with the information of their walls.
    stamps, scans, _ = office_drive
    local = _mapped(stamps, scans)
    closer = local.backend.closer
    pose = closer.keyframes.pose
    last = len(closer.keyframes.scans) - 1
    first_window, last_window = closer._window_members(0), closer._window_members(last)
    assert not set(first_window.tolist()) & set(last_window.tolist())

    def no_match(*args: object, **kwargs: object) -> None:
        raise AssertionError("the closure edge must not match the scans again")

    monkeypatch.setattr(closer, "_match", no_match)
    # The windows' placement as the graph has it: every member pair's edge is then the graph's
    # own relative pose of the two members.
    placement = se2.between(pose(0), pose(last))
    edge = closer._scan_edge(0, last, placement)
    assert edge.first in first_window and edge.second in last_window
    np.testing.assert_allclose(
        edge.T_first_second, se2.between(pose(edge.first), pose(edge.second)), atol=1e-9
    )
    assert edge.robust
    volume = np.linalg.slogdet(edge.information)[1]
    for i in first_window.tolist():
        for j in last_window.tolist():
            T_i_j = attempts.hypotheses_of([se2.between(pose(i), pose(j))])[0]
            other = closer._edge(i, j, T_i_j, robust=True)
            assert np.linalg.slogdet(other.information)[1] <= volume + 1e-9
    # Walls of both scans overlap there: tighter than the ceiling of an unconstrained edge
    # (10 m, 1 rad), in every direction; 40 m away nothing overlaps.
    assert np.all(np.linalg.eigvalsh(edge.information) > 1.0)
    apart = closer._scan_edge(0, last, (placement[0] + 40.0, placement[1], placement[2]))
    assert np.linalg.eigvalsh(apart.information).min() < np.linalg.eigvalsh(edge.information).min()


@pytest.mark.parametrize(
    ("matched", "in_context", "corroborated"),
    [
        (0.6, 0.6, True),  # each more likely right than wrong by its own evidence
        (0.3, 0.7, False),  # only by the context's prior: shared, so it counts once
    ],
)
def test_two_matches_corroborate_each_other_by_their_own_evidence(
    matched: float, in_context: float, corroborated: bool
) -> None:
    # Two matches of one scan against two reference scans agree on its placement. They
    # corroborate each other when each is likely right by its own evidence; their context's
    # prior (the same for both: one scan, one situation) must not be counted in each.
    def attempt(keyframe: int, pose: tuple[float, float, float]) -> attempts.Attempt:
        return attempts.Attempt(
            _match(pose, matched),
            attempts.Anchor(keyframe, (0.0, 0.0, 0.0)),
            np.zeros((0, 4)),
            pose,
            0,
            "recent",
            "recent",
            in_context,
            0.0,
        )

    pair = [attempt(0, (1.0, 0.0, 0.0)), attempt(2, (1.05, 0.02, 0.01))]
    assert (attempts.corroborated(pair) is not None) == corroborated
