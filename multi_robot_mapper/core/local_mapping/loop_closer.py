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
   place; wrong closures rarely agree with each other). Its edge is the two keyframes' own
   scans refined from the window match. It enters the graph with a robust (Huber) kernel:
   convex, so a closure that corrects metres of drift still pulls from where the drift left
   the keyframes, and one wrong closure that got past the checks pulls with a bounded force;
4. **joins**: a piece started when the robot was lost is joined to the piece it was lost
   from: its keyframes' windows are matched with the other piece's keyframes near where the
   front end's guess puts them (:meth:`LoopCloser._joins`); the younger piece moves into the
   older one's frame;
5. the graph is optimised (ISAM2), the keyframes that moved are reported.
"""

from __future__ import annotations

import dataclasses
import time
import traceback
from collections.abc import Callable
from typing import NamedTuple, TypeVar

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeMap, KeyframeScan
from multi_robot_mapper.core.matching import HEURISTICS, MatchResult, integrate
from multi_robot_mapper.core.matching.beams import Viewpoint
from multi_robot_mapper.core.matching.confidence import (
    RIGHT_ANGLE,
    RIGHT_DISTANCE,
    TRACK_TURNS,
)
from multi_robot_mapper.core.matching.refine import match_information
from multi_robot_mapper.core.pose_graph import Edge, PoseGraph

FloatArray = NDArray[np.float64]
Pose = tuple[float, float, float]
T = TypeVar("T")


class LostFrom(NamedTuple):
    """Where a piece started: the front end's guess of its origin (the keyframe the best match
    was against, and T_keyframe_piece by that match, right or not), and where the robot's last
    placed scan was (its keyframe and T_keyframe_scan): the piece's first scan is the next
    scan, so the robot was there one scan interval before."""

    keyframe: int
    T_keyframe_piece: Pose
    last_keyframe: int
    T_last_keyframe_scan: Pose


# Pieces followed back along the chain of losses when joining (a piece lost from a piece
# lost from a third ...).
_CHAIN = 3
# Keyframes per window matched for loop closures and joins: the keyframe and its nearest
# neighbours in time (the confidence is calibrated on windows of three scans).
_WINDOW = 3
# The loop-closure gate (chi-square, 3 degrees of freedom, 99.9 %) on the graph's marginal
# covariances inflated this many times (drift the graph does not model: biased matches).
_CHI2_3DOF_999 = 16.27
_GATE_INFLATION = 4.0
# A robot turns less than a quarter turn between two consecutive scans (at most 79 deg on the
# shared logs, whose scans are up to 1.5 m apart): a join that turns a piece's first scan more
# than this from the robot's last placed scan is the half-turned look-alike of a symmetric
# corridor, not the robot's motion.
_TURN_BETWEEN_SCANS = np.pi / 2
_ORIGIN: Pose = (0.0, 0.0, 0.0)
# Two closures are neighbours (checked against each other) when both ends are within this many
# keyframes; their cycle must close within the correctness tolerance, plus the drift of the
# path the cycle runs along, in metres and in radians per metre as the local maps drift
# (README "Merging", intel 4's 0.34 m: keyframe pairs of one piece against the reference on
# intel 4, csail 4, aces 2 and 4, 0.022 m/m and 0.001 rad/m).
_PAIR_SLACK = 0.02
_PAIR_SLACK_ANGLE = 0.001


@dataclasses.dataclass(frozen=True)
class Closure:
    """A match between keyframes far apart in time, accepted or refused."""

    first: int  # the older keyframe
    second: int  # the new keyframe
    T_first_second: Pose
    confidence: float
    kind: str  # "loop" (same piece) or "join" (two pieces)
    accepted: bool
    reason: str  # why refused ("" when accepted)


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


class LoopCloser:
    """Local edges, loop closures and joins for each new keyframe; the pose graph."""

    def __init__(self, config: LocalMapperConfig, keyframes: KeyframeMap) -> None:
        self.config = config
        self.keyframes = keyframes
        self.graph = PoseGraph()
        self.accepted: dict[int, Closure] = {}  # graph edge id -> closure in the graph
        self.refused: dict[str, int] = {}  # reason -> closures refused
        self._pending: list[_Candidate] = []  # loop closures waiting for a consistent partner
        self._path_since_closure: dict[int, float] = {}  # piece -> metres since a closure
        # piece -> (keyframe the robot was lost near, T_keyframe_piece as guessed)
        self._lost_from: dict[int, LostFrom] = {}
        # piece -> searched joins waiting for a partner: (keyframe, T_other_piece)
        self._join_candidates: dict[int, list[tuple[int, Pose]]] = {}
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
                self._lost_from[piece] = lost_from
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
        self.keyframes.set_poses(self.graph.poses())
        optimise_seconds += time.perf_counter() - optimise_started
        after = self.keyframes.poses
        count = min(len(before), len(after))
        changed = np.flatnonzero(
            np.abs(after[:count] - before[:count]).max(axis=1, initial=0.0) > 1e-6
        )
        moved = {int(k): self.keyframes.pose(int(k)) for k in changed}
        moved[index] = self.keyframes.pose(index)
        self.local_edges += local
        self.errors += len(errors)
        return BackendUpdate(
            moved,
            joins,
            closures,
            local,
            time.perf_counter() - started,
            optimise_seconds,
            errors,
        )

    # --- matching ---------------------------------------------------------------------------

    def _match(self, first: int, second: int, predicted: Pose | None, search: bool) -> MatchResult:
        """Keyframe ``second``'s scan placed in keyframe ``first``'s frame: from the prediction
        alone (``search`` False) or with no guess (INTEGRATE, the prediction one more
        hypothesis)."""
        a, b = self.keyframes.scans[first], self.keyframes.scans[second]
        extra = None if predicted is None else _hypothesis(predicted)
        return integrate(
            a.segments,
            b.segments,
            self.config.integrate,
            heuristics=HEURISTICS if search else (),
            extra_hypotheses=extra,
            views=(a.view, b.view),
        )

    def _window(self, center: int) -> tuple[FloatArray, list[Viewpoint]]:
        """Keyframe ``center`` and its nearest neighbours in time in its piece (``_WINDOW``
        keyframes in all), their scans fused in its frame, and their viewpoints: a window
        sees more of a place than one scan, and its matches are surer (README, "Match
        confidence": window pairs)."""
        piece = self.keyframes.piece(center)
        pieces = self.keyframes.pieces
        candidates = np.flatnonzero(pieces == piece)
        members = candidates[np.argsort(np.abs(candidates - center), kind="stable")[:_WINDOW]]
        T_center = se2.invert(se2.matrix_from_pose(*self.keyframes.pose(center)))
        fused, owner = np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
        viewpoints = []
        for k in sorted(int(m) for m in members):
            scan = self.keyframes.scans[k]
            T = T_center @ se2.matrix_from_pose(*self.keyframes.pose(k))
            placed = se2.transform_segments(T, scan.segments)
            fused, owner = fuse(
                fused,
                owner,
                placed,
                np.full(len(placed), k, dtype=np.int64),
                self.config.integrate,
                self.config.fusion_tolerance,
            )
            viewpoints.append(Viewpoint(scan.view, T))
        return fused, viewpoints

    def _match_windows(
        self, first: int, second: int, predicted: Pose | None, search: bool = True
    ) -> MatchResult:
        """The window of keyframe ``second`` placed in the window of ``first``: with no guess
        (INTEGRATE, the prediction one more hypothesis), or refined from the prediction
        alone (``search`` False: the prediction turned either way too, so that a wrong
        minimum has rivals)."""
        segments_a, views_a = self._window(first)
        segments_b, views_b = self._window(second)
        hypotheses = None
        if predicted is not None:
            turns = (0.0,) if search else (0.0, *TRACK_TURNS)
            x, y, theta = predicted
            hypotheses = np.array([[theta + d, x, y] for d in turns])
        return integrate(
            segments_a,
            segments_b,
            self.config.integrate,
            heuristics=HEURISTICS if search else (),
            extra_hypotheses=hypotheses,
            views=(views_a, views_b),
        )

    def _scan_edge(self, first: int, second: int, T_first_second: Pose) -> Edge:
        """The robust edge of a closure or join: the placement the two keyframes' windows
        agreed on, with the information of the two keyframes' own scans at it. The windows'
        placement is kept as it is: refined again on the two scans alone it got worse (against
        the reference, over the accepted closures of intel, aces, fhw, csail and edmonton cut
        into 4 robots and freiburg-079 into 2: p90 error 0.07-0.15 m / 0.9-1.5 deg for the
        windows, 0.09-0.17 m / 1.3-2.1 deg refined; 10 of 1244 closures wrong by the
        reference against 16); two scans hold fewer walls than two windows."""
        return self._edge(first, second, _hypothesis(T_first_second)[0], robust=True)

    def _edge(self, first: int, second: int, T_1_2: FloatArray, robust: bool) -> Edge:
        """The edge of the placement ``T_1_2`` (theta, tx, ty) of keyframe ``second`` in
        ``first``, with the information of the two keyframes' scans at it."""
        a, b = self.keyframes.scans[first], self.keyframes.scans[second]
        config = self.config
        information = match_information(
            a.segments,
            b.segments,
            T_1_2,
            config.integrate,
            config.wall_sigma,
            (config.edge_sigma_floor, config.edge_angle_floor),
            (10.0, 1.0),
        )
        return Edge(first, second, _pose(T_1_2), information, robust)

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
            if result.confidence < config.integrate_confidence or not _close(
                _pose(result.T_1_2), predicted, RIGHT_DISTANCE, RIGHT_ANGLE
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
            found = _pose(result.T_1_2)
            if result.confidence < config.loop_confidence:
                self._refuse("confidence")
                continue
            if not self._agrees_with_graph(first, index, found):
                self._refuse("far from the graph's prediction")
                continue
            edge = self._scan_edge(first, index, found)
            closure = Closure(
                first, index, edge.T_first_second, result.confidence, "loop", True, ""
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

    def _agrees_with_graph(self, first: int, second: int, T_first_second: Pose) -> bool:
        """The Mahalanobis gate of a loop closure: the closure's relative pose of the two
        keyframes against the graph's, with the covariance of the graph's relative pose (from
        the two keyframes' joint marginal: what the path between them leaves uncertain, not
        what both inherit from far back), inflated ``_GATE_INFLATION`` times against drift
        the graph does not model, plus the correctness tolerance; chi-square 3 dof, 99.9 %."""
        predicted = se2.between(self.keyframes.pose(first), self.keyframes.pose(second))
        dx, dy, dtheta = se2.between(predicted, T_first_second)
        delta = np.array([dx, dy, dtheta])
        sigma = _GATE_INFLATION * self.graph.relative_covariance(first, second)
        sigma += np.diag([RIGHT_DISTANCE**2, RIGHT_DISTANCE**2, RIGHT_ANGLE**2])
        return float(delta @ np.linalg.solve(sigma, delta)) <= _CHI2_3DOF_999

    def _refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def _pairwise(self, closure: Closure, other: Closure) -> bool | None:
        """Are two closures consistent (None: not neighbours, both ends more than
        ``loop_window`` keyframes apart; or not independent, from the same new keyframe)?
        The cycle (this closure, the path from its second end to the other's, the other
        closure backwards, the path back) must close within the correctness tolerance plus a
        share of the path it runs along."""
        window = self.config.loop_window
        if abs(other.first - closure.first) > window or abs(other.second - closure.second) > window:
            return None
        if other.second == closure.second:
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
        return _close(
            closure.T_first_second,
            predicted,
            RIGHT_DISTANCE + _PAIR_SLACK * path,
            RIGHT_ANGLE + _PAIR_SLACK_ANGLE * path,
        )

    def _joins(self, index: int) -> list[tuple[int, int, FloatArray]]:
        """Join the new keyframe's piece to the piece the robot was lost from.

        The front end's best match of the piece's first scan (not confident enough to
        integrate) is a guess of where the piece lies in the other piece's frame. While the
        piece is young, the window of its first keyframe (growing with the keyframes after it)
        is matched with the window of the keyframe the robot was lost near: the end of one
        stretch against the start of the next, the most overlap there is. Then each new
        keyframe's window is matched with the other piece's keyframes near where the guess
        puts it. Matches are searched with no guess (the guess one more hypothesis), so a
        guess that fits a symmetric corridor turned round as well as the right way has a
        rival. A match is confident at ``loop_confidence``, as a loop closure, and must not
        turn the robot round between its last placed scan and the piece's first (a
        symmetric corridor's half-turned look-alike). One that **agrees with the guess**
        joins (two matches of different scans found the same placement); one that does not
        waits, within a region around the guess (the robot does not jump: its last placed
        scan was near), for a second one from another keyframe that puts the piece at the
        same place (any heading: a guess that was not confident may be turned round). The
        younger piece then moves into the older one's frame."""
        piece = self.keyframes.piece(index)
        # The pieces the robot was lost from, one after the other (a piece of one scan, lost
        # again at once, never grows to join by itself): each with the guess of this piece's
        # frame in its frame, composed along the chain.
        chain: list[tuple[int, Pose, int]] = []  # (lost-from keyframe, T_other_piece, depth)
        T_piece_here: Pose = (0.0, 0.0, 0.0)
        current = piece
        while current in self._lost_from and len(chain) < _CHAIN:
            keyframe, T_keyframe_current, _, _ = self._lost_from[current]
            other = self.keyframes.piece(keyframe)
            if other == piece:
                break  # joined already (through another keyframe)
            T_other_current = se2.compose(self.keyframes.pose(keyframe), T_keyframe_current)
            T_piece_here = se2.compose(T_other_current, T_piece_here)
            chain.append((keyframe, T_piece_here, len(chain)))
            current = other
        for keyframe, T_other_piece, depth in chain:
            joined = self._join_through_guess(index, piece, keyframe, T_other_piece, depth)
            if joined:
                return joined
        return []

    def _join_through_guess(
        self, index: int, piece: int, keyframe: int, T_other_piece: Pose, depth: int
    ) -> list[tuple[int, int, FloatArray]]:
        """One attempt of :meth:`_joins` against the piece of ``keyframe`` (the robot was lost
        near it), where the guess puts this piece at ``T_other_piece``."""
        config = self.config
        other_piece = self.keyframes.piece(keyframe)
        path = self._path_since_closure.get(piece, 0.0)
        radius = config.loop_radius + 2.0 * config.keyframe_distance
        radius += config.loop_radius_growth * path
        pairs: list[tuple[int, int]] = []  # (keyframe of this piece, of the other)
        young = len(self.keyframes.members(piece))
        if 1 < young <= _WINDOW and depth == 0:
            # Where the robot was lost: near the keyframe it was last placed by, whatever the
            # guess's heading (a guess that is not confident may be turned round).
            lost_at = self.keyframes.pose(keyframe)
            around = self.keyframes.near(lost_at, other_piece, config.loop_radius)
            pairs += [(piece, int(k)) for k in around[: config.loop_candidates]]
        guess = se2.compose(T_other_piece, self.keyframes.pose(index))
        near = self.keyframes.near(guess, other_piece, radius)
        pairs += [(index, int(k)) for k in near[: config.loop_candidates] if index != piece]
        for mine, first in pairs:
            predicted = se2.between(
                self.keyframes.pose(first),
                se2.compose(T_other_piece, self.keyframes.pose(mine)),
            )
            result = self._match_windows(first, mine, predicted)
            found = _pose(result.T_1_2)
            if result.confidence < config.loop_confidence:
                self._refuse("confidence (join)")
                continue
            if depth == 0 and not self._robot_did_not_turn_round(piece, first, mine, found):
                self._refuse("turned round from the robot's last pose (join)")
                continue
            if mine != piece and _close(found, predicted, RIGHT_DISTANCE, RIGHT_ANGLE):
                # The guess came from the piece's first scan: only another keyframe's match
                # is a second opinion.
                return [self._join(first, mine, found, result.confidence)]
            # Any heading where the robot's last placed scan rules out a half turn (above);
            # through a chain of pieces nothing does, and the chained guess must.
            if not _close(found, predicted, radius, np.pi if depth == 0 else _TURN_BETWEEN_SCANS):
                self._refuse("far from the guess (join)")
                continue
            T_found = se2.compose(
                se2.compose(self.keyframes.pose(first), found),
                se2.between(self.keyframes.pose(mine), _ORIGIN),
            )
            earlier = self._join_candidates.setdefault(piece, [])
            if not any(
                k != mine and _close(T, T_found, RIGHT_DISTANCE, RIGHT_ANGLE) for k, T in earlier
            ):
                earlier.append((mine, T_found))
                continue
            return [self._join(first, mine, found, result.confidence)]
        return []

    def _robot_did_not_turn_round(
        self, piece: int, first: int, mine: int, T_first_mine: Pose
    ) -> bool:
        """Would joining ``piece`` by this match (keyframe ``mine`` of the piece placed in
        keyframe ``first``'s frame) keep the robot's motion between its last placed scan and
        the piece's first scan within ``_TURN_BETWEEN_SCANS``? True when the last placed scan
        is not in ``first``'s piece (nothing to compare)."""
        lost = self._lost_from.get(piece)
        if lost is None or self.keyframes.piece(lost.last_keyframe) != self.keyframes.piece(first):
            return True
        last_scan = se2.compose(self.keyframes.pose(lost.last_keyframe), lost.T_last_keyframe_scan)
        T_other_mine = se2.compose(self.keyframes.pose(first), T_first_mine)
        # The piece's first scan is the origin of its frame.
        T_other_piece = se2.compose(T_other_mine, se2.between(self.keyframes.pose(mine), _ORIGIN))
        first_scan = se2.compose(T_other_piece, self.keyframes.pose(piece))
        return abs(se2.between(last_scan, first_scan)[2]) <= _TURN_BETWEEN_SCANS

    def _join(
        self, first: int, second: int, T_first_second: Pose, confidence: float
    ) -> tuple[int, int, FloatArray]:
        """Join the pieces of keyframes ``first`` and ``second`` through their match: the
        younger piece moves into the older one's frame. Returns (moved, kept, T_kept_moved)."""
        own, other = self.keyframes.piece(second), self.keyframes.piece(first)
        kept, moved = min(own, other), max(own, other)
        # T_other_second = pose(first) . T_first_second, in the other piece's frame.
        T_other_second = se2.matrix_from_pose(*self.keyframes.pose(first))
        T_other_second = T_other_second @ se2.matrix_from_pose(*T_first_second)
        T_own_second = se2.matrix_from_pose(*self.keyframes.pose(second))
        T_other_own = T_other_second @ se2.invert(T_own_second)
        T_kept_moved = T_other_own if kept == other else se2.invert(T_other_own)
        moved_keys = [int(k) for k in self.keyframes.members(moved)]
        self.keyframes.join(moved, kept, T_kept_moved)
        self.graph.join(moved_keys, T_kept_moved, dropped_anchor=moved)
        edge = self._scan_edge(first, second, T_first_second)
        self.accepted[self.graph.add_edge(edge)] = Closure(
            first, second, edge.T_first_second, confidence, "join", True, ""
        )
        self._lost_from.pop(moved, None)
        self._path_since_closure[kept] = 0.0
        return (moved, kept, T_kept_moved)


def _pose(T_1_2: FloatArray) -> Pose:
    """INTEGRATE's (theta, tx, ty) as an (x, y, theta) pose."""
    return (float(T_1_2[1]), float(T_1_2[2]), float(T_1_2[0]))


def _hypothesis(pose: Pose) -> FloatArray:
    """An (x, y, theta) pose as an INTEGRATE hypothesis row (theta, tx, ty)."""
    return np.array([[pose[2], pose[0], pose[1]]])


def _close(a: Pose, b: Pose, distance: float, angle: float) -> bool:
    """Are two relative poses within ``distance`` and ``angle`` of each other?"""
    dx, dy, dtheta = se2.between(b, a)
    return bool(np.hypot(dx, dy) <= distance and abs(dtheta) <= angle)
