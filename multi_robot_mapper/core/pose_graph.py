"""The keyframe pose graph: the one module that talks to gtsam (local mapping and merging).

Nodes are keyframes, each an SE(2) pose ``(x, y, theta)`` in its piece's frame; edges are
relative poses ``T_first_second`` measured by scan matching, with an information matrix from
the match itself (:func:`core.matching.refine.match_information`). Edges between keyframes
far apart in time (loop closures, joins between pieces) carry a robust kernel (Huber), so
one wrong closure that got past the checks pulls with a bounded force. A :class:`ReachBound`
is not a measurement but a bound: a keyframe lies within a distance of a point in another's
frame (the robot's reach across a loss), free inside, a soft wall beyond. Every piece (a part of
the map started when the robot was lost) has a prior on its first keyframe: pieces float
freely until a closure joins them (:meth:`PoseGraph.join`).

Optimisation is incremental (ISAM2: a new keyframe or closure costs milliseconds, not a batch
solve of the whole graph); joining pieces moves a whole piece into another's frame and
rebuilds the solver from the stored edges. The merger builds a graph of every robot's
keyframes at once from a rough start and solves it in one batch (:meth:`PoseGraph.solve`,
Levenberg-Marquardt), its links between robots under the Dynamic Covariance Scaling kernel
(``kernel="dcs"``: a wrong link that got past the consistency checks is switched off rather
than bending two robots' maps). The rest of core sees numpy arrays only:
``(x, y, theta)`` triples and 3x3 information matrices in gtsam's Pose2 tangent order
``(x, y, theta)``, expressed in the ``second`` keyframe's frame (gtsam's ``between`` error).
"""

from __future__ import annotations

import dataclasses
from types import MappingProxyType

import gtsam
import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]

# The prior that holds each piece's first keyframe where it is: 1 mm, 0.006 degrees.
_ANCHOR_SIGMAS = np.array([1e-3, 1e-3, 1e-4])
_KERNELS = MappingProxyType(
    {
        "huber": gtsam.noiseModel.mEstimator.Huber.Create,
        "dcs": gtsam.noiseModel.mEstimator.DCS.Create,
    }
)


@dataclasses.dataclass(frozen=True)
class Edge:
    """A measured relative pose between two keyframes."""

    first: int
    second: int
    T_first_second: Pose  # x, y, theta
    information: FloatArray  # (3, 3), Pose2 tangent order (x, y, theta)
    robust: bool  # loop closures and joins: Huber kernel


@dataclasses.dataclass(frozen=True)
class ReachBound:
    """A bound, not a measurement: keyframe ``second`` lies within ``reach`` (m) of the point
    ``point`` (x, y in keyframe ``first``'s frame). Free inside; outside, a quadratic wall
    whose cost is 1 at ``sigma`` (m) beyond the reach. What the robot's motion across a loss
    says: it does not jump, but its motion while the front end could not follow is unknown
    within its reach (a mean and a Gaussian would pull every such loss towards a guess)."""

    first: int
    second: int
    point: tuple[float, float]
    reach: float
    sigma: float

    def error(self, first: Pose, second: Pose) -> tuple[float, FloatArray, FloatArray]:
        """How far ``second`` lies beyond the reach (m, 0 inside) with ``first`` and
        ``second`` at these poses, and its Jacobians (1x3) in each pose's body tangent (x, y,
        theta), gtsam's Pose2 retraction. The distance does not depend on the frame:
        u = t_second - t_first - R(theta_first) point."""
        R_first = se2.matrix_from_pose(0.0, 0.0, first[2])[:2, :2]
        offset = R_first @ np.asarray(self.point)
        u = np.array([second[0] - first[0], second[1] - first[1]]) - offset
        distance = float(np.hypot(*u))
        if distance <= self.reach or distance == 0.0:
            return 0.0, np.zeros((1, 3)), np.zeros((1, 3))
        n = u / distance
        # d t = R(theta) dv for either pose; R(theta + w) point = offset + w J offset.
        J_first = np.array([[*(-n @ R_first), -float(n @ (_QUARTER_TURN @ offset))]])
        J_second = np.array([[*(n @ se2.matrix_from_pose(0.0, 0.0, second[2])[:2, :2]), 0.0]])
        return distance - self.reach, J_first, J_second


