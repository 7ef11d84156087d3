"""The front end's match attempts for one scan: tracking against its prediction, the search and
its rivals, corroboration, confidence in context, where the robot can have driven."""

from __future__ import annotations

import numpy as np
import pytest
from local_mapping_drives import (
    EXTRACTION,
    fake_match,
    stranger_scan,
)

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.local_mapping import (
    LocalMapperConfig,
    attempts,
    context,
    keyframe_map,
)
from multi_robot_mapper.core.matching import integrate
from multi_robot_mapper.core.matching.shape import Shapes
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import (
    LaserModel,
    simulate_scan,
)
from multi_robot_mapper.core.worlds import WORLDS


@pytest.fixture
def as_matched(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Every context keeps the match confidence as it is: a fake INTEGRATE's confidences are
    then the ones the front end decides on."""
    calibration = {c: attempts.ContextCalibration(1.0, 0.0) for c in attempts.CONTEXTS}
    monkeypatch.setattr(context, "installed_context_model", lambda: calibration)


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
    scan = stranger_scan()
    segments, _ = extract_scan(scan, EXTRACTION)
    references = _only_the_last_scan(segments.segments, scan)
    motions = [(0.5, 0.0, 0.0), (0.0, 0.0, 0.0)]
    return attempts.match_scan(
        LocalMapperConfig(), references, segments.segments, scan, motions, True, lambda *_: None
    )


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

    def fake(
        reference,
        new,
        config,
        heuristics=(),
        extra_hypotheses=None,
        views=None,
        judged=None,
        prior=None,
    ):  # type: ignore[no-untyped-def]
        searched.append(bool(heuristics))
        if heuristics:
            pose, confidence = search_finds, 0.9
        elif len(extra_hypotheses) == 1:
            pose, confidence = (0.5, 0.0, 0.0), 0.3  # the prediction alone
        else:
            pose, confidence = tracked, 0.95
        return fake_match(pose, confidence, judged)

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
        # Sure, but turned a quarter from the prediction (generated building 103): a
        # look-alike a room of right angles fits, the search confirms it or not.
        ((0.5, 0.0, np.pi / 2), 0.9999, 3),
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
    # made too, unless the track is sure and turned from the prediction no more than a turn
    # starting between two scans explains.
    calls: list[bool] = []

    def fake(
        reference,
        new,
        config,
        heuristics=(),
        extra_hypotheses=None,
        views=None,
        judged=None,
        prior=None,
    ):  # type: ignore[no-untyped-def]
        calls.append(bool(heuristics))
        return fake_match(refined_to, confidence, judged)

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

    def fake(
        reference,
        new,
        config,
        heuristics=(),
        extra_hypotheses=None,
        views=None,
        judged=None,
        prior=None,
    ):  # type: ignore[no-untyped-def]
        calls.append(bool(heuristics))
        if len(extra_hypotheses) == 1:
            return fake_match((0.5, 0.0, 0.06), 0.81, judged)  # the prediction alone
        return fake_match(truth, 0.95, judged)  # with the rivals, and the search

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


def _match_in_two_pieces(
    monkeypatch,  # type: ignore[no-untyped-def]
    matches: dict[int, tuple[tuple[float, float, float], float]],
    older: list[int],
    motion: tuple[float, float, float],
    left_seconds: float,
    top_speed: float,
    **timing: float,
) -> tuple[attempts.Attempt, bool, bool]:
    """:func:`attempts.match_scan` of a scan of a robot in piece 1 (keyframe 1, its last scan,
    and keyframe 3, both at the origin), beside piece 0 (keyframe 0 at the origin, keyframe 2
    1 m along x), which it left ``left_seconds`` ago at its origin; ``matches`` gives each
    keyframe's (placement, confidence) from a fake INTEGRATE."""
    scan = stranger_scan()
    segments, _ = extract_scan(scan, EXTRACTION)
    keyframes = {k: segments.segments.copy() for k in (0, 1, 2, 3)}

    def fake(
        reference,
        new,
        config,
        heuristics=(),
        extra_hypotheses=None,
        views=None,
        judged=None,
        prior=None,
    ):  # type: ignore[no-untyped-def]
        # The reference is the map of the last scan or of a keyframe's scan.
        last = references.last.segments
        found = (
            1
            if reference is last
            else next(k for k, s in references.scans.items() if s.segment_map is reference)
        )
        pose, confidence = matches[found]
        return fake_match(pose, confidence, judged)

    monkeypatch.setattr(attempts, "integrate", fake)
    origin = (0.0, 0.0, 0.0)
    references = attempts.References(
        here=origin,
        last=attempts.Reference(keyframes[1], scan, attempts.Anchor(1, origin), 0.0),
        keyframe=1,
        older=older,
        poses={0: origin, 1: origin, 2: (1.0, 0.0, 0.0), 3: origin},
        pieces={0: 0, 1: 1, 2: 0, 3: 1},
        scans={k: keyframe_map.KeyframeScan(k, 0.0, s, scan) for k, s in keyframes.items()},
        left={0: (origin, left_seconds)},
        top_speed=top_speed,
        **timing,
    )
    return attempts.match_scan(
        LocalMapperConfig(), references, keyframes[1], scan, [motion], False, lambda *_: None
    )


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
    matches = {
        0: ((placed_at, 0.0, 0.0), 0.7),  # keyframe 0 at the origin
        2: ((placed_at - 1.0, 0.0, 0.0), 0.6),  # keyframe 2, 1 m along x
        1: ((0.0, 0.0, 0.0), 0.2),  # the last scan: no idea
    }
    chosen, placed, _ = _match_in_two_pieces(
        monkeypatch, matches, [2, 0], (0.0, 0.0, 0.0), 7.0, 0.3
    )
    assert placed == integrated
    if integrated:
        assert chosen.piece == 0
        np.testing.assert_allclose(chosen.pose, (placed_at, 0.0, 0.0))
    else:
        # Nor is the look-alike the guess the new piece is joined from.
        assert chosen.piece == 1


@pytest.mark.usefixtures("as_matched")
@pytest.mark.parametrize(
    ("own_turn", "own_confidence", "integrated"),
    [(0.0, 0.2, True), (81.0, 0.99, False), (-7.0, 0.7, True)],
)
def test_a_scan_its_own_piece_matches_where_the_robot_cannot_be_is_not_put_in_another(
    monkeypatch,  # type: ignore[no-untyped-def]
    own_turn: float,
    own_confidence: float,
    integrated: bool,
) -> None:
    # Generated building 119 (a hall of pillars), robot1 scan 655: tracked at 0.999 the scan
    # before in its piece (here piece 1, at its origin), the robot's own last scan and
    # keyframes matched it at 0.96-0.998 turned 81 deg in 0.1 s (a right-angle look-alike the
    # turn bound refuses); two keyframes of the piece it had left 20 s before (piece 0) then
    # agreed at 0.998 and 0.997 on a placement 11.4 m and 90 deg from the truth, within the
    # 0.8 m/s x 20 s it can have driven since, and its map went on there turned 90 deg. A
    # scan that matched its own piece likely where the robot cannot be is not put in another
    # piece: it is not integrated (held). The same matches in another piece, when its own
    # piece does not know the scan (0.2) or matches it where the robot can be but not surely
    # (0.7: building 110's robot2 went back to the piece it had left, right, so), put it
    # back there as before.
    matches = {
        0: ((1.5, 0.0, np.pi / 2), 0.998),  # keyframe 0 at the origin
        2: ((0.5, 0.0, np.pi / 2), 0.997),  # keyframe 2, 1 m along x
        1: ((0.1, 0.0, float(np.radians(own_turn))), own_confidence),  # its own last scan
    }
    chosen, placed, _ = _match_in_two_pieces(
        monkeypatch, matches, [0, 2], (0.08, 0.0, -0.16), 20.0, 0.8, elapsed=0.1, period=0.1
    )
    assert placed == integrated
    if integrated:
        assert chosen.piece == 0
        np.testing.assert_allclose(chosen.pose, (1.5, 0.0, np.pi / 2))


@pytest.mark.usefixtures("as_matched")
@pytest.mark.parametrize(("home_confidence", "moved"), [(0.98, False), (0.7, True)])
def test_a_scan_its_own_piece_matches_more_surely_where_the_robot_can_be_stays_home(
    monkeypatch,  # type: ignore[no-untyped-def]
    home_confidence: float,
    moved: bool,
) -> None:
    # Generated building 119, robot3 scan 1019: an older keyframe of its own piece matched it
    # at 0.98 where the robot can be (right, but an older keyframe settles nothing alone); two
    # keyframes of another piece agreed at 0.93, 8.3 m and 90 deg off, and the robot moved
    # there. The piece that matches the scan less surely than the robot's own does not take
    # it; when its own matches less surely (building 110's robot2, 0.74, going back right to
    # the piece it had left), the move is made as before.
    matches = {
        0: ((1.5, 0.0, np.pi / 2), 0.93),  # keyframe 0 at the origin
        2: ((0.5, 0.0, np.pi / 2), 0.92),  # keyframe 2, 1 m along x
        3: ((0.08, 0.0, -0.1), home_confidence),  # keyframe 3, its own piece
        1: ((0.3, 2.0, 1.0), 0.2),  # its own last scan: no match
    }
    chosen, placed, _ = _match_in_two_pieces(
        monkeypatch, matches, [3, 0, 2], (0.08, 0.0, -0.1), 20.0, 0.8, elapsed=0.1, period=0.1
    )
    assert placed == moved
    assert chosen.piece == (0 if moved else 1)
    if moved:
        np.testing.assert_allclose(chosen.pose, (1.5, 0.0, np.pi / 2))


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
    scan = stranger_scan()
    segments, _ = extract_scan(scan, EXTRACTION)
    calls: list[int] = []

    def fake(
        reference,
        new,
        config,
        heuristics=(),
        extra_hypotheses=None,
        views=None,
        judged=None,
        prior=None,
    ):  # type: ignore[no-untyped-def]
        calls.append(len(extra_hypotheses))
        if len(calls) == 1:
            pose, confidence = (0.2, 0.0, 0.0), 0.3
        else:
            pose, confidence = (0.5, 0.1, 0.0), second_confidence
        return fake_match(pose, confidence, judged)

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
        Shapes(LocalMapperConfig().shape),
    )
    assert len(calls) == 2 and calls[1] > calls[0]  # the shape placements came in
    assert "shape" in stages
    assert placed == (kept == "second")
    expected = (0.5, 0.1, 0.0) if kept == "second" else (0.2, 0.0, 0.0)
    np.testing.assert_allclose(chosen.pose, expected)


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
    calibration = {
        c: attempts.ContextCalibration(1.0, shift.get(c, 0.0)) for c in attempts.CONTEXTS
    }
    monkeypatch.setattr(context, "installed_context_model", lambda: calibration)
    monkeypatch.setattr(attempts, "integrate", lambda *a, **k: fake_match((0.4, 0.0, 0.0), 0.6))
    scan = stranger_scan()
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
            fake_match(pose, matched),
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


