"""The back end of local mapping: keyframes into the pose graph, local edges, loop closures,
joins between pieces, optimisation.

For every new keyframe (:meth:`LoopCloser.add_keyframe`):

1. the keyframe enters the :class:`KeyframeMap` (fused with the map near it) and the
   :class:`PoseGraph` (with the front end's edge to the keyframe it was matched against);
2. **local edges**: it is matched (from the predicted relative pose) with up to
   ``local_edges`` of the nearest keyframes among the ``loop_window`` before it; each match
   with confidence >= ``integrate_confidence`` that agrees with the prediction becomes an edge:
   the graph gets stiff where the robot has been for a while;
3. **loop closures**: candidates are older keyframes of the same piece within a search region
   that grows with the path driven since the last closure (``loop_radius`` +
   ``loop_radius_growth`` per metre), nearest first, at most ``loop_candidates``. The window
   of each (the candidate and its neighbours in time) is matched with no guess against the
   new keyframe's window (INTEGRATE, the graph's prediction one more hypothesis). A closure
   is accepted only if (a) its confidence >= ``loop_confidence``, (b) it agrees with the
   graph's prediction within the search region (a gate whose size grows with the path: the
   front end's drift), (c) it is consistent with the closures nearby (pairwise consistency in
   the manner of PCM: the cycle closure - path - closure - path must close within the
   correctness tolerance), and has a consistent partner: an accepted closure nearby or another
   candidate found within ``loop_window`` keyframes (one closure alone may be a look-alike
   place; wrong closures rarely agree with each other). Its edge is the windows' placement,
   put between the member of each window whose scans see the same walls best. It enters the
   graph with a robust (Huber) kernel: convex, so a closure that corrects metres of drift
   still pulls from where the drift left the keyframes, and one wrong closure that got past
   the checks pulls with a bounded force;
4. **joins**: a piece started when the robot was lost is joined to the piece it was lost
   from: its keyframes' windows are matched with the other piece's keyframes near where the
   front end's guess puts them, and on the ring of keyframes the robot's motion allows
   (``joins.py``); the younger piece moves into the older one's frame. Once a join makes the
   two sides of a loss one piece, the robot's reach bounds the motion across it, and the
   front end's guess gives its heading where the join does not span the loss
   (:meth:`LoopCloser._bridge_headings`);
5. the graph is optimised (ISAM2), the keyframes that moved are reported.
"""

from __future__ import annotations

import dataclasses
import time
import traceback
from collections.abc import Callable
from typing import TypeVar

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.model import graph_prior
from multi_robot_mapper.core.evidence.placement import Reach
from multi_robot_mapper.core.local_mapping.attempts import close_to
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.evidence import without_approach
from multi_robot_mapper.core.local_mapping.joins import LostFrom, PieceJoins
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeMap, KeyframeScan
from multi_robot_mapper.core.local_mapping.windows import (
    Closure,
    FloatArray,
)
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE
from multi_robot_mapper.core.matching.integrate import hypotheses_of, pose_of_match
from multi_robot_mapper.core.pose_graph import Edge
from multi_robot_mapper.core.se2 import Pose

T = TypeVar("T")

__all__ = ["BackendUpdate", "Closure", "LoopCloser", "LostFrom"]

# The loop-closure gate (chi-square, 3 degrees of freedom, 99.9 %) on the graph's marginal
# covariances inflated this many times (drift the graph does not model: biased matches).
_CHI2_3DOF_999 = 16.27
_GATE_INFLATION = 4.0
# The same gate on a heading alone (chi-square, 1 degree of freedom, 99.9 %).
_CHI2_1DOF_999 = 10.83
# The position information of an edge that holds a heading only: one over (1 km)^2.
_NO_POSITION = 1e-6
# Two closures are neighbours (checked against each other) when both ends are within this many
# keyframes; their cycle must close within the correctness tolerance, plus the drift of the
# path the cycle runs along, in metres and in radians per metre as the local maps drift
# (README "Merging", intel 4's 0.34 m: keyframe pairs of one piece against the reference on
# intel 4, csail 4, aces 2 and 4, 0.022 m/m and 0.001 rad/m).
_PAIR_SLACK = 0.02
_PAIR_SLACK_ANGLE = 0.001


