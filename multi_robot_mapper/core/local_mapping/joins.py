"""Joins between pieces of one robot's map (:class:`PieceJoins`, the back end's step 4).

A robot whose scans cannot be placed maps on in a new piece (its own frame); the front end's
best match, right or not, is the guess of where the piece lies (:class:`LostFrom`). Each new
keyframe of the piece is matched with the keyframes of the piece the robot was lost from:
near where the guess puts it, and on the ring of keyframes the robot's motion allows whatever
the guess (the piece is rigid, and its first scan lies within the robot's reach of its last
placed scan, or of the last scan placed before a chain of losses, :class:`LastPlaced`). The
younger piece then moves into the older one's frame.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.placement import Reach
from multi_robot_mapper.core.local_mapping.attempts import close_to
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeMap
from multi_robot_mapper.core.local_mapping.windows import (
    _WINDOW,
    Closure,
    FloatArray,
    WindowMatcher,
)
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE
from multi_robot_mapper.core.matching.integrate import pose_of_match
from multi_robot_mapper.core.pose_graph import ReachBound
from multi_robot_mapper.core.se2 import Pose


class LastPlaced(NamedTuple):
    """The robot's last placed scan before a piece, in another piece's frame (``pose``), or
    the motion from there to the piece's first scan; ``reach``: how far apart the two can be
    (m: the reach across each loss between, plus how far the robot got in each piece between,
    from its first scan to its last placed one); ``losses``: how many losses lie between."""

    pose: Pose
    reach: float
    losses: int

    def within(self, slack: float = 0.0) -> bool:
        """Is the motion within the reach (plus ``slack``, m)?"""
        return bool(np.hypot(self.pose[0], self.pose[1]) <= self.reach + slack)

    def turned_round(self) -> bool:
        """Does the motion turn the robot round across one loss (more than
        ``_TURN_BETWEEN_SCANS``)? Across two or more the robot may have turned further."""
        return self.losses == 1 and abs(self.pose[2]) > _TURN_BETWEEN_SCANS


class LostFrom(NamedTuple):
    """Where a piece started: the front end's guess of its origin (the keyframe the best match
    was against, and T_keyframe_piece by that match, right or not), and where the robot's last
    placed scan was (its keyframe and T_keyframe_scan): the piece's first scan is the next
    scan, so the robot was there one scan interval before. ``reach``: how far it can have
    driven in that interval (m: the front end's 95th-percentile speed times the interval, plus
    the correctness tolerance; None before the front end knows a speed). ``confidence``: the
    best match's."""

    keyframe: int
    T_keyframe_piece: Pose
    last_keyframe: int
    T_last_keyframe_scan: Pose
    reach: float | None = None
    confidence: float = 0.0


# Pieces followed back along the chain of losses when joining (a piece lost from a piece
# lost from a third ...): on the sparse logs a robot is lost up to five times in six scans
# (fhw 4 robot1, scans 57-62, pieces of one or two scans between), and only the reach summed
# along the chain bounds where the piece before them lies. Each piece of the chain costs its
# window matches.
_CHAIN = 5
# A robot turns less than a quarter turn between two consecutive scans (at most 79 deg on the
# shared logs, whose scans are up to 1.5 m apart): a join that turns a piece's first scan more
# than this from the robot's last placed scan is the half-turned look-alike of a symmetric
# corridor, not the robot's motion.
_TURN_BETWEEN_SCANS = np.pi / 2
_ORIGIN: Pose = (0.0, 0.0, 0.0)