def _placed_at(
    pose: tuple[float, float, float], elapsed: float, piece: int = 0, period: float | None = None
) -> bool:
    """Whether the front end finds ``pose`` reachable for a scan ``elapsed`` seconds after the
    last placed one, which lies at the origin of piece 0."""
    from multi_robot_mapper.core.local_mapping import attempts

    references = attempts.References(
        here=(0.0, 0.0, 0.0),
        last=None,  # type: ignore[arg-type]
        keyframe=0,
        older=[],
        poses={},
        pieces={0: 0},
        scans={},
        elapsed=elapsed,
        period=period,
    )
    matching = attempts._ScanMatching(
        LocalMapperConfig(),
        references,
        np.zeros((0, 4)),
        None,
        lambda *_: None,
        None,
        [],  # type: ignore[arg-type]
    )
    attempt = attempts.Attempt(None, None, None, pose, piece, "search", "search", 0.99, 0.0)  # type: ignore[arg-type]
    return matching.reachable(attempt)


def test_a_placement_turned_faster_than_a_robot_turns_is_not_reachable() -> None:
    # Generated building 111: in a U-turn at 18 deg a scan (10 Hz), a search placed a scan
    # -72 deg from the last, a right-angle look-alike; the next scan was then tracked turned
    # 180 deg and the robot's map with it. A full turn a second, plus the tolerance, bounds it.
    assert _placed_at((0.1, 0.0, np.radians(18.0)), 0.1)
    assert _placed_at((0.1, 0.0, np.radians(-40.0)), 0.1)  # 36 + 5 deg
    assert not _placed_at((0.1, 0.0, np.radians(-72.0)), 0.1)
    assert not _placed_at((0.0, 0.0, np.pi), 0.1)
    assert _placed_at((0.0, 0.0, np.pi), 0.6)  # a half turn in 0.6 s can be real
    # Where it was lost in another piece, the robot may have turned any way since.
    assert _placed_at((0.0, 0.0, np.pi), 0.1, piece=1)
    # Stamps 1 ms apart (a clock that repeated, moved on import) bound nothing less than the
    # robot's usual scan period: intel's corrected log, scans about 3 s apart.
    assert not _placed_at((0.1, 0.0, np.radians(30.0)), 0.001)
    assert _placed_at((0.1, 0.0, np.radians(30.0)), 0.001, period=3.0)