# Rotates a 2-vector by a quarter turn (the derivative of a rotation).
_QUARTER_TURN = np.array([[0.0, -1.0], [1.0, 0.0]])


class PoseGraph:
    """Keyframe poses optimised with gtsam's ISAM2."""

    def __init__(
        self, robust_scale: float = 1.0, kernel: str = "huber", relinearize: float = 0.01
    ) -> None:
        """``kernel`` of the robust edges: ``"huber"`` (convex: a closure correcting metres of
        drift still pulls from where the drift left the keyframes) or ``"dcs"`` (Dynamic
        Covariance Scaling, Agarwal et al. 2013: an edge whose error is far beyond
        ``robust_scale`` squared Mahalanobis units is scaled down towards nothing).
        ``relinearize``: ISAM2's threshold (m and rad of a keyframe's step) for linearising
        it again; the estimate's error from the optimum is of its second order."""
        if kernel not in _KERNELS:
            raise ValueError(f"kernel {kernel!r}: choose one of {', '.join(_KERNELS)}")
        self.robust_scale = robust_scale
        self.kernel = kernel
        self.relinearize = relinearize
        self.edges: dict[int, Edge] = {}  # edge id -> edge
        self.bounds: dict[int, ReachBound] = {}  # edge id -> bound (ids shared with edges)
        self._anchors: dict[int, Pose] = {}  # key -> prior pose (each piece's first keyframe)
        self._estimate: dict[int, Pose] = {}
        self._factor_index: dict[int, int] = {}  # edge id -> ISAM2 factor index
        self._next_edge = 0
        self._isam = gtsam.ISAM2(self._params())
        self._new_values = gtsam.Values()
        # What the next ISAM2 update adds: anchors' priors first, then edges, in this order.
        # Their factors are built only then (a graph built and solved in one batch, as the
        # merger's, never builds them for ISAM2 at all).
        self._pending_anchors: list[int] = []
        self._pending_edges: list[int] = []
        self._removed: list[int] = []  # ISAM2 factor indices to remove at the next update

    def _params(self) -> gtsam.ISAM2Params:
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(self.relinearize)
        params.relinearizeSkip = 1
        return params

    def __contains__(self, key: int) -> bool:
        return key in self._estimate

    def __len__(self) -> int:
        return len(self._estimate)

    # --- building ---------------------------------------------------------------------------

    def add_node(self, key: int, pose: Pose, anchored: bool = False) -> None:
        """A keyframe at its initial ``pose``; ``anchored`` for the first keyframe of a piece."""
        if key in self._estimate:
            raise ValueError(f"keyframe {key} is already in the graph")
        self._estimate[key] = pose
        self._new_values.insert(key, gtsam.Pose2(*pose))
        if anchored:
            self._anchors[key] = pose
            self._pending_anchors.append(key)

    def add_edge(self, edge: Edge) -> int:
        """Add a measured relative pose; returns its id (for :meth:`remove_edge`)."""
        edge_id = self._new_edge_id(edge.first, edge.second)
        self.edges[edge_id] = edge
        return edge_id

    def add_bound(self, bound: ReachBound) -> int:
        """Add a bound on where a keyframe lies (:class:`ReachBound`); returns its id."""
        edge_id = self._new_edge_id(bound.first, bound.second)
        self.bounds[edge_id] = bound
        return edge_id

    def _new_edge_id(self, first: int, second: int) -> int:
        """The id of a new edge or bound between two keyframes, pending for the solver."""
        for key in (first, second):
            if key not in self._estimate:
                raise ValueError(f"edge to keyframe {key}, which is not in the graph")
        edge_id = self._next_edge
        self._next_edge += 1
        self._pending_edges.append(edge_id)
        return edge_id

    def remove_edge(self, edge_id: int) -> None:
        """Drop an edge (a closure found wrong); takes effect at the next :meth:`optimize`."""
        del self.edges[edge_id]
        index = self._factor_index.pop(edge_id, None)
        if index is not None:
            self._removed.append(index)
        else:  # never reached the solver
            self._pending_edges.remove(edge_id)

    def _batch(self) -> gtsam.NonlinearFactorGraph:
        """The factors not yet given to the solver: anchors first, then edges (the order
        :meth:`optimize` reads their solver indices in)."""
        factors = gtsam.NonlinearFactorGraph()
        for key in self._pending_anchors:
            factors.push_back(self._anchor_factor(key, self._anchors[key]))
        for edge_id in self._pending_edges:
            factors.push_back(self._factor_of(edge_id))
        return factors

    def _factor_of(self, edge_id: int) -> gtsam.NonlinearFactor:
        bound = self.bounds.get(edge_id)
        return self._factor(self.edges[edge_id]) if bound is None else self._bound_factor(bound)

    @staticmethod
    def _bound_factor(bound: ReachBound) -> gtsam.CustomFactor:
        def error(
            factor: gtsam.CustomFactor, values: gtsam.Values, jacobians: list[FloatArray] | None
        ) -> FloatArray:
            first, second = (values.atPose2(key) for key in (bound.first, bound.second))
            beyond, J_first, J_second = bound.error(
                (first.x(), first.y(), first.theta()), (second.x(), second.y(), second.theta())
            )
            if jacobians is not None:
                jacobians[0], jacobians[1] = J_first, J_second
            return np.array([beyond])

        noise = gtsam.noiseModel.Isotropic.Sigma(1, bound.sigma)
        return gtsam.CustomFactor(noise, [bound.first, bound.second], error)

    def _anchor_factor(self, key: int, pose: Pose) -> gtsam.PriorFactorPose2:
        return gtsam.PriorFactorPose2(
            key, gtsam.Pose2(*pose), gtsam.noiseModel.Diagonal.Sigmas(_ANCHOR_SIGMAS)
        )

    def _factor(self, edge: Edge, robust: bool = True) -> gtsam.BetweenFactorPose2:
        information = 0.5 * (edge.information + edge.information.T)
        noise: gtsam.noiseModel.Base = gtsam.noiseModel.Gaussian.Information(information)
        if edge.robust and robust and self.robust_scale > 0:
            kernel = _KERNELS[self.kernel](self.robust_scale)
            noise = gtsam.noiseModel.Robust.Create(kernel, noise)
        return gtsam.BetweenFactorPose2(
            edge.first, edge.second, gtsam.Pose2(*edge.T_first_second), noise
        )

    # --- solving ----------------------------------------------------------------------------

    def optimize(self, iterations: int = 1) -> None:
        """Bring the estimate up to date with every node and edge added since the last call
        (ISAM2: one incremental step, plus ``iterations - 1`` relinearising steps)."""
        self._update_pending()
        for _ in range(iterations - 1):
            self._isam.update()
        self._read_estimate()

    def settle(self, max_steps: int = 20) -> int:
        """:meth:`optimize`, then relinearising steps until one relinearises no keyframe (every
        linearisation point within the threshold of the estimate: the estimate is the
        optimum's, up to that threshold's second-order error) or ``max_steps`` were taken. For
        a graph kept between merge updates, where an update moves some keyframes by metres
        (a new closure) and most not at all. Returns the steps taken."""
        self._update_pending()
        steps = 1
        while steps < max_steps and self._isam.update().getVariablesRelinearized() > 0:
            steps += 1
        self._read_estimate()
        return steps

    def _update_pending(self) -> None:
        """One ISAM2 step with every node and edge added (and edge removed) since the last."""
        result = self._isam.update(self._batch(), self._new_values, self._removed)
        indices = result.getNewFactorsIndices()
        # New factors get their indices in insertion order: the anchors first, then the edges.
        offset = len(self._pending_anchors)
        for position, edge_id in enumerate(self._pending_edges):
            self._factor_index[edge_id] = int(indices[offset + position])
        self._new_values = gtsam.Values()
        self._pending_edges, self._pending_anchors, self._removed = [], [], []

    def _read_estimate(self) -> None:
        values = self._isam.calculateEstimate()
        for key in self._estimate:
            pose = values.atPose2(key)
            self._estimate[key] = (float(pose.x()), float(pose.y()), float(pose.theta()))

    def objective(self) -> float:
        """The graph's cost at the estimate: half the sum of its edges' squared whitened
        errors, under their robust kernels, and the anchors' (gtsam's ``error``)."""
        return float(self._whole_graph().error(self._values()))

    def _whole_graph(self) -> gtsam.NonlinearFactorGraph:
        graph = gtsam.NonlinearFactorGraph()
        for key, pose in self._anchors.items():
            graph.push_back(self._anchor_factor(key, pose))
        for edge_id in (*self.edges, *self.bounds):
            graph.push_back(self._factor_of(edge_id))
        return graph

    def _values(self) -> gtsam.Values:
        values = gtsam.Values()
        for key, pose in self._estimate.items():
            values.insert(key, gtsam.Pose2(*pose))
        return values

    def solve(self, max_iterations: int = 50) -> int:
        """Optimise the whole graph in one batch (Levenberg-Marquardt from the current
        estimate), for a graph built at once from a rough start rather than grown keyframe by
        keyframe; the incremental solver restarts from the result. Returns the iterations."""
        graph, initial = self._whole_graph(), self._values()
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(max_iterations)
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        values = optimizer.optimize()
        for key in self._estimate:
            solved = values.atPose2(key)
            self._estimate[key] = (float(solved.x()), float(solved.y()), float(solved.theta()))
        self._restart()
        return int(optimizer.iterations())

    def pose(self, key: int) -> Pose:
        """The keyframe's current estimate (as of the last :meth:`optimize`, or as added)."""
        return self._estimate[key]

    def poses(self) -> dict[int, Pose]:
        return dict(self._estimate)

    def covariance(self, key: int) -> FloatArray:
        """Marginal covariance (3x3, Pose2 tangent order) of an optimised keyframe."""
        return np.asarray(self._isam.marginalCovariance(key), dtype=np.float64)

    def relative_covariance(self, first: int, second: int) -> FloatArray:
        """Covariance (3x3, tangent of T_first_second) of keyframe ``second``'s pose in
        keyframe ``first``'s frame, from the two keyframes' joint marginal: what the graph
        knows of their relative pose, which two poses far from the anchor know much better
        than either alone."""
        joint = np.asarray(self._isam.jointMarginalCovariance([first, second]).fullMatrix())
        T_first_second = gtsam.Pose2(*self._estimate[first]).between(
            gtsam.Pose2(*self._estimate[second])
        )
        # d(between)/d(first) = -Ad(T_second_first), d(between)/d(second) = I (body tangents).
        jacobian = np.hstack((-T_first_second.inverse().AdjointMap(), np.eye(3)))
        return np.asarray(jacobian @ joint @ jacobian.T, dtype=np.float64)

    def edge_error(self, edge_id: int) -> float:
        """Squared Mahalanobis distance of an edge's measurement at the current estimate."""
        edge = self.edges[edge_id]
        T_first = se2.matrix_from_pose(*self._estimate[edge.first])
        T_second = se2.matrix_from_pose(*self._estimate[edge.second])
        T_measured = se2.matrix_from_pose(*edge.T_first_second)
        residual = se2.invert(T_measured) @ se2.invert(T_first) @ T_second
        local = np.asarray(gtsam.Pose2.Logmap(gtsam.Pose2(*se2.pose_from_matrix(residual))))
        return float(local @ edge.information @ local)

    def _restart(self) -> None:
        """A new solver from the stored anchors and edges, linearised at the estimate."""
        self._isam = gtsam.ISAM2(self._params())
        self._factor_index.clear()
        self._removed = []
        self._new_values = gtsam.Values()
        for key, pose in self._estimate.items():
            self._new_values.insert(key, gtsam.Pose2(*pose))
        self._pending_anchors = list(self._anchors)
        self._pending_edges = [*self.edges, *self.bounds]

    # --- pieces -----------------------------------------------------------------------------

    def join(self, moved: list[int], T_kept_moved: FloatArray, dropped_anchor: int) -> None:
        """Express the keyframes ``moved`` (a whole piece) in another piece's frame:
        ``T_kept_moved`` (3x3) maps the moved piece's frame into the kept one. The moved
        piece's anchor is dropped (the joining edge holds it now); the solver is rebuilt from
        the stored edges with the moved estimates."""
        for key in moved:
            T = T_kept_moved @ se2.matrix_from_pose(*self._estimate[key])
            self._estimate[key] = se2.pose_from_matrix(T)
        self._anchors.pop(dropped_anchor, None)
        self._restart()