class PieceJoins(WindowMatcher):
    """Joins of a robot's pieces of map: what each piece was lost from, and the searches
    that join it back."""

    def __init__(self, config: LocalMapperConfig, keyframes: KeyframeMap) -> None:
        super().__init__(config, keyframes)
        # piece -> (keyframe the robot was lost near, T_keyframe_piece as guessed)
        self._lost_from: dict[int, LostFrom] = {}
        # piece -> where it was lost, until the robot's motion across the loss is bounded
        self._motion_bounds: dict[int, LostFrom] = {}
        # (piece, other piece) -> searched joins waiting for a partner: (keyframe,
        # T_other_piece)
        self._join_candidates: dict[tuple[int, int], list[tuple[int, Pose]]] = {}
        # piece -> matches of the piece it was lost from, come back: (keyframe, T_piece_other)
        self._return_candidates: dict[int, list[tuple[int, Pose]]] = {}
        # (piece, other piece) -> how far along the ring of the other's reachable keyframes
        # the piece's joins have tried
        self._ring_cursor: dict[tuple[int, int], int] = {}
        # piece -> where it was lost, until its heading across the loss is tested against
        # the graph (once the two sides are one piece: LoopCloser._bridge_headings)
        self._unbridged: dict[int, LostFrom] = {}

    def _lost(self, piece: int, lost_from: LostFrom) -> None:
        """``piece`` was started when the robot was lost (``lost_from``: where)."""
        self._lost_from[piece] = lost_from
        self._unbridged[piece] = lost_from
        if lost_from.reach is not None:
            self._motion_bounds[piece] = lost_from

    @property
    def motion_bounds(self) -> int:
        """Bounds across a loss in the graph (:meth:`_bound_motions`)."""
        return len(self.graph.bounds)

    def lost_from(self, piece: int) -> LostFrom | None:
        """Where ``piece`` started, while it has not joined the piece it was lost from (None:
        it has, or no loss started it)."""
        return self._lost_from.get(piece)

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
        same place (any heading: a guess that was not confident may be turned round). Where
        the guess is wrong, each piece the robot was lost from (directly or through a chain
        of losses) is also searched on the ring of keyframes its motion allows
        (:meth:`_reachable_candidates`). A match away from the guess, on the ring or not,
        must put the piece's first scan within the robot's reach of its last placed scan
        (through a chain: the reaches across each loss plus how far the robot got in each
        piece between, :meth:`_last_placed_scan`; a chain's composed guess is as wrong as
        its guesses together, csail 4 robot4: 8 m off where a match 5 cm from the truth was
        refused), and waits for a second one from a keyframe whose window shares no scan
        with its own. The younger piece then moves into the older one's frame."""
        piece = self.keyframes.piece(index)
        # The pieces the robot was lost from, one after the other (a piece of one scan, lost
        # again at once, never grows to join by itself): each with the guess of this piece's
        # frame in its frame, composed along the chain.
        chain: list[tuple[int, Pose, int]] = []  # (lost-from keyframe, T_other_piece, depth)
        T_piece_here: Pose = (0.0, 0.0, 0.0)
        current = piece
        while current in self._lost_from and len(chain) < _CHAIN:
            lost = self._lost_from[current]
            keyframe, T_keyframe_current = lost.keyframe, lost.T_keyframe_piece
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
        return self._join_pieces_lost_here(index, piece)

    def _join_pieces_lost_here(self, index: int, piece: int) -> list[tuple[int, int, FloatArray]]:
        """Join a piece that the robot was lost from this piece into, when the robot comes
        back where that piece mapped. The robot maps in this piece now, so that piece grows no
        keyframes to search from (fhw 2 robot2: lost at its scan 5, the robot mapped 150 scans
        in a second piece, was lost again, and came back to its start in a third that joined
        the first). The new keyframe's window is matched with that piece's keyframes near
        where its guess puts the keyframe. A match must keep the robot's motion across the
        loss possible (within its reach, plus the search radius for the drift since, and less
        than a quarter turn), and a second keyframe whose window shares no scan with the
        first's must put the piece at the same place."""
        config = self.config
        radius = self._join_radius(piece)
        here = self.keyframes.pose(index)
        for other, lost in list(self._lost_from.items()):
            if other == piece or lost.reach is None or self.keyframes.piece(lost.keyframe) != piece:
                continue
            # The other piece's frame in this one, as the front end guessed it.
            T_piece_other = se2.compose(self.keyframes.pose(lost.keyframe), lost.T_keyframe_piece)
            here_in_other = se2.between(T_piece_other, here)
            near = self.keyframes.near(here_in_other, other, radius)
            for first in (int(k) for k in near[: config.loop_candidates]):
                predicted = se2.between(self.keyframes.pose(first), here_in_other)
                result = self._match_windows(first, index, predicted)
                if result.confidence < config.loop_confidence:
                    self._refuse("confidence (join)")
                    continue
                found = pose_of_match(result.T_1_2)
                motion = self._motion_since_lost(other, index, first, se2.between(found, _ORIGIN))
                if motion is None or not motion.within(radius) or motion.turned_round():
                    self._refuse("beyond the robot's reach (join)")
                    continue
                T_found = self._piece_frame(first, index, found)
                earlier = self._return_candidates.setdefault(other, [])
                if self._seconded(earlier, index, T_found, apart=True) and (
                    self._join_believed(first, index, found)
                ):
                    return [self._join(first, index, found, result.confidence)]
        return []

    def _join_through_guess(
        self, index: int, piece: int, keyframe: int, T_other_piece: Pose, depth: int
    ) -> list[tuple[int, int, FloatArray]]:
        """One attempt of :meth:`_joins` against the piece of ``keyframe`` (the robot was lost
        near it), where the guess puts this piece at ``T_other_piece``."""
        config = self.config
        other_piece = self.keyframes.piece(keyframe)
        radius = self._join_radius(piece)
        pairs, bounded = self._guess_pairs(index, piece, keyframe, T_other_piece, depth, radius)
        for mine, first in pairs + bounded:
            predicted = se2.between(
                self.keyframes.pose(first),
                se2.compose(T_other_piece, self.keyframes.pose(mine)),
            )
            result = self._match_windows(first, mine, predicted)
            found = pose_of_match(result.T_1_2)
            if result.confidence < config.loop_confidence:
                self._refuse("confidence (join)")
                continue
            motion = self._motion_since_lost(piece, first, mine, found)
            if motion is not None and motion.turned_round():
                self._refuse("turned round from the robot's last pose (join)")
                continue
            reachable = motion is not None and motion.within()
            # Any heading near the guess where the robot's last placed scan rules out a half
            # turn (above); through a chain of pieces nothing does, and the chained guess must.
            near_guess = (mine, first) not in bounded and close_to(
                found, predicted, radius, np.pi if depth == 0 else _TURN_BETWEEN_SCANS
            )
            if (
                mine != piece
                and near_guess
                and close_to(found, predicted, RIGHT_DISTANCE, RIGHT_ANGLE)
            ):
                # The guess came from the piece's first scan: only another keyframe's match
                # is a second opinion.
                if self._join_believed(first, mine, found):
                    return [self._join(first, mine, found, result.confidence)]
                continue
            if not near_guess and not reachable:
                # Found away from the guess (on the ring, or through a chain of pieces lost
                # one after the other, whose guesses compose their errors): the piece's first
                # scan must lie where the robot can have driven since its last placed scan,
                # and a second keyframe's match must put the piece at the same place (below).
                self._refuse("beyond the robot's reach (join)")
                continue
            T_found = self._piece_frame(first, mine, found)
            earlier = self._join_candidates.setdefault((piece, other_piece), [])
            # Away from the guess, a second opinion shares no scan with the first: neighbouring
            # keyframes' windows overlap, and see a corridor slid the same way (fhw: a join
            # 0.96 m off at 0.96).
            if self._seconded(earlier, mine, T_found, apart=not near_guess) and (
                self._join_believed(first, mine, found)
            ):
                return [self._join(first, mine, found, result.confidence)]
        return []

    def _guess_pairs(
        self,
        index: int,
        piece: int,
        keyframe: int,
        T_other_piece: Pose,
        depth: int,
        radius: float,
    ) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
        """The pairs (keyframe of this piece, of the other) :meth:`_join_through_guess`
        matches: near where the robot was lost (a young piece's first attempt) and near where
        the guess puts keyframe ``index`` (within ``radius``); then, apart, those on the ring
        of keyframes the robot's motion allows."""
        config = self.config
        other_piece = self.keyframes.piece(keyframe)
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
        # Where the guess is wrong, the robot's motion still bounds where the piece lies.
        ring = self._reachable_candidates(index, piece, other_piece, radius)
        bounded = [(index, k) for k in ring if (index, k) not in pairs]
        return pairs, bounded

    def _join_believed(self, first: int, mine: int, T_first_mine: Pose) -> bool:
        """Does the evidence model believe the join that puts keyframe ``mine`` at
        ``T_first_mine`` in keyframe ``first``'s frame: ``mine``'s piece near it, on the whole
        of ``first``'s piece (:meth:`_believed`)? A join it doubts is refused."""
        keyframes = self.keyframes
        piece, other = keyframes.piece(mine), keyframes.piece(first)
        patch = keyframes.members(piece)
        target = keyframes.members(other)
        # Where the robot's motion since its last placed scan lets the piece lie (its first
        # scan within the robot's reach of that scan): rivals beyond it are no rivals.
        last = self._last_placed_scan(piece, other)
        reach = None
        if last is not None:
            turn = _TURN_BETWEEN_SCANS if last.losses == 1 else float(np.pi)
            radius = last.reach + self._join_radius(piece)
            reach = Reach(last.pose, radius, keyframes.pose(piece), turn)
        if self._believed("join", patch, target, first, mine, T_first_mine, reach):
            return True
        self._refuse("evidence (join)")
        return False

    def _join_radius(self, piece: int) -> float:
        """How far from where a guess puts a keyframe of ``piece`` its joins look: the loop
        closures' region, two keyframe steps wider."""
        config = self.config
        path = self._path_since_closure.get(piece, 0.0)
        return (
            config.loop_radius + 2.0 * config.keyframe_distance + config.loop_radius_growth * path
        )

    def _seconded(
        self, earlier: list[tuple[int, Pose]], mine: int, T_found: Pose, apart: bool
    ) -> bool:
        """Does a match in ``earlier`` (keyframe, piece frame) from a second opinion on
        keyframe ``mine`` put the piece at ``T_found`` too? A second opinion is any other
        keyframe, or with ``apart`` one whose window shares no scan with ``mine``'s. If none
        does, this match waits in ``earlier`` for one."""
        window = set(self._window_members(mine).tolist()) if apart else set()

        def second_opinion(other: int) -> bool:
            if apart:
                return window.isdisjoint(self._window_members(other).tolist())
            return other != mine

        if any(
            second_opinion(k) and close_to(T, T_found, RIGHT_DISTANCE, RIGHT_ANGLE)
            for k, T in earlier
        ):
            return True
        earlier.append((mine, T_found))
        return False

    def _piece_frame(self, first: int, mine: int, T_first_mine: Pose) -> Pose:
        """The frame of keyframe ``mine``'s piece in keyframe ``first``'s piece, by a match
        that places ``mine`` at ``T_first_mine`` in ``first``'s frame."""
        T_other_mine = se2.compose(self.keyframes.pose(first), T_first_mine)
        return se2.compose(T_other_mine, se2.between(self.keyframes.pose(mine), _ORIGIN))

    def _last_placed_scan(self, piece: int, other: int) -> LastPlaced | None:
        """Where the robot's last scan placed in ``other`` before ``piece`` was, followed back
        along the chain of losses (a piece lost from a piece lost from ``other`` ...; up to
        ``_CHAIN`` losses). None: no such chain, or no speed was known at one of its losses."""
        reach, current = 0.0, piece
        for losses in range(1, _CHAIN + 1):
            lost = self._lost_from.get(current)
            if lost is None or lost.reach is None:
                return None
            reach += lost.reach
            last = se2.compose(self.keyframes.pose(lost.last_keyframe), lost.T_last_keyframe_scan)
            current = self.keyframes.piece(lost.last_keyframe)
            if current == other:
                return LastPlaced(last, reach, losses)
            # From the first scan of the piece between to its last placed one.
            start = self.keyframes.pose(current)
            reach += float(np.hypot(last[0] - start[0], last[1] - start[1]))
        return None

    def _motion_since_lost(
        self, piece: int, first: int, mine: int, T_first_mine: Pose
    ) -> LastPlaced | None:
        """The robot's motion from its last placed scan in ``first``'s piece to the first scan
        of ``piece`` if this match (keyframe ``mine`` of the piece placed in keyframe
        ``first``'s frame) joined the pieces (:meth:`_last_placed_scan`, with the motion in
        place of the scan's pose); None when the robot was not lost from ``first``'s piece
        into ``piece`` (nothing to compare)."""
        last = self._last_placed_scan(piece, self.keyframes.piece(first))
        if last is None:
            return None
        # The piece's first scan is the origin of its frame.
        T_other_piece = self._piece_frame(first, mine, T_first_mine)
        first_scan = se2.compose(T_other_piece, self.keyframes.pose(piece))
        return last._replace(pose=se2.between(last.pose, first_scan))

    def _reachable_candidates(self, index: int, piece: int, other: int, radius: float) -> list[int]:
        """Keyframes of ``other`` (a piece the robot was lost from before ``piece``: one loss
        or a chain of them) that keyframe ``index`` of ``piece`` can lie near, whatever the
        guess, up to ``loop_candidates``. The piece is rigid and its first scan lies within the
        robot's reach of its last placed scan (:meth:`_last_placed_scan`), so the new keyframe
        lies at its own distance from the piece's first scan from there, give or take that
        reach; a window matches within ``radius``. The ring is walked a few keyframes per new
        keyframe (a window holds ``_WINDOW``), so a piece that grows tries the whole ring over
        time."""
        last = self._last_placed_scan(piece, other)
        if last is None or index == piece:
            return []
        last_scan, reach, _ = last
        here, origin = self.keyframes.pose(index), self.keyframes.pose(piece)
        offset = float(np.hypot(here[0] - origin[0], here[1] - origin[1]))
        members = self.keyframes.members(other)
        poses = self.keyframes.poses[members]
        distance = np.hypot(poses[:, 0] - last_scan[0], poses[:, 1] - last_scan[1])
        ring = members[np.abs(distance - offset) <= reach + radius]
        if len(ring) == 0:
            return []
        start = self._ring_cursor.get((piece, other), 0)
        steps = start + _WINDOW * np.arange(self.config.loop_candidates)
        self._ring_cursor[(piece, other)] = start + _WINDOW * self.config.loop_candidates
        return sorted({int(ring[k % len(ring)]) for k in steps})

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
        # The edge from the two pieces' windows, each still its own piece's (relative poses
        # within a piece do not change with the join).
        edge = self._scan_edge(first, second, T_first_second)
        self.keyframes.join(moved, kept, T_kept_moved)
        self.graph.join(moved_keys, T_kept_moved, dropped_anchor=moved)
        self.accepted[self.graph.add_edge(edge)] = Closure(
            edge.first,
            edge.second,
            edge.T_first_second,
            confidence,
            "join",
            True,
            "",
            found_by=second,
        )
        self._lost_from.pop(moved, None)
        self._path_since_closure[kept] = 0.0
        self._bound_motions()
        return (moved, kept, T_kept_moved)

    def _bound_motions(self) -> None:
        """A bound across each loss whose two sides are one piece now: the robot does not
        jump. The piece's first keyframe (where its first scan was) lies within the robot's
        reach of its last placed scan; beyond it a soft wall pulls (one sigma at the
        correctness tolerance past the reach, as the reach is a 95th-percentile speed). A
        join places the piece where it sees the same walls; without the bound the loop the
        robot drove while lost stays open at the loss, and the drift of both sides (fhw 2
        robot2: 2.8 m over 90 m of corridors no closure reaches) stays in the map there.
        Inside the reach it has no say: the robot's motion while the front end could not
        follow it is unknown (a constant-velocity guess with a Gaussian, tried, pulled intel 4
        robot4's joins 0.25 m off)."""
        for piece, lost in list(self._motion_bounds.items()):
            if self.keyframes.piece(lost.last_keyframe) != self.keyframes.piece(piece):
                continue
            del self._motion_bounds[piece]
            assert lost.reach is not None
            x, y, _ = lost.T_last_keyframe_scan
            self.graph.add_bound(
                ReachBound(lost.last_keyframe, piece, (x, y), lost.reach, RIGHT_DISTANCE)
            )
