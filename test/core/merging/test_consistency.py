"""The link-level rules of the joint merger with known answers, on links made by hand from known
poses: the consistent set of a pair, rival placements, walls in the other robot's free space,
cycles, and the motion between a robot's pieces (merging/motion.py: test_motion.py is local
mapping's)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_joint import CONFIG, moved

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.model import FEATURES
from multi_robot_mapper.core.evidence.placement import PlacementEvidence
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.logistic import LogisticModel
from multi_robot_mapper.core.merging.consistency import (
    PairVerdict,
    accept_pairs,
    consistent_set,
    placement_weights,
    seen_through_near,
)
from multi_robot_mapper.core.merging.free_space import MapViews
from multi_robot_mapper.core.merging.motion import motion_excess, robot_reaches
from multi_robot_mapper.core.merging.pair_evidence import PairEvidence
from multi_robot_mapper.core.merging.place_links import LinkCandidate
from multi_robot_mapper.core.merging.places import MapUnit, units_of


def link(
    units: dict[tuple[str, int], MapUnit],
    frames: dict[str, np.ndarray],
    source: str,
    centre: int,
    target: str,
    keyframe: int,
    confidence: float,
    error: tuple[float, float, float] = (0.0, 0.0, 0.0),
    rank: int = 0,
) -> LinkCandidate:
    """The link of ``source``'s keyframe ``centre`` to ``target``'s keyframe ``keyframe`` as
    the truth has it, then moved by ``error`` (x, y, theta in the target keyframe's frame)."""
    T_world_centre = frames[source] @ se2.matrix_from_pose(*units[(source, 0)].poses[centre])
    T_world_keyframe = frames[target] @ se2.matrix_from_pose(*units[(target, 0)].poses[keyframe])
    T = se2.matrix_from_pose(*error) @ se2.invert(T_world_keyframe) @ T_world_centre
    T_target_centre = se2.matrix_from_pose(*units[(target, 0)].poses[keyframe]) @ T
    return LinkCandidate(
        source=(source, 0),
        centre=centre,
        target=(target, 0),
        keyframe=keyframe,
        T_keyframe_centre=se2.pose_from_matrix(T),
        T_target_centre=se2.pose_from_matrix(T_target_centre),
        confidence=confidence,
        fit=0.95,
        value=20.0,
        rank=rank,
        information=np.diag([400.0, 400.0, 1e4]),
    )


def line_units(names: list[str], frames: list[np.ndarray]) -> dict[str, list[Keyframe]]:
    """Robots driving the same straight corridor (world x axis, keyframes every metre),
    each robot's keyframe poses in its map frame at ``frames[i]`` (T_world_robotmap)."""
    wall = np.array([[-0.5, 1.0, 0.5, 1.0], [-0.5, -1.0, 0.5, -1.0]])
    world = [Keyframe(k, float(k), np.array([float(k), 0.0, 0.0]), wall) for k in range(20)]
    return {name: moved(world, T) for name, T in zip(names, frames, strict=True)}


def certain(probability: float = 0.999) -> LogisticModel:
    """A join model that gives every placement ``probability`` (its evidence aside): the
    tests of sets, cycles and motion below are about links, not the evidence model
    (test_model.py)."""
    return LogisticModel(
        FEATURES, float(np.log(probability / (1.0 - probability))), (0.0,) * len(FEATURES), ""
    )


def weighed(
    pair: tuple[tuple[str, int], tuple[str, int]],
    links: Sequence[LinkCandidate],
    units: dict[tuple[str, int], MapUnit],
    seen_through: Callable[[Sequence[LinkCandidate]], tuple[float, float]] | None = None,
) -> PairVerdict:
    """The pair's consistent set, weighed by :func:`certain`."""
    plain = PlacementEvidence(50.0, 0.0, 50.0, np.zeros(3), None)
    return consistent_set(
        pair,
        links,
        units,
        CONFIG,
        seen_through or (lambda _: (0.0, 0.0)),
        lambda *_: PairEvidence(plain, plain),
        certain(),
    )


def test_the_consistent_set_is_the_placement_several_places_agree_on() -> None:
    # A corridor: each place of b fits a's corridor at its true place and at another (each
    # placement unsure, confidence 0.4-0.45). The true placements agree with each other; the
    # rivals agree with nothing (each is off by another amount along the corridor): the
    # pair's hypothesis is the true placements (whether to believe it is the evidence
    # model's, test_model.py).
    frames = {"a": se2.matrix_from_pose(0.0, 0.0, 0.0), "b": se2.matrix_from_pose(3.0, 0.5, 0.2)}
    units = units_of(line_units(["a", "b"], [frames["a"], frames["b"]]))
    right = [link(units, frames, "b", k, "a", k + 3, 0.45) for k in (2, 7, 12)]
    rivals = [
        link(units, frames, "b", k, "a", k + 3, 0.4, (shift, 0.0, 0.0), rank=1)
        for k, shift in ((2, 4.0), (7, -6.0), (12, 9.0))
    ]
    verdict = weighed((("a", 0), ("b", 0)), right + rivals, units)
    assert verdict.accepted, verdict.reason
    assert sorted(c.centre for c in verdict.links) == [2, 7, 12]
    assert all(c.rank == 0 for c in verdict.links)
    assert verdict.probability == pytest.approx(0.999)


def test_a_places_own_rival_placements_do_not_veto_it() -> None:
    # What the office's node test met: three places of b link confidently at the truth (1.0,
    # 0.99, 0.97); each place's own rival lies 6 m along the corridor (0.2, 0.68, 0.74), and
    # the rivals agree with each other. Each confidence was judged against the other
    # placement of the same place, so the rivals are the same ambiguity counted again: by
    # raw confidences 2.96 against 1.62 (ambiguous within the factor 2); weighed as exclusive
    # placements of one place each, 2.9 against 0.1: accepted, with the right links.
    frames = {"a": se2.matrix_from_pose(0.0, 0.0, 0.0), "b": se2.matrix_from_pose(3.0, 0.5, 0.2)}
    units = units_of(line_units(["a", "b"], [frames["a"], frames["b"]]))
    right = [
        link(units, frames, "b", k, "a", k + 3, c) for k, c in ((2, 1.0), (7, 0.99), (12, 0.97))
    ]
    rivals = [
        link(units, frames, "b", k, "a", k + 3, c, (6.0, 0.0, 0.0), rank=1)
        for k, c in ((2, 0.2), (7, 0.68), (12, 0.74))
    ]
    verdict = weighed((("a", 0), ("b", 0)), right + rivals, units)
    assert verdict.accepted, verdict.reason
    assert sorted((c.centre, c.rank) for c in verdict.links) == [(2, 0), (7, 0), (12, 0)]
    assert verdict.weight > 2.8 and verdict.rival_weight < 0.2
    # A lone candidate weighs its confidence; two of one place share one probability.
    weights = placement_weights(right[:1] + rivals[1:2] + right[1:2])
    np.testing.assert_allclose(weights[0], 1.0, atol=1e-5)
    np.testing.assert_allclose(weights[1:].sum(), (99 + 2.125) / (1 + 99 + 2.125))


def test_a_placement_that_puts_walls_in_the_other_robots_free_space_is_measured() -> None:
    # Three mutually consistent links that turn b's corridor a quarter round across a's (a
    # look-alike that fits a few places): b's walls stand where a's laser saw through its
    # corridor, and a's where b's did. The right placement leaves none there. The metres
    # are a feature of the join model (its conflict).
    frames = {"a": se2.matrix_from_pose(0.0, 0.0, 0.0), "b": se2.matrix_from_pose(3.0, 0.0, 0.0)}
    units = units_of(line_units(["a", "b"], [frames["a"], frames["b"]]))
    views = {key: MapViews.of(u.segments, u.poses, CONFIG.view_fan()) for key, u in units.items()}

    def seen_through(links: Sequence[LinkCandidate]) -> tuple[float, float]:
        return seen_through_near(links, units, views.get, CONFIG)

    pair = (("a", 0), ("b", 0))
    right = [link(units, frames, "b", k, "a", k + 3, 0.95) for k in (2, 7, 12)]
    verdict = weighed(pair, right, units, seen_through)
    assert verdict.seen_through == (0.0, 0.0) and verdict.conflict == 0.0
    across = {"a": frames["a"], "b": se2.matrix_from_pose(10.0, -10.0, np.pi / 2)}
    wrong = [link(units, across, "b", k, "a", 10, 0.95) for k in (8, 10, 12)]
    verdict = weighed(pair, wrong, units, seen_through)
    assert verdict.seen_through[0] > CONFIG.link_max_seen_through
    assert verdict.conflict >= verdict.seen_through[1] > 0.0


def test_a_map_that_bends_between_its_places_keeps_its_walls_out_of_free_space() -> None:
    # b's map bends 0.1 rad at its keyframe 10 (its own drift): four right links, two places
    # each side of the bend. As rigid bodies at one link the maps cross each other's corridor
    # beyond the bend (3.3 m of wall in free space); each wall placed by its nearest link,
    # none. A look-alike's links agree on one placement: both readings are the same for it.
    frames = {"a": se2.matrix_from_pose(0.0, 0.0, 0.0), "b": se2.matrix_from_pose(3.0, 0.0, 0.0)}
    truth = units_of(line_units(["a", "b"], [frames["a"], frames["b"]]))
    keyframes = line_units(["a", "b"], [frames["a"], frames["b"]])
    pivot = se2.matrix_from_pose(*keyframes["b"][10].T_robotmap_keyframe)
    T_bend = pivot @ se2.matrix_from_pose(0.0, 0.0, 0.1) @ se2.invert(pivot)
    keyframes["b"] = [
        kf
        if kf.index <= 10
        else dataclasses.replace(
            kf,
            T_robotmap_keyframe=np.array(
                se2.pose_from_matrix(T_bend @ se2.matrix_from_pose(*kf.T_robotmap_keyframe))
            ),
        )
        for kf in keyframes["b"]
    ]
    units = units_of(keyframes)
    views = {key: MapViews.of(u.segments, u.poses, CONFIG.view_fan()) for key, u in units.items()}
    right = [link(truth, frames, "b", k, "a", k + 3, 0.97) for k in (2, 6, 12, 15)]
    verdict = weighed(
        (("a", 0), ("b", 0)),
        right,
        units,
        lambda links: seen_through_near(links, units, views.get, CONFIG),
    )
    assert len(verdict.links) == 4
    near, whole = verdict.seen_through
    assert near == 0.0
    assert whole > CONFIG.link_max_seen_through  # the rigid reading: walls across the corridor


def test_a_link_that_breaks_a_cycle_is_refused() -> None:
    # Three robots in one corridor, each pair linked by a consistent set of two places. a-b
    # and b-c are right; a-c is 2 m off (consistent in itself: both its links are off alike)
    # and lighter, so it comes last and closes a cycle that does not close.
    names = ["a", "b", "c"]
    poses = [(0.0, 0.0, 0.0), (2.0, 0.3, 0.1), (4.0, -0.2, -0.1)]
    frames = {n: se2.matrix_from_pose(*p) for n, p in zip(names, poses, strict=True)}
    units = units_of(line_units(names, [frames[n] for n in names]))

    def verdict(source: str, target: str, weight: float, error: float) -> PairVerdict:
        links = [
            link(units, frames, source, k, target, k + 1, weight / 2, (error, 0.0, 0.0))
            for k in (3, 9)
        ]
        pair = ((target, 0), (source, 0))
        return weighed(pair, links, units)

    ab, bc = verdict("b", "a", 1.9, 0.0), verdict("c", "b", 1.9, 0.0)
    wrong = dataclasses.replace(verdict("c", "a", 1.8, 2.0), probability=0.995)
    assert ab.accepted and bc.accepted and wrong.accepted  # each pair alone believes its set
    accepted = accept_pairs([ab, bc, wrong], units, CONFIG, certain())
    assert [v.pair for v in accepted.pairs] == [ab.pair, bc.pair]
    assert [v.pair for v in accepted.refused] == [wrong.pair]
    assert accepted.refused[0].reason == "breaks a cycle"
    assert accepted.groups == [[("a", 0), ("b", 0), ("c", 0)]]
    # The right a-c link closes the cycle and is taken.
    right = verdict("c", "a", 1.8, 0.0)
    closed = accept_pairs([ab, bc, right], units, CONFIG, certain())
    assert len(closed.pairs) == 3 and closed.refused == []


# --- Motion between a robot's pieces ---------------------------------------------------------


def lost_once() -> tuple[dict[tuple[str, int], MapUnit], dict[tuple[str, int], np.ndarray]]:
    """Robot ``a`` drove the corridor of :func:`line_units` at 1 m/s and was lost once: its
    keyframes 0-9 are its map, 10-19 a second piece (its own frame at a random pose), the
    first of them one second after the last of the map. ``b`` drove the whole corridor. The
    units and each unit's frame in the world."""
    wall = np.array([[-0.5, 1.0, 0.5, 1.0], [-0.5, -1.0, 0.5, -1.0]])
    frames = {
        ("a", 0): se2.matrix_from_pose(0.0, 0.0, 0.0),
        ("a", 10): se2.matrix_from_pose(7.0, 4.0, 2.5),
        ("b", 0): se2.matrix_from_pose(3.0, 0.5, 0.2),
    }
    keyframes: dict[str, list[Keyframe]] = {"a": [], "b": []}
    for k in range(20):
        T_world_keyframe = se2.matrix_from_pose(float(k), 0.0, 0.0)
        for key in [("a", 0 if k < 10 else 10), ("b", 0)]:
            pose = se2.pose_from_matrix(se2.invert(frames[key]) @ T_world_keyframe)
            keyframes[key[0]].append(Keyframe(k, float(k), np.array(pose), wall, key[1]))
    return units_of(keyframes), frames


def piece_link(
    units: dict[tuple[str, int], MapUnit],
    frames: dict[tuple[str, int], np.ndarray],
    source: tuple[str, int],
    centre: int,
    target: tuple[str, int],
    keyframe: int,
    shift: float = 0.0,
) -> LinkCandidate:
    """:func:`link` between any two units, confident, moved ``shift`` m along the corridor."""
    pose_of = {key: dict(zip(u.index.tolist(), u.poses, strict=True)) for key, u in units.items()}
    T_world_centre = frames[source] @ se2.matrix_from_pose(*pose_of[source][centre])
    T_target_keyframe = se2.matrix_from_pose(*pose_of[target][keyframe])
    T_world_keyframe = frames[target] @ T_target_keyframe
    T = se2.matrix_from_pose(shift, 0.0, 0.0) @ se2.invert(T_world_keyframe) @ T_world_centre
    return LinkCandidate(
        source=source,
        centre=centre,
        target=target,
        keyframe=keyframe,
        T_keyframe_centre=se2.pose_from_matrix(T),
        T_target_centre=se2.pose_from_matrix(T_target_keyframe @ T),
        confidence=0.95,
        fit=0.95,
        value=20.0,
        rank=0,
        information=np.diag([400.0, 400.0, 1e4]),
    )


def test_motion_bounds_how_far_apart_a_robots_pieces_can_be_placed() -> None:
    units, frames = lost_once()
    reaches = robot_reaches(units, max_speed=2.0)
    # Between keyframes of one piece the reach is the piece's own distance; across the loss
    # it is the speed bound: 9 m, then 2 m in the one second, then 9 m.
    np.testing.assert_allclose(reaches["a"].reach[[0, 9, 10, 19]], [0.0, 9.0, 11.0, 20.0])
    truth = {key: frames[key] for key in [("a", 0), ("a", 10)]}
    assert motion_excess(truth, units, reaches, slack=0.0) == 0.0
    # The second piece placed 8 m further along: keyframe 10 lies 9 m from keyframe 9,
    # 7 m beyond the 2 m the robot can have driven (and the 0.3 m tolerance).
    along = {**truth, ("a", 10): se2.matrix_from_pose(8.0, 0.0, 0.0) @ frames[("a", 10)]}
    assert motion_excess(along, units, reaches, slack=0.0) == pytest.approx(9.0 - 2.0 - 0.3)
    # Only keyframes of different pieces are judged, and a robot with one piece placed is free.
    assert motion_excess({("a", 10): np.eye(3)}, units, reaches, slack=0.0) == 0.0
    # A robot whose stamps do not increase (no clock) is bound by nothing between its pieces.
    for stamps in (np.zeros(20), np.r_[np.arange(10.0), np.nan, np.arange(11.0, 20.0)]):
        unclocked = {
            key: dataclasses.replace(u, stamps=stamps[u.index]) for key, u in units.items()
        }
        free = robot_reaches(unclocked, max_speed=2.0)
        assert np.isinf(free["a"].reach[-1])
        assert motion_excess(along, unclocked, free, slack=0.0) == 0.0


@settings(max_examples=25, deadline=None)
@given(
    x=st.floats(-100.0, 100.0),
    y=st.floats(-100.0, 100.0),
    theta=st.floats(-np.pi, np.pi),
    shift=st.floats(0.0, 20.0),
)
def test_motion_judges_placements_not_where_the_group_lies(
    x: float, y: float, theta: float, shift: float
) -> None:
    # The same placement of a's two pieces, the whole group moved rigidly anywhere: the same
    # excess (the bound is between the robot's keyframes, not in any frame).
    units, frames = lost_once()
    reaches = robot_reaches(units, max_speed=2.0)
    placed = {
        ("a", 0): frames[("a", 0)],
        ("a", 10): se2.matrix_from_pose(shift, 0.0, 0.0) @ frames[("a", 10)],
    }
    T = se2.matrix_from_pose(x, y, theta)
    moved = {key: T @ T_group_unit for key, T_group_unit in placed.items()}
    expected = max(0.0, abs(1.0 + shift) - 2.0 - 0.3)
    assert motion_excess(placed, units, reaches, 0.0) == pytest.approx(expected, abs=1e-9)
    assert motion_excess(moved, units, reaches, 0.0) == pytest.approx(expected, abs=1e-6)


def test_a_piece_placed_where_its_robot_cannot_have_driven_is_refused() -> None:
    # b's places link a's map at the truth (every keyframe of it: ten places), and a's
    # second piece 8 m along the corridor: a look-alike set, consistent in itself and
    # confident (three places). Placed so, a would have driven 9 m in the second between its
    # pieces: refused. Without motion (no reaches) both are taken; the right set for the
    # second piece is taken with motion.
    units, frames = lost_once()
    a0, a10, b = ("a", 0), ("a", 10), ("b", 0)

    def verdict(piece: tuple[str, int], keyframes: Sequence[int], shift: float) -> PairVerdict:
        links = [piece_link(units, frames, b, k, piece, k, shift) for k in keyframes]
        return weighed((piece, b), links, units)

    right = verdict(a0, range(10), 0.0)
    look_alike = verdict(a10, (11, 14, 17), 8.0)
    assert right.accepted and look_alike.accepted  # each pair alone believes its set
    reaches = robot_reaches(units, CONFIG.max_speed)
    model = certain()
    accepted = accept_pairs([right, look_alike], units, CONFIG, model, reaches)
    assert [v.pair for v in accepted.pairs] == [right.pair]
    assert [v.pair for v in accepted.refused] == [look_alike.pair]
    assert len(accept_pairs([right, look_alike], units, CONFIG, model).pairs) == 2
    both = accept_pairs([right, verdict(a10, (11, 14, 17), 0.0)], units, CONFIG, model, reaches)
    assert len(both.pairs) == 2 and both.refused == [] and both.groups == [[a0, a10, b]]
