"""The joint merger (issue 13) with known answers: robots' keyframes in one graph.

Keyframes are built the way a robot's ``partial_map`` carries them: simulated scans at the true
laser poses along a route, fused, each fused segment owned by the keyframe whose scan brought
it and stored in that keyframe's frame; each robot's keyframe poses are then expressed in a map
frame at a random pose, so every true ``T_map_robotmap`` (and every keyframe's true pose in
``map``) is known. The link-level rules (pairwise consistency, cycles) are checked on links
made by hand from known poses.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_merging import LASER, SIMULATED_WORLD_JOIN_PROBABILITY, random_frames, stranger_walls

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.model import FEATURES
from multi_robot_mapper.core.evidence.placement import PlacementEvidence
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.logistic import LogisticModel
from multi_robot_mapper.core.matching import IntegrateConfig
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.merging import MergeConfig, MergeResult
from multi_robot_mapper.core.merging.consistency import (
    PairVerdict,
    accept_pairs,
    consistent_set,
    placement_weights,
    seen_through_near,
)
from multi_robot_mapper.core.merging.free_space import MapViews
from multi_robot_mapper.core.merging.joint import merge_joint
from multi_robot_mapper.core.merging.motion import motion_excess, robot_reaches
from multi_robot_mapper.core.merging.pair_evidence import PairEvidence
from multi_robot_mapper.core.merging.place_links import LinkCandidate
from multi_robot_mapper.core.merging.places import MapUnit, units_of
from multi_robot_mapper.core.pipeline import TimedLaserScan, run_offline
from multi_robot_mapper.core.simulation import (
    LaserModel,
    drive_path,
    plan_paths,
    simulate_robots,
    simulate_scan,
)
from multi_robot_mapper.core.worlds import ROUTES, WORLDS

CONFIG = MergeConfig(join_probability=SIMULATED_WORLD_JOIN_PROBABILITY)
DISTANCE = 40.0  # m driven per robot
TOLERANCE_M, TOLERANCE_RAD = 0.10, np.radians(1.0)


def keyframes_along(walls: np.ndarray, poses: np.ndarray, seed: int) -> list[Keyframe]:
    """Keyframes at ``poses`` (world frame; a robot whose map frame is the world): each pose's
    scan fused into the map, each fused segment owned by one keyframe, in its frame."""
    rng = np.random.default_rng(seed)
    segments, owner = np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
    for k, pose in enumerate(poses):
        data = simulate_scan(walls, (pose[0], pose[1], pose[2]), LASER, rng)
        found = extract_scan(data, ExtractionConfig())[0].segments
        placed = se2.transform_segments(se2.matrix_from_pose(*pose), found)
        own = np.full(len(placed), k, dtype=np.int64)
        segments, owner = fuse(
            segments, owner, placed, own, pair_tolerance(IntegrateConfig()), 0.02
        )
    return [
        Keyframe(
            k,
            float(k),
            np.asarray(pose, dtype=np.float64),
            se2.transform_segments(se2.invert(se2.matrix_from_pose(*pose)), segments[owner == k]),
        )
        for k, pose in enumerate(poses)
    ]


def moved(keyframes: list[Keyframe], T_world_robotmap: np.ndarray) -> list[Keyframe]:
    """The keyframes with their poses in a map frame at ``T_world_robotmap``."""
    T = se2.invert(T_world_robotmap)
    return [
        Keyframe(
            kf.index,
            kf.stamp,
            np.array(se2.pose_from_matrix(T @ se2.matrix_from_pose(*kf.T_robotmap_keyframe))),
            kf.segments,
        )
        for kf in keyframes
    ]


@functools.cache
def drives(world: str, robots: int) -> tuple[tuple[np.ndarray, ...], tuple[list[Keyframe], ...]]:
    """(laser poses, keyframes), world frame, of robots driving overlapping stretches of the
    world's route (neighbours share 30 % of their stretch), a keyframe every 0.8 m."""
    paths = plan_paths(ROUTES[world], robots, DISTANCE, overlap=0.3)
    poses = tuple(drive_path(w, 0.8, 1.0, DISTANCE / 0.8) for w in paths)
    walls = WORLDS[world]()
    return poses, tuple(keyframes_along(walls, p, seed=k) for k, p in enumerate(poses))


