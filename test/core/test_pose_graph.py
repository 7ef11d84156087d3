"""The pose graph's bounds (:class:`ReachBound`): known answers and their Jacobians."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from multi_robot_mapper.core.pose_graph import Edge, PoseGraph, ReachBound

coordinate = st.floats(-20.0, 20.0)
heading = st.floats(-np.pi, np.pi)
pose = st.tuples(coordinate, coordinate, heading)


def _retract(p: tuple[float, float, float], d: np.ndarray) -> tuple[float, float, float]:
    moved = gtsam.Pose2(*p).retract(d)
    return (moved.x(), moved.y(), moved.theta())


@given(pose, pose, st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)), st.floats(0.1, 5.0))
def test_a_bound_costs_the_distance_beyond_its_reach_with_exact_jacobians(
    first: tuple[float, float, float],
    second: tuple[float, float, float],
    point: tuple[float, float],
    reach: float,
) -> None:
    bound = ReachBound(0, 1, point, reach, 0.3)
    beyond, J_first, J_second = bound.error(first, second)
    c, s = np.cos(first[2]), np.sin(first[2])
    centre = np.array(
        [first[0] + c * point[0] - s * point[1], first[1] + s * point[0] + c * point[1]]
    )
    distance = float(np.hypot(second[0] - centre[0], second[1] - centre[1]))
    if abs(distance - reach) < 1e-3:
        return  # the wall's edge: no derivative there
    assert beyond == pytest.approx(max(distance - reach, 0.0), abs=1e-9)
    step = 1e-6
    for p, J, moving_first in ((first, J_first, True), (second, J_second, False)):
        numeric = []
        for d in np.eye(3) * step:
            ahead = (_retract(p, d), second) if moving_first else (first, _retract(p, d))
            behind = (_retract(p, -d), second) if moving_first else (first, _retract(p, -d))
            numeric.append((bound.error(*ahead)[0] - bound.error(*behind)[0]) / (2 * step))
        np.testing.assert_allclose(J[0], numeric, atol=1e-5)


def _chain(bound: ReachBound | None) -> PoseGraph:
    # Keyframe 0 anchored; 0 -> 1 measured 3 m ahead sharply, 1 -> 2 another 3 m loosely.
    graph = PoseGraph()
    graph.add_node(0, (0.0, 0.0, 0.0), anchored=True)
    graph.add_node(1, (3.0, 0.0, 0.0))
    graph.add_node(2, (6.0, 0.0, 0.0))
    sharp = np.diag([1e4, 1e4, 1e4])
    loose = np.diag([1.0, 1e4, 1e4])
    graph.add_edge(Edge(0, 1, (3.0, 0.0, 0.0), sharp, robust=False))
    graph.add_edge(Edge(1, 2, (3.0, 0.0, 0.0), loose, robust=False))
    if bound is not None:
        graph.add_bound(bound)
    graph.optimize(iterations=5)
    return graph


def test_a_bound_pulls_a_keyframe_back_within_reach_and_nothing_inside_it() -> None:
    # Keyframe 2 must lie within 4 m of keyframe 0's origin: the loose edge gives way, the
    # sharp one does not. A bound the keyframes already keep changes nothing.
    free = _chain(None)
    np.testing.assert_allclose(free.pose(2), (6.0, 0.0, 0.0), atol=1e-6)
    pulled = _chain(ReachBound(0, 2, (0.0, 0.0), 4.0, 0.01))
    np.testing.assert_allclose(pulled.pose(1), (3.0, 0.0, 0.0), atol=1e-3)
    assert 4.0 < pulled.pose(2)[0] < 4.05 and abs(pulled.pose(2)[1]) < 1e-3
    kept = _chain(ReachBound(0, 2, (1.0, 0.0), 6.0, 0.01))
    np.testing.assert_allclose(kept.pose(2), (6.0, 0.0, 0.0), atol=1e-6)
    # The same after the solver is rebuilt from the stored edges and bounds (a join).
    pulled.join([2], np.eye(3), dropped_anchor=2)
    pulled.optimize(iterations=5)
    assert 4.0 < pulled.pose(2)[0] < 4.05
    assert pulled.solve() >= 0 and 4.0 < pulled.pose(2)[0] < 4.05
