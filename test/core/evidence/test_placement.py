"""The evidence model of place matches (issue 46) with known answers: buildings that fit two
ways are never placed, one wall that tells them apart is enough, and what is published says
how sure it is. The models themselves: `test_model.py`.

Buildings are drawn here by hand so that their symmetry is exact: a corridor with equal rooms
either side that a half turn about its middle maps onto itself, and a row of equal rooms.
Keyframes are made as a robot's ``partial_map`` carries them (test_joint's
``keyframes_along``), each robot's map frame anywhere (``random_frames``).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from test_joint import drives, keyframes_along, moved, stranger_keyframes
from test_link_graph import random_frames

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.correlation import CorrelationConfig, Drawing
from multi_robot_mapper.core.evidence.model import (
    FEATURES,
    installed_model,
    join_features,
)
from multi_robot_mapper.core.evidence.placement import placement_evidence
from multi_robot_mapper.core.logistic import LogisticModel
from multi_robot_mapper.core.merging import MergeConfig, MergeResult
from multi_robot_mapper.core.merging.joint import merge_joint
from multi_robot_mapper.core.simulation import drive_path
from multi_robot_mapper.core.worlds import polygon

CONFIG = MergeConfig()
WIDTH = 2.4  # m, the corridor
ROOM = 5.0  # m, each room's width along the corridor
DEPTH = 5.0  # m, each room's depth
DOOR = 1.0  # m


def corridor_of_rooms(rooms: int = 8, offset_door: float = 0.0) -> np.ndarray:
    """A corridor along x (0..rooms*ROOM, 0..WIDTH) with ``rooms`` equal rooms either side,
    each with a door in the middle: a half turn about the corridor's middle maps it onto
    itself. ``offset_door`` moves the door of the third room on the north side along the
    corridor (the one feature that tells the two ends apart)."""
    walls = []
    length = rooms * ROOM
    for y0, y1 in ((WIDTH, WIDTH + DEPTH), (0.0, -DEPTH)):
        for k in range(rooms):
            start = k * ROOM
            door = start + 0.5 * (ROOM - DOOR) + (offset_door if (y0 > 0 and k == 2) else 0.0)
            walls.append(polygon([(start, y0), (door, y0)], closed=False))
            walls.append(polygon([(door + DOOR, y0), (start + ROOM, y0)], closed=False))
            walls.append(polygon([(start, y0), (start, y1)], closed=False))
        walls.append(polygon([(length, y0), (length, y1)], closed=False))
        walls.append(polygon([(0.0, y1), (length, y1)], closed=False))
    walls.append(polygon([(0.0, 0.0), (0.0, WIDTH)], closed=False))
    walls.append(polygon([(length, 0.0), (length, WIDTH)], closed=False))
    return np.vstack(walls)


def drive(walls: np.ndarray, route: list[tuple[float, float]], seed: int) -> list:  # type: ignore[type-arg]
    """Keyframes along ``route`` (a keyframe every 0.8 m, world frame)."""
    waypoints = np.array(route, dtype=np.float64)
    length = float(np.hypot(*np.diff(waypoints, axis=0).T).sum())
    poses = drive_path(waypoints, 0.8, 1.0, length / 0.8 * 0.99)
    return keyframes_along(walls, poses, seed)


@functools.cache
def corridor_drives(offset_door: float) -> tuple[list, list]:  # type: ignore[type-arg]
    """Robot a drives the whole corridor; robot b its western third and into a room."""
    walls = corridor_of_rooms(offset_door=offset_door)
    middle = 0.5 * WIDTH
    a = drive(walls, [(1.0, middle), (39.0, middle)], seed=1)
    b = drive(walls, [(4.0, middle), (17.5, middle), (17.5, 4.5)], seed=2)
    return a, b


def merge_two(a: list, b: list, seed: int) -> tuple[MergeResult, dict[str, np.ndarray]]:  # type: ignore[type-arg]
    frames = dict(zip(("a", "b"), random_frames(2, seed), strict=True))
    keyframes = {"a": moved(a, frames["a"]), "b": moved(b, frames["b"])}
    return merge_joint(keyframes, CONFIG, budget=0.0), frames


def placement_error(result: MergeResult, frames: dict[str, np.ndarray], robot: str) -> float:
    """Metres between where the merge put the robot's map frame and the truth."""
    assert result.reference is not None
    truth = se2.invert(frames[result.reference]) @ frames[robot]
    placed = result.matrix(robot)
    assert placed is not None
    return float(np.hypot(*se2.pose_from_matrix(se2.invert(truth) @ placed)[:2]))


def test_a_corridor_that_a_half_turn_maps_onto_itself_gives_no_margin() -> None:
    # The exact half turn about the corridor's middle puts every wall of b's stretch on a
    # wall: as much wall as the truth explains, so no margin either way.
    walls = corridor_of_rooms()
    drawing = Drawing.of(walls, np.zeros((0, 2)), CONFIG.correlation_cell)
    west = Drawing.of(walls[walls[:, [0, 2]].max(axis=1) < 15.0], np.zeros((0, 2)), 0.3)
    evidence = placement_evidence(drawing, west, np.eye(3), CorrelationConfig(cell=0.3))
    assert evidence.score > 40.0  # b's walls all lie on a's
    assert evidence.rival > 0.9 * evidence.score  # and as well turned half round
    assert abs(evidence.rival_placement[0]) == pytest.approx(np.pi, abs=np.radians(2.0))  # type: ignore[index]
    assert evidence.margin < 0.1 * evidence.score


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_symmetric_corridor_is_never_merged_turned_round(seed: int) -> None:
    a, b = corridor_drives(0.0)
    result, _ = merge_two(a, b, seed)
    # It cannot be told which end b drove: placing it is a guess, so it is not placed.
    assert result.placements["b"] is None or result.placements["a"] is None
    unmerged = result.unmerged[0]
    assert result.unmerged_reasons[unmerged]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_door_that_tells_the_ends_apart_is_enough_to_merge(seed: int) -> None:
    a, b = corridor_drives(1.5)
    result, frames = merge_two(a, b, seed)
    # Placed right, or not at all: never turned round.
    for robot in ("a", "b"):
        if result.placements[robot] is not None:
            assert placement_error(result, frames, robot) < 0.10
    if not result.unmerged:
        assert min(result.probabilities.values()) >= CONFIG.join_probability