@dataclasses.dataclass(frozen=True)
class _Candidate:
    """A loop closure waiting for a consistent partner."""

    closure: Closure
    edge: Edge
    born: int  # the keyframe that found it


@dataclasses.dataclass
class BackendUpdate:
    """What one keyframe changed."""

    moved: dict[int, Pose]  # keyframes whose pose changed, in their piece's frame
    joins: list[tuple[int, int, FloatArray]]  # (moved piece, kept piece, T_kept_moved 3x3)
    closures: list[Closure]
    local_edges: int
    seconds: float  # spent in this update
    optimise_seconds: float  # of which in the optimiser
    errors: list[str]  # tracebacks of steps that failed (and were skipped)


class LoopCloser(PieceJoins):
    """Local edges, loop closures and joins for each new keyframe; the pose graph."""

    def __init__(self, config: LocalMapperConfig, keyframes: KeyframeMap) -> None:
        super().__init__(config, keyframes)
        self._pending: list[_Candidate] = []  # loop closures waiting for a consistent partner
        self.headings: list[Closure] = []  # headings across losses in the graph (kind "heading")
        self.local_edges = 0
        self.errors = 0  # back-end steps that failed (and were skipped)

    def add_keyframe(
        self,
        scan: KeyframeScan,
        pose: Pose,
        piece: int,
        odometry: Edge | None,
        lost_from: LostFrom | None = None,
    ) -> BackendUpdate:
        """Bring a new keyframe into the map and the graph; returns what moved.

        ``odometry`` is the front end's edge to the keyframe it was matched against (None for
        the first keyframe of a piece). ``lost_from`` (with a piece's first keyframe): the
        keyframe the robot was last placed near, and where this piece's frame lies in that
        keyframe's frame as far as the front end knows (where its last scan was: the robot
        does not jump). It says where to look for the join.
        """
        started = time.perf_counter()
        index = scan.index
        before = self.keyframes.poses
        self._enter(scan, pose, piece, odometry, lost_from)
        # The keyframe and its edge are in; every later step only improves the map. One that
        # fails (a bug) is reported and skipped, so the next keyframe finds the graph whole.
        errors: list[str] = []

        def guarded(step: Callable[[], T], default: T) -> T:
            try:
                return step()
            except Exception:
                errors.append(traceback.format_exc())
                return default

        guarded(lambda: self.keyframes.fuse(index), None)
        local = guarded(lambda: self._local_edges(index, piece, odometry), 0)
        optimise_seconds = 0.0
        optimise_started = time.perf_counter()
        guarded(self.graph.optimize, None)  # the new keyframe's marginal, for the closure gate
        optimise_seconds += time.perf_counter() - optimise_started
        no_closures: list[Closure] = []
        no_joins: list[tuple[int, int, FloatArray]] = []
        closures = guarded(lambda: self._loop_closures(index, piece), no_closures)
        joins = guarded(lambda: self._joins(index), no_joins)
        optimise_started = time.perf_counter()
        if closures or joins:
            guarded(lambda: self.graph.optimize(iterations=3), None)
        headings = guarded(self._bridge_headings, no_closures) if joins else no_closures
        if headings:
            guarded(lambda: self.graph.optimize(iterations=3), None)
        self.keyframes.set_poses(self.graph.poses())
        optimise_seconds += time.perf_counter() - optimise_started
        moved = self._moved_since(before, index)
        self.local_edges += local
        self.errors += len(errors)
        seconds = time.perf_counter() - started
        return BackendUpdate(moved, joins, closures, local, seconds, optimise_seconds, errors)

    def _enter(
        self,
        scan: KeyframeScan,
        pose: Pose,
        piece: int,
        odometry: Edge | None,
        lost_from: LostFrom | None,
    ) -> None:
        """The new keyframe into the map and the graph (with the front end's edge), and the
        path its piece has driven since its last closure; a piece's first keyframe starts
        that path, and says where the robot was lost from."""
        index = scan.index
        self.keyframes.add(scan, pose, piece)
        self.graph.add_node(index, pose, anchored=odometry is None)
        if odometry is not None:
            self.graph.add_edge(odometry)
            previous = self.keyframes.pose(odometry.first)
            step = float(np.hypot(pose[0] - previous[0], pose[1] - previous[1]))
            self._path_since_closure[piece] = self._path_since_closure.get(piece, 0.0) + step
        else:
            self._path_since_closure[piece] = 0.0
            if lost_from is not None:
                self._lost(piece, lost_from)

    def _moved_since(self, before: FloatArray, index: int) -> dict[int, Pose]:
        """The keyframes whose pose changed since ``before`` (every keyframe's pose then), and
        the new keyframe ``index``, with their poses now."""
        after = self.keyframes.poses
        count = min(len(before), len(after))
        changed = np.flatnonzero(
            np.abs(after[:count] - before[:count]).max(axis=1, initial=0.0) > 1e-6
        )
        moved = {int(k): self.keyframes.pose(int(k)) for k in changed}
        moved[index] = self.keyframes.pose(index)
        return moved

    def _local_edges(self, index: int, piece: int, odometry: Edge | None) -> int:
        """Edges to the nearest recent keyframes (not the front end's own reference)."""
        config = self.config
        if config.local_edges == 0:
            return 0
        pose = self.keyframes.pose(index)
        window = self.keyframes.near(pose, piece, config.fusion_radius, before=index)
        window = window[window >= index - config.loop_window]
        if odometry is not None:
            window = window[window != odometry.first]
        added = 0
        for other in window[: config.local_edges]:
            predicted = se2.between(self.keyframes.pose(int(other)), pose)
            result = self._match(int(other), index, predicted, search=False)
            if result.confidence < config.integrate_confidence or not close_to(
                pose_of_match(result.T_1_2), predicted, RIGHT_DISTANCE, RIGHT_ANGLE
            ):
                continue
            self.graph.add_edge(self._edge(int(other), index, result.T_1_2, robust=False))
            added += 1
        return added

    def _loop_closures(self, index: int, piece: int) -> list[Closure]:
        """Loop-closure candidates of the new keyframe, matched and checked; returns the
        closures accepted in this step (a candidate may wait for a consistent partner)."""
        config = self.config
        pose = self.keyframes.pose(index)
        path = self._path_since_closure.get(piece, 0.0)
        radius = config.loop_radius + config.loop_radius_growth * path
        candidates = self.keyframes.near(pose, piece, radius, before=index - config.loop_window)
        accepted: list[Closure] = []
        for other in candidates[: config.loop_candidates]:
            first = int(other)
            predicted = se2.between(self.keyframes.pose(first), pose)
            result = self._match_windows(first, index, predicted)
            found = pose_of_match(result.T_1_2)
            if result.confidence < config.loop_confidence:
                self._refuse("confidence")
                continue
            correction, gate = self._graph_gate(first, index, found)
            if float(correction @ np.linalg.solve(gate, correction)) > _CHI2_3DOF_999:
                self._refuse("far from the graph's prediction")
                continue
            # The recent stretch of map near the new keyframe, placed by the closure on the
            # piece's older map (without the robot's own approach to the place, mapped with the
            # drift the closure corrects): believed only when no rival placement explains about
            # as much (the evidence model, as for a link between robots). A rival lies within
            # the region the closure was searched in: the drift since the last closure cannot
            # have carried the robot farther.
            members = self.keyframes.members(piece)
            recent = members[(members > index - config.loop_window) & (members <= index)]
            older = members[members <= index - config.loop_window]
            older = without_approach(self.keyframes.poses, older, first + config.loop_window, index)
            here = self.keyframes.pose(index)
            reach = Reach(here, radius, here)
            prior = graph_prior(correction, gate, radius)
            if not self._believed("loop", recent, older, first, index, found, reach, prior):
                self._refuse("evidence")
                continue
            edge = self._scan_edge(first, index, found)
            closure = Closure(
                edge.first,
                edge.second,
                edge.T_first_second,
                result.confidence,
                "loop",
                True,
                "",
                found_by=index,
            )
            accepted += self._corroborate(_Candidate(closure, edge, index), piece)
        # Candidates no consistent partner came for within a window of keyframes are refused.
        expired = [c for c in self._pending if c.born < index - config.loop_window]
        self._pending = [c for c in self._pending if c.born >= index - config.loop_window]
        for _ in expired:
            self._refuse("no consistent partner")
        return accepted

    def _corroborate(self, candidate: _Candidate, piece: int) -> list[Closure]:
        """Pairwise consistency (in the manner of PCM). A candidate inconsistent with an
        accepted closure nearby is refused; one consistent with an accepted closure, or with
        another waiting candidate, is accepted (with that partner); otherwise it waits: one
        closure alone, however confident, may be a look-alike place, while wrong closures
        rarely agree with each other."""
        verdicts = [self._pairwise(candidate.closure, other) for other in self.accepted.values()]
        if False in verdicts:
            self._refuse("inconsistent with nearby closures")
            return []
        partners: list[_Candidate] = []
        if True not in verdicts:
            partners = [
                waiting
                for waiting in self._pending
                if self._pairwise(candidate.closure, waiting.closure)
            ][:1]
            if not partners:
                self._pending.append(candidate)
                return []
        for chosen in (*partners, candidate):
            if chosen in self._pending:
                self._pending.remove(chosen)
            self.accepted[self.graph.add_edge(chosen.edge)] = chosen.closure
        self._path_since_closure[piece] = 0.0
        return [c.closure for c in (*partners, candidate)]

    def _graph_gate(
        self, first: int, second: int, T_first_second: Pose
    ) -> tuple[FloatArray, FloatArray]:
        """The Mahalanobis gate of a loop closure: the closure's relative pose of the two
        keyframes in the graph's (dx, dy, dtheta), and the covariance it is gated with
        (chi-square 3 dof, 99.9 %): the graph's relative pose's (from the two keyframes' joint
        marginal: what the path between them leaves uncertain, not what both inherit from far
        back), inflated ``_GATE_INFLATION`` times against drift the graph does not model, plus
        the correctness tolerance."""
        predicted = se2.between(self.keyframes.pose(first), self.keyframes.pose(second))
        correction = np.array(se2.between(predicted, T_first_second), dtype=np.float64)
        sigma = _GATE_INFLATION * self.graph.relative_covariance(first, second)
        sigma += np.diag([RIGHT_DISTANCE**2, RIGHT_DISTANCE**2, RIGHT_ANGLE**2])
        return correction, sigma

    def _bridge_headings(self) -> list[Closure]:
        """The heading across each loss whose two sides are one piece now, from the front
        end's guess: its best match when the robot was lost, not confident, but a wrong one
        is mostly a corridor slid along itself with its heading right (on the sparse shared
        logs cut into 4 and 2 robots, 48 of the 56 guesses whose two sides joined were within
        3.3 deg of the reference, the other eight 81-180 deg off). Where the join is far from
        the loss, the loop the robot drove while lost stays open there in heading without it
        (fhw 2 robot2: 12 deg at the loss); the reach bound (:meth:`_bound_motions`) holds
        the position, which a slid guess gets wrong. A loss its join spans
        (:meth:`_join_spans`) is closed already.

        The guess's heading enters the graph as a robust edge with the heading information
        of the two keyframes' scans at the guess (marginal over position) and none in
        position, when it agrees with the graph's relative heading of the two keyframes
        within what the joint marginal leaves uncertain, inflated as the loop-closure gate's,
        plus the correctness tolerance (chi-square, 1 dof, 99.9 %). Called once the graph
        holds the join (the marginal is the joined graph's)."""
        bridged: list[Closure] = []
        for piece, lost in list(self._unbridged.items()):
            first = lost.keyframe
            if self.keyframes.piece(first) != self.keyframes.piece(piece):
                continue
            del self._unbridged[piece]
            if self._join_spans(first, piece):
                self._refuse("loss spanned by its join (heading)")
                continue
            predicted = se2.between(self.keyframes.pose(first), self.keyframes.pose(piece))
            turn = float(se2.wrap_angle(lost.T_keyframe_piece[2] - predicted[2]))
            spread = _GATE_INFLATION * self.graph.relative_covariance(first, piece)[2, 2]
            if turn**2 > _CHI2_1DOF_999 * (spread + RIGHT_ANGLE**2):
                self._refuse("heading far from the graph's (loss)")
                continue
            T_guess = hypotheses_of([lost.T_keyframe_piece])[0]
            matched = self._edge(first, piece, T_guess, robust=True)
            variance = float(np.linalg.inv(matched.information)[2, 2])
            information = np.diag([_NO_POSITION, _NO_POSITION, 1.0 / variance])
            self.graph.add_edge(Edge(first, piece, matched.T_first_second, information, True))
            bridged.append(
                Closure(
                    first,
                    piece,
                    matched.T_first_second,
                    lost.confidence,
                    "heading",
                    True,
                    "",
                    found_by=piece,
                )
            )
        self.headings += bridged
        return bridged

    def _join_spans(self, first: int, second: int) -> bool:
        """Does a join lie between the windows of keyframes ``first`` and ``second``? A join
        found at the loss itself already closes it, with an edge from the same scans as the
        guess: the guess's heading would count their evidence twice."""
        ends = (
            set(self._window_members(first).tolist()),
            set(self._window_members(second).tolist()),
        )
        return any(
            closure.kind == "join"
            and any(closure.first in a and closure.second in b for a, b in (ends, ends[::-1]))
            for closure in self.accepted.values()
        )

    def _pairwise(self, closure: Closure, other: Closure) -> bool | None:
        """Are two closures consistent (None: not neighbours, both ends more than
        ``loop_window`` keyframes apart; or not independent, from the same new keyframe)?
        The cycle (this closure, the path from its second end to the other's, the other
        closure backwards, the path back) must close within the correctness tolerance plus a
        share of the path it runs along."""
        window = self.config.loop_window
        if abs(other.first - closure.first) > window or abs(other.second - closure.second) > window:
            return None
        if other.found_by == closure.found_by:
            # The same new keyframe's window matched to neighbouring old ones: one scan's
            # evidence twice, which a look-alike place fools as consistently (intel: three
            # such closures 7.2 m off, at 0.98-0.99). Only a later keyframe is a partner.
            return None
        first, second = closure.first, closure.second
        # T_first_second should equal T_first_a . T_a_b . T_b_second (a, b: the other's ends).
        T_first_a = se2.between(self.keyframes.pose(first), self.keyframes.pose(other.first))
        T_b_second = se2.between(self.keyframes.pose(other.second), self.keyframes.pose(second))
        predicted = se2.compose(se2.compose(T_first_a, other.T_first_second), T_b_second)
        path = float(np.hypot(*T_first_a[:2]) + np.hypot(*T_b_second[:2]))
        return close_to(
            closure.T_first_second,
            predicted,
            RIGHT_DISTANCE + _PAIR_SLACK * path,
            RIGHT_ANGLE + _PAIR_SLACK_ANGLE * path,
        )