@functools.cache
def stranger_keyframes() -> list[Keyframe]:
    """Keyframes of a drive through another building (test_merging's ``stranger_walls``)."""
    route = np.array([(2.5, 5.5), (5.0, 6.5), (8.0, 5.0), (11.0, 3.5)])
    return keyframes_along(stranger_walls(), drive_path(route, 0.8, 1.0, 12.0), seed=7)


def assert_at_truth(
    result: MergeResult, frames: dict[str, np.ndarray], world: dict[str, list[Keyframe]]
) -> None:
    """Every robot of ``frames`` placed where the truth puts it, relative to the reference;
    every one of its merged keyframes too (``world``: its keyframes in the world frame)."""
    assert result.reference is not None
    T_world_map = frames[result.reference]
    for name, T_world_robot in frames.items():
        got = result.placements[name]
        assert got is not None, name
        want = se2.pose_from_matrix(se2.invert(T_world_map) @ T_world_robot)
        assert np.hypot(got[0] - want[0], got[1] - want[1]) < TOLERANCE_M, (name, got, want)
        assert abs(float(se2.wrap_angle(got[2] - want[2]))) < TOLERANCE_RAD, name
        truth = np.array(
            [
                se2.pose_from_matrix(
                    se2.invert(T_world_map) @ se2.matrix_from_pose(*kf.T_robotmap_keyframe)
                )
                for kf in world[name]
            ]
        )
        index = result.keyframe_index[name]
        assert index.tolist() == [kf.index for kf in world[name]]
        poses = result.keyframe_poses[name]
        assert np.hypot(*(poses[:, :2] - truth[:, :2]).T).max() < 2 * TOLERANCE_M, name


def merged(
    world: dict[str, list[Keyframe]], seed: int, **settings: object
) -> tuple[MergeResult, dict[str, np.ndarray]]:
    """The robots' keyframes (world frame) moved into map frames anywhere and merged (every
    place matched); their true ``T_world_robotmap``."""
    settings.setdefault("join_probability", SIMULATED_WORLD_JOIN_PROBABILITY)
    names = sorted(world)
    frames = dict(zip(names, random_frames(len(names), seed=seed), strict=True))
    keyframes = {name: moved(world[name], frames[name]) for name in names}
    return merge_joint(keyframes, MergeConfig(**settings), budget=0.0), frames  # type: ignore[arg-type]


# --- End to end on simulated worlds --------------------------------------------------------


def test_a_robot_whose_map_never_overlaps_stays_unmerged() -> None:
    _, office = drives("office", 3)
    world = {"r1": office[0], "r2": office[1], "r3": office[2], "stranger": stranger_keyframes()}
    result, frames = merged(world, seed=2)
    assert result.placements["stranger"] is None
    assert result.unmerged == ["stranger"]
    assert "stranger" not in result.keyframe_poses
    assert not any("stranger" in (link.robot_a, link.robot_b) for link in result.links)
    assert 3 not in set(result.segment_robot.tolist())  # its segments are not in the map
    office_frames = {name: frames[name] for name in ("r1", "r2", "r3")}
    assert_at_truth(result, office_frames, world)
    assert result.stats["maps_merged"] == 3 and result.stats["matches_pending"] == 0


def test_a_look_alike_building_is_refused() -> None:
    # The corridors world is drawn on the office's grid of right angles: its places fit
    # office places (some with a confident link), but no two of them agree on one placement.
    _, office = drives("office", 3)
    _, corridors = drives("corridors", 2)
    world = {"r1": office[0], "r2": office[1], "r3": office[2], "lookalike": corridors[1]}
    result, frames = merged(world, seed=4)
    assert result.unmerged == ["lookalike"]
    refused = [v for pair, v in result.verdicts.items() if "lookalike" in {k[0] for k in pair}]  # type: ignore[union-attr]
    assert refused and not any(v.accepted for v in refused)  # type: ignore[attr-defined]
    assert any(v.links for v in refused)  # type: ignore[attr-defined]  # it did fit somewhere
    assert_at_truth(result, {n: frames[n] for n in ("r1", "r2", "r3")}, world)


