"""The joint graph (core/merging/joint_graph.py): a map's keyframes joined by edges from their
published poses (consecutive ones, and earlier ones within the radius), the reference map's
frame kept exactly, and the last solution reused while its graph is the same."""

from __future__ import annotations

import dataclasses
from collections import OrderedDict

import numpy as np

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging.consistency import Accepted
from multi_robot_mapper.core.merging.joint_graph import graph_model, solved
from multi_robot_mapper.core.merging.joint_graph_config import JointGraphConfig
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey, units_of

WALL = np.array([[0.0, 1.0, 1.0, 1.0]])
POSES = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.1], [2.0, 0.0, 0.2], [3.0, 0.0, 0.3]])
STEP = np.array([0.0, 0.5, 0.0])


def one_map(poses: np.ndarray = POSES) -> tuple[dict[UnitKey, MapUnit], UnitKey, Accepted]:
    units = units_of({"a": [Keyframe(k, float(k), p, WALL) for k, p in enumerate(poses)]})
    key = ("a", 0)
    return units, key, Accepted([], [], [[key]], {key: []})


def test_the_reference_alone_keeps_its_published_poses_and_its_frame() -> None:
    units, key, accepted = one_map()
    model = graph_model(dataclasses.replace(JointGraphConfig(), radius=2.5))
    _, solution = solved(units, [key], key, accepted, model, None, OrderedDict())
    np.testing.assert_allclose(solution.poses[key], POSES, atol=1e-9)
    np.testing.assert_allclose(solution.frames[key], np.eye(3))
    assert solution.order == [key] and solution.accepted == [] and solution.iterations == 0
    # Edges: the three consecutive pairs, and keyframes 0-2 and 1-3 (2 m apart, within 2.5 m;
    # 0-3, 3 m apart, is not).
    assert (solution.nodes, solution.edges) == (4, 5)
    model = graph_model(dataclasses.replace(JointGraphConfig(), radius=0.0))
    assert solved(units, [key], key, accepted, model, None, OrderedDict())[1].edges == 3


def test_the_last_solution_is_reused_only_while_the_graph_is_the_same() -> None:
    units, key, accepted = one_map()
    model = graph_model(JointGraphConfig())
    last = solved(units, [key], key, accepted, model, None, OrderedDict())
    assert solved(units, [key], key, accepted, model, last, OrderedDict()) is last
    moved, _, _ = one_map(POSES + STEP)  # the map changed: solved again
    again = solved(moved, [key], key, accepted, model, last, OrderedDict())
    assert again is not last and again[0] != last[0]
    np.testing.assert_allclose(again[1].poses[key], POSES + STEP, atol=1e-9)


def test_no_reference_no_solution() -> None:
    units, key, accepted = one_map()
    model = graph_model(JointGraphConfig())
    _, solution = solved(units, [key], None, accepted, model, None, OrderedDict())
    assert (solution.poses, solution.frames, solution.order) == ({}, {}, [])