def test_a_corridor_slid_by_one_room_is_a_rival_the_margin_sees() -> None:
    # The corridor's rooms repeat every ROOM metres: a stretch of it from the middle, slid by
    # one room along the corridor, puts every wall on a wall. The correlation's peaks along a
    # corridor form a ridge; the slide along the weakest direction finds the rival.
    walls = corridor_of_rooms()
    drawing = Drawing.of(walls, np.zeros((0, 2)), 0.3)
    middle = walls[(walls[:, [0, 2]].min(axis=1) >= 15.0) & (walls[:, [0, 2]].max(axis=1) <= 25.0)]
    middle = middle[np.abs(middle[:, 1] - middle[:, 3]) < 1e-9]  # its walls along the corridor
    patch = Drawing.of(middle, np.zeros((0, 2)), 0.3)
    evidence = placement_evidence(drawing, patch, np.eye(3), CorrelationConfig(cell=0.3))
    assert evidence.rival_placement is not None
    shift = float(np.hypot(*evidence.rival_placement[1:]))
    assert abs(float(evidence.rival_placement[0])) < np.radians(2.0)
    assert shift > 1.0 and abs(shift / ROOM - round(shift / ROOM)) < 0.1, evidence.rival_placement
    assert evidence.margin < 0.1 * evidence.score
    assert installed_model().probability(join_features([evidence])) < 0.5


def test_a_wall_drawn_twice_is_matched_once() -> None:
    # A target that holds its walls twice reads two metres per metre: a patch matches at
    # most the metres of wall it has.
    walls = corridor_of_rooms(rooms=3)
    once = Drawing.of(walls, np.zeros((0, 2)), 0.3)
    beside = walls + np.array([0.05, 0.0, 0.05, 0.0])
    twice = Drawing.of(np.vstack((walls, beside)), np.zeros((0, 2)), 0.3)
    config = CorrelationConfig(cell=0.3)
    single = placement_evidence(once, once, np.eye(3), config)
    double = placement_evidence(twice, once, np.eye(3), config)
    assert single.score <= once.weight.sum() + 1e-6
    assert double.matched <= once.weight.sum() + 1e-6
    assert double.matched == pytest.approx(single.matched, rel=0.05)


def test_equal_rooms_seen_one_each_are_not_merged() -> None:
    # a looks into the third room from the north door, b into the sixth: the rooms are
    # equal, and what else each saw of the corridor is equal too. Nothing tells them apart.
    walls = corridor_of_rooms()
    middle = 0.5 * WIDTH
    a = drive(walls, [(10.0, middle), (12.5, middle), (12.5, 4.5), (12.5, middle)], seed=3)
    b = drive(walls, [(25.0, middle), (27.5, middle), (27.5, 4.5), (27.5, middle)], seed=4)
    for seed in range(3):
        result, _ = merge_two(a, b, seed)
        assert result.unmerged, "equal rooms placed on each other"


def test_what_is_published_carries_its_probability() -> None:
    a, b = corridor_drives(1.5)
    result, _ = merge_two(a, b, 0)
    for robot, pose in result.placements.items():
        if pose is None:
            assert robot in result.unmerged_reasons
        elif robot != result.reference:
            assert CONFIG.join_probability <= result.probabilities[robot] <= 1.0


def test_a_wrong_join_does_not_move_the_reference() -> None:
    # A model that believes every placement joins a robot of another building to the office
    # robots through whatever its places matched (a wrong join). The reference robot's map is
    # still where its own keyframes put it, and the office robot joined to it still at the
    # truth: a join moves the map it places, never the reference (the joint graph anchors the
    # reference, and a link between two maps that nothing else ties bends neither).
    _, office = drives("office", 3)
    world = {"r1": office[0], "r2": office[1], "stranger": stranger_keyframes()}
    names = sorted(world)
    frames = dict(zip(names, random_frames(len(names), seed=5), strict=True))
    keyframes = {name: moved(world[name], frames[name]) for name in names}
    believing = LogisticModel(FEATURES, 20.0, (0.0,) * len(FEATURES), "believes everything")
    result = merge_joint(keyframes, CONFIG, budget=0.0, model=believing)
    assert result.placements["stranger"] is not None  # joined, wrongly
    reference = result.reference
    assert reference is not None
    own = np.array([kf.T_robotmap_keyframe for kf in keyframes[reference]])
    placed = result.keyframe_poses[reference]
    assert np.hypot(*(placed[:, :2] - own[:, :2]).T).max() < 0.01
    other = "r2" if reference == "r1" else "r1"
    if reference != "stranger":
        assert placement_error(result, frames, other) < 0.10
