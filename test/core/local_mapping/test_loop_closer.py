"""Odometry-free local mapping, the back end: loop closures that straighten a biased map, their
edges, and the heading across a loss. A lost robot's pieces joined again: `test_joins.py`."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from local_mapping_drives import (
    ate,
    biased_integrate,
    feed,
    looped_drive,
    mapped,
)

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping import (
    LocalMapper,
    LocalMapperConfig,
    LocalUpdate,
    attempts,
    loop_closer,
    mapper,
    windows,
)
from multi_robot_mapper.core.local_mapping import joins as piece_joins
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE

# The simulated office repeats its rooms: the join model (calibrated on generated buildings,
# issue 46) gives the right joins of these short drives' pieces P 0.98 (36-54 m of wall, no
# rival within the robot's reach), below the default 0.99. These tests are about pieces,
# losses and bounds, so their joins are made at 0.9 (test_model.py tests the model).
PIECES = dataclasses.replace(LocalMapperConfig(), join_probability=0.9)


def test_a_heading_bias_is_straightened_by_loop_closures(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # Every match the front end accepts turns 1 degree per metre of motion too far: the map
    # bends by tens of degrees over a lap. Driving the office round twice, the back end (its
    # local edges and loop closures, matched without the bias) pulls it straight again.
    stamps, scans, truth = looped_drive(rate=4.0, laps=2.0, seed=3)

    monkeypatch.setattr(attempts, "integrate", biased_integrate)
    local = mapped(stamps, scans)
    assert local.pieces_started == 0
    assert len(local.closures) >= 5  # 9 at 0.99 in the office, whose rooms repeat
    times, poses = local.trajectory()
    truth_at = {
        float(t): np.asarray(se2.between(truth[0], p)) for t, p in zip(stamps, truth, strict=True)
    }
    assert ate(times, poses, truth_at) < 0.05
    # Without the back end's edges the same bias bends the map by metres.
    monkeypatch.setattr(windows, "integrate", biased_integrate)
    unclosed = LocalMapper(
        dataclasses.replace(LocalMapperConfig(), loop_candidates=0, local_edges=0)
    )
    for t, s in zip(stamps, scans, strict=True):
        feed(unclosed, float(t), s)
    assert ate(*unclosed.trajectory(), truth_at) > 0.5


def _mapped_losing_the_robot_at(
    monkeypatch: pytest.MonkeyPatch,
    stamps: np.ndarray,
    scans: list,
    lost_at: set[int],
    config: LocalMapperConfig = PIECES,
) -> tuple[LocalMapper, list[LocalUpdate]]:
    """The scans mapped by a LocalMapper whose front end fails on the scans ``lost_at`` (a
    match not confident enough: each starts a new piece from its best match's guess)."""
    original = mapper.LocalMapper._match
    count = {"scan": 0}

    def failing(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        chosen, integrated = original(self, *args, **kwargs)
        return chosen, integrated and count["scan"] not in lost_at

    monkeypatch.setattr(mapper.LocalMapper, "_match", failing)
    # Each failing scan is a loss at once (not held for the next scan to confirm it).
    local = LocalMapper(dataclasses.replace(config, lost_confirm_scans=1))
    updates = []
    for k, (t, s) in enumerate(zip(stamps, scans, strict=True)):
        count["scan"] = k
        updates.append(feed(local, float(t), s))
    return local, updates


def _ate_of_one_map(local: LocalMapper, stamps: np.ndarray, truth: np.ndarray) -> float:
    """Every scan in the map's one piece: its ATE against the truth (m)."""
    assert set(local.backend.map.pieces.tolist()) == {0}
    times, poses = local.trajectory()
    np.testing.assert_array_equal(times, stamps)
    truth_at = {
        float(t): np.asarray(se2.between(truth[0], p)) for t, p in zip(stamps, truth, strict=True)
    }
    return ate(times, poses, truth_at)


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
    stamps, scans, truth = looped_drive(rate=4.0, laps=1.2, seed=3)

    monkeypatch.setattr(attempts, "integrate", biased_integrate)
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
    stamps, scans, truth = looped_drive(rate=4.0, laps=1.2, seed=3)
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
    stamps, scans, truth = looped_drive(rate=4.0, laps=0.5, seed=4)
    local, _ = _mapped_losing_the_robot_at(monkeypatch, stamps, scans, {25})
    closer = local.backend.closer
    assert [c.kind for c in local.closures].count("join") == 1
    assert closer.headings == []
    assert closer.refused["loss spanned by its join (heading)"] == 1
    assert _ate_of_one_map(local, stamps, truth) < 0.02


def test_closures_of_one_new_keyframe_are_not_each_others_partner() -> None:
    # Pairwise consistency needs independent matches: the new keyframe's window matched to
    # two neighbouring old keyframes is one scan's evidence twice (a look-alike place fools
    # both alike), so neither is the other's partner, however well they agree.
    local = LocalMapper(PIECES)
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
    local = mapped(stamps, scans)
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