def test_a_corridor_is_merged_through_a_consistent_set_of_links() -> None:
    _, corridors = drives("corridors", 2)
    world = {"a": corridors[0], "b": corridors[1]}
    result, frames = merged(world, seed=6)
    assert result.unmerged == []
    assert_at_truth(result, frames, world)
    (verdict,) = [v for v in result.verdicts.values() if v.accepted]  # type: ignore[attr-defined]
    assert verdict.places >= CONFIG.link_confident_support
    # Every accepted link is right: its two keyframes are where the truth puts them.
    for link in verdict.links:
        source = world[link.source[0]][link.centre].T_robotmap_keyframe
        target = world[link.target[0]][link.keyframe].T_robotmap_keyframe
        want = se2.between(target, source)
        got = link.T_keyframe_centre
        assert np.hypot(got[0] - want[0], got[1] - want[1]) < 0.3
        assert abs(float(se2.wrap_angle(got[2] - want[2]))) < np.radians(5.0)
    # The next update with nothing changed matches nothing again and places the same.
    keyframes = {n: moved(world[n], frames[n]) for n in world}
    again = merge_joint(keyframes, CONFIG, previous=result, budget=0.0)
    assert again.stats["matches_computed"] == 0
    for name in world:
        np.testing.assert_allclose(again.placements[name], result.placements[name], atol=1e-6)  # type: ignore[arg-type]


def test_what_an_update_keeps_from_the_last_never_changes_its_result() -> None:
    # The merger keeps the last update's pair verdicts, graph solution and fusion and reuses
    # them where their inputs are the same. Merging other maps in between, then the first
    # maps again (with and without the previous result), gives what a merge from nothing gave;
    # a map that changed gets a new verdict and graph.
    _, corridors = drives("corridors", 2)
    world = {"a": corridors[0], "b": corridors[1]}
    frames = dict(zip(world, random_frames(2, seed=6), strict=True))
    keyframes = {n: moved(world[n], frames[n]) for n in world}
    first = merge_joint(keyframes, CONFIG, budget=0.0)
    assert first.unmerged == []
    shorter = {"a": keyframes["a"], "b": keyframes["b"][:-3]}
    other = merge_joint(shorter, CONFIG, budget=0.0)
    for previous in (None, first, other):
        again = merge_joint(keyframes, CONFIG, previous=previous, budget=0.0)
        for name in world:
            np.testing.assert_allclose(again.keyframe_poses[name], first.keyframe_poses[name])
        np.testing.assert_allclose(again.segments, first.segments)
    assert len(other.keyframe_poses["b"]) == len(keyframes["b"]) - 3


def test_an_update_takes_about_its_budget_in_all() -> None:
    from multi_robot_mapper.core.merging.joint import JointState, _matching_budget

    # The rest of the last update that changed a map took 0.3 s: matching gets the remainder.
    last = JointState(rest_s=0.3)
    assert _matching_budget(1.0, last) == pytest.approx(0.7)
    assert _matching_budget(1.0, None) == 1.0  # the first update: nothing known of the rest
    assert 0.0 < _matching_budget(0.2, last) < 1e-3  # one match (match_places makes one)
    assert _matching_budget(0.0, last) == 0.0 and _matching_budget(None, last) is None
    # An update with nothing new keeps the estimate of the last one that changed a map.
    _, corridors = drives("corridors", 2)
    world = {"a": corridors[0], "b": corridors[1]}
    frames = dict(zip(world, random_frames(2, seed=6), strict=True))
    keyframes = {n: moved(world[n], frames[n]) for n in world}
    first = merge_joint(keyframes, CONFIG, budget=0.0)
    assert isinstance(first.state, JointState)
    assert first.state.rest_s == pytest.approx(
        first.timings["total_s"] - first.timings["matching_s"], abs=1e-3
    )
    again = merge_joint(keyframes, CONFIG, previous=first, budget=0.0)
    assert isinstance(again.state, JointState) and again.state.rest_s == first.state.rest_s


def test_robots_whose_overlap_ends_one_map_and_starts_the_next_are_merged() -> None:
    # `make demo`'s scenario (three robots in the office, neighbours sharing 45 % of their
    # stretches) mapped by the local mapper with 60 % of the scans lost, as in transit on a
    # busy machine. robot1's places at the end of its stretch reach past robot2's map and fit
    # a corridor robot2 mapped whole better than the right placement (ranked 5th-15th), while
    # robot2's first places lie inside robot1's map and find it first. Searching only the
    # smaller map's places (robot1's) left robot1 unmerged; each map's places are searched.
    runs = simulate_robots("office", 3, LaserModel(), seed=0, duration=20.0, overlap=0.45)
    rng = np.random.default_rng(1)
    scans, frames = {}, {}
    for k, run in enumerate(runs):
        kept = np.flatnonzero(rng.random(len(run.scans)) > 0.6)
        scans[f"robot{k + 1}"] = [TimedLaserScan(run.stamps[i], run.scans[i]) for i in kept]
        frames[f"robot{k + 1}"] = se2.matrix_from_pose(*run.T_world_laser[kept[0]])
    local = run_offline(scans, "local", ExtractionConfig())
    result = merge_joint(local.keyframes, CONFIG, budget=0.0)
    assert result.unmerged == []
    assert result.reference is not None
    T_map_world = se2.invert(frames[result.reference])
    for name, T_world_robot in frames.items():
        want = se2.pose_from_matrix(T_map_world @ T_world_robot)
        got = result.placements[name]
        assert got is not None
        assert np.hypot(got[0] - want[0], got[1] - want[1]) < TOLERANCE_M, (name, got, want)
        assert abs(float(se2.wrap_angle(got[2] - want[2]))) < TOLERANCE_RAD, name


def test_a_time_budget_leaves_places_for_the_next_update() -> None:
    _, corridors = drives("corridors", 2)
    world = {"a": corridors[0], "b": corridors[1]}
    frames = dict(zip(world, random_frames(2, seed=6), strict=True))
    keyframes = {n: moved(world[n], frames[n]) for n in world}
    first = merge_joint(keyframes, CONFIG, budget=1e-9)  # one place match, then out of time
    assert first.stats["matches_computed"] == 1 and first.stats["matches_pending"] > 0
    result = first
    for _ in range(first.stats["matches_pending"] + 1):
        if result.stats["matches_pending"] == 0:
            break
        result = merge_joint(keyframes, CONFIG, previous=result, budget=1e-9)
    assert result.stats["matches_pending"] == 0
    everything = merge_joint(keyframes, CONFIG, budget=0.0)
    for name in world:
        np.testing.assert_allclose(result.placements[name], everything.placements[name], atol=1e-3)  # type: ignore[arg-type]


# --- Links made by hand from known poses -----------------------------------------------------


def line_units(names: list[str], frames: list[np.ndarray]) -> dict[str, list[Keyframe]]:
    """Robots driving the same straight corridor (world x axis, keyframes every metre),
    each robot's keyframe poses in its map frame at ``frames[i]`` (T_world_robotmap)."""
    wall = np.array([[-0.5, 1.0, 0.5, 1.0], [-0.5, -1.0, 0.5, -1.0]])
    world = [Keyframe(k, float(k), np.array([float(k), 0.0, 0.0]), wall) for k in range(20)]
    return {name: moved(world, T) for name, T in zip(names, frames, strict=True)}


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


def certain(probability: float = 0.999) -> LogisticModel:
    """A join model that gives every placement ``probability`` (its evidence aside): the
    tests of sets, cycles and motion below are about links, not the evidence model
    (test_evidence.py)."""
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
    # model's, test_evidence.py).
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
    views = {key: MapViews.of(u.segments, u.poses, CONFIG) for key, u in units.items()}

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
    views = {key: MapViews.of(u.segments, u.poses, CONFIG) for key, u in units.items()}
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
