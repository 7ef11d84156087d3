"""Odometry-free local mapping: one robot's scans in, its keyframe graph and partial map out.

Frames: a robot's map is made of *pieces*; each piece's frame is the laser frame of its first
keyframe, and piece 0 (the first scan's) is the robot's map frame ``robotmap``.
``T_piece_laser`` places a scan in its piece. Every scan takes one path (:meth:`LocalMapper.
add_scan`):

1. **match**: the scan is matched against the last keyframe from the constant-velocity
   prediction alone (every scan of a fast laser is placed this way, in milliseconds); if that
   is not confident, INTEGRATE searches with no guess against the last scan, then against up
   to ``recent_keyframes`` keyframes before it (the predictions stay hypotheses); a search
   that is not confident is searched again with Wolter's shape matching as a second source of
   hypotheses (:mod:`core.matching.shape`);
2. **confidence**: the best match's probability of being right
   (:mod:`core.matching.confidence`), in the context it was asked in (the last scan, an older
   keyframe, another piece: :func:`~core.local_mapping.attempts.in_context`);
3. **integrate** when it reaches ``integrate_confidence``: the scan is placed; a scan that
   moved ``keyframe_distance`` or turned ``keyframe_angle`` from the last keyframe becomes a
   keyframe, with an edge (its information from the match) to the keyframe it was matched
   against; **otherwise the scan is held** (:mod:`.held`): when a later scan is placed from
   the map, the held ones contradicted the robot's own stream (scans of another place, junk
   ranges) and are set aside, the map untouched; when ``lost_confirm_scans`` held scans in a
   row follow each other (or ``lost_confirm_scans + 2`` are held), **the robot is lost** and
   maps on in a new piece, from the first of them. A placement in the robot's own piece is
   never farther from its last placed scan than it can have driven since
   (``plausible_speed``; right after held scans, its own top speed).

The back end (:mod:`.backend`: the loop closer and the keyframe map) takes each new keyframe:
local edges, loop closures, joins between pieces, optimisation of the pose graph, fusion into
the partial map. Replay calls it in line (:meth:`LocalMapper.add_scan` returns once the
keyframe is in the graph); a node hands keyframes to it on another thread, which waits on a
worker process (:meth:`LocalMapper.start_worker`), so a scan never waits for it. A pose can
jump when a closure moves the keyframes: that is expected.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import SegmentScan
from multi_robot_mapper.core.local_mapping.attempts import (
    Anchor,
    Attempt,
    Reference,
    References,
    match_scan,
    reach_in,
)
from multi_robot_mapper.core.local_mapping.backend import (
    Backend,
    BackendThread,
    HostedBackend,
)
from multi_robot_mapper.core.local_mapping.backend_link import BackendLink
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.held import OUTLIER, HeldScan, follow_match
from multi_robot_mapper.core.local_mapping.joins import LostFrom
from multi_robot_mapper.core.local_mapping.keyframe_map import Keyframe, KeyframeScan
from multi_robot_mapper.core.local_mapping.local_map import LocalMaps
from multi_robot_mapper.core.local_mapping.motion import RecentMotion
from multi_robot_mapper.core.matching import MatchResult
from multi_robot_mapper.core.matching.integrate import pose_of_match
from multi_robot_mapper.core.matching.prior import prior_support
from multi_robot_mapper.core.matching.refine import match_information
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.matching.shape import Shapes
from multi_robot_mapper.core.pose_graph import Edge
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.segment_map import SegmentMap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


# Back-end times kept (per keyframe): enough for any replay, bounded for a node running for hours.
_TIMES_KEPT = 100_000


@dataclasses.dataclass(frozen=True)
class LocalUpdate:
    """What one scan did."""

    accepted: bool  # placed (in its piece; a scan starting a new piece is placed too)
    pose: Pose | None  # T_piece_laser of this scan when accepted
    keyframe_added: bool
    confidence: float  # of the match that placed it (1 for a piece's first scan)
    reason: str  # why a scan was set aside, or why a new piece started ("" otherwise)
    piece: int = 0  # the piece the scan is in
    # the robot was lost: this scan (or the scans held before it) started a new piece
    new_piece: bool = False
    # the context of the match that placed it (attempts.CONTEXTS; "" when it starts a piece)
    placed_by: str = ""
    # seconds per stage of this scan: track / search / recent (matching), confidence,
    # handoff (a keyframe's edge to the back end), integrate (the rest)
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)


LOST = "lost: no confident match"  # why a new piece started (LocalMapper.set_aside_reasons)


@dataclasses.dataclass
class _Last:
    """The newest accepted scan."""

    stamp: float
    segments: SegmentMap
    view: LaserScanData
    anchor: Anchor


class LocalMapper(BackendLink):
    """One robot's keyframe graph and partial map, built scan by scan with no odometry."""

    def __init__(
        self,
        config: LocalMapperConfig | None = None,
        backend: bool = True,
        trajectory: bool = True,
    ) -> None:
        """``backend`` False: the back end runs only when :meth:`run_backend` is called or
        on the thread :meth:`start_worker` starts. ``trajectory`` False: every placed scan is
        not remembered (a node running for hours needs only the keyframes)."""
        self.config = config if config is not None else LocalMapperConfig()
        # keyframe map and loop closer, here or in a worker process (start_worker)
        self.backend: Backend | HostedBackend = Backend(self.config)
        self._shapes = Shapes(self.config.shape)  # of the scans the front end searches
        self.inline_backend = backend  # run the back end inside add_scan
        self.version = 0  # bumped whenever the partial map changes
        self.scans_accepted = 0
        self.scans_set_aside = 0
        self.scans_tracked = 0  # placed from the prediction alone, without a search
        self.scans_placed_by: dict[str, int] = {}  # placed scans per context of their match
        self.set_aside_reasons: dict[str, int] = {}
        self.pieces_started = 0  # new pieces after the first (the robot was lost)
        # Scans not placed from the map, held until the next ones say what they were.
        self._held: list[HeldScan] = []
        self._replaying = False  # mapping held scans after all (the robot was lost)
        self.stage_seconds: dict[str, float] = {}  # front-end time per stage, summed
        # The matches the newest scan was tried with (a bench judges them by the reference).
        self.last_attempts: list[Attempt] = []
        self._scan_seconds: dict[str, float] = {}  # the current scan's
        self.backend_seconds: deque[float] = deque(maxlen=_TIMES_KEPT)  # per keyframe
        self.backend_errors = 0  # back-end steps that failed and were skipped (bugs)
        self.last_backend_error: str | None = None  # the newest one's traceback
        self.optimise_seconds: deque[float] = deque(maxlen=_TIMES_KEPT)  # per keyframe
        self._last: _Last | None = None
        # the velocity, how far its predictions miss, the robot's top speed and scan period
        self._motion = RecentMotion(self.config.velocity_window)
        self._local_maps = LocalMaps()  # the local map tracking matches against
        # piece when placed -> (stamp, anchor) of the robot's last scan placed in it
        self._last_in_piece: dict[int, tuple[float, Anchor]] = {}
        self._piece_of_last = 0
        # The scans placed so far: (stamp, anchor), for the trajectory.
        self._placed: list[tuple[float, Anchor]] | None = [] if trajectory else None
        self._scans_at: dict[int, int] = {}  # keyframe -> scans placed on it
        # Keyframes the front end made and the back end has not taken yet.
        self._queue: deque[tuple[KeyframeScan, Pose, int, Edge | None, LostFrom | None]] = deque()
        # Front-end copy of every keyframe's pose and piece (the back end updates it).
        self._poses: dict[int, Pose] = {}
        self._pieces: dict[int, int] = {}
        self._scans: dict[int, KeyframeScan] = {}
        self._lock = threading.Lock()  # front end vs. a back end on another thread
        self._worker: BackendThread | None = None  # the back end's thread, when started
        self._busy = False  # the back end is on a keyframe
        self._keyframes: list[Keyframe] = []  # the back end's last published state

    # --- the method -------------------------------------------------------------------------

    @property
    def pose(self) -> Pose | None:
        """T_piece_laser of the newest accepted scan (its piece: :attr:`piece`)."""
        if self._last is None:
            return None
        with self._lock:
            return self._placed_pose(self._last.anchor)

    @property
    def piece(self) -> int:
        """The piece the newest accepted scan is in."""
        if self._last is None:
            return 0
        with self._lock:
            return self._pieces[self._last.anchor.keyframe]

    @property
    def stamp(self) -> float | None:
        return None if self._last is None else self._last.stamp

    @property
    def scans_held(self) -> int:
        """Scans not placed, waiting for the next scans (neither mapped nor set aside yet)."""
        return len(self._held)

    def add_scan(self, stamp: float, segments: SegmentScan, view: LaserScanData) -> LocalUpdate:
        """Place one scan (its segments and the scan they came from) and extend the map."""
        started = time.perf_counter()
        self._scan_seconds = {}
        self.last_attempts = []
        update = self._add_scan(stamp, segments, view)
        spent = time.perf_counter() - started
        self._count("integrate", spent - sum(self._scan_seconds.values()))
        return dataclasses.replace(update, seconds=dict(self._scan_seconds))

    def _add_scan(self, stamp: float, segments: SegmentScan, view: LaserScanData) -> LocalUpdate:
        array = np.asarray(segments.segments, dtype=np.float64).reshape(-1, 4)
        new = SegmentMap.of(array[np.isfinite(array).all(axis=1)])
        if new.total_length < self.config.integrate.min_match_value:
            return self._set_aside("too little structure in the scan")
        return self._place(stamp, new, view)

    def _place(self, stamp: float, new: SegmentMap, view: LaserScanData) -> LocalUpdate:
        last = self._last
        if last is None:
            return self._start_piece(stamp, new, view, "")
        dt = max(stamp - last.stamp, 0.0)
        holding = bool(self._held) and not self._replaying
        if holding and (follow := self._follows_held(stamp, new.segments, view)) is not None:
            return self._hold(HeldScan(stamp, new.segments, view, None, follow), follow.confidence)
        chosen, integrated = self._match(last, new, view, dt, after_held=holding)
        result, anchor, reference = chosen.result, chosen.anchor, chosen.reference
        T_keyframe_new = se2.compose(anchor.T_keyframe_scan, pose_of_match(result.T_1_2))
        if not integrated:
            # The best match, right or not, is the guess of where the new piece lies: the back
            # end joins the pieces when later keyframes confirm it (or find better).
            top_speed = self._top_speed()
            lost_from = LostFrom(
                anchor.keyframe,
                T_keyframe_new,
                last.anchor.keyframe,
                last.anchor.T_keyframe_scan,
                None if top_speed is None else reach_in(top_speed, dt),
                chosen.confidence,
            )
            if self._replaying:
                return self._start_piece(stamp, new, view, LOST, lost_from)
            return self._hold(HeldScan(stamp, new.segments, view, lost_from), chosen.confidence)
        self._set_aside_held()  # placed from the map: the scans held before it were outliers
        pose = chosen.pose
        motion = se2.between(self._placed_pose_unlocked(last.anchor), pose)
        if dt > 0.0:
            evidence = chosen.result.evidence
            support = None if evidence is None else evidence.support
            self._motion.placed(dt, motion, self._motion.predict(dt), support)
        placed = Anchor(anchor.keyframe, T_keyframe_new)
        keyframe_added = False
        known = self._known_view(pose, chosen.piece) if self.config.revisit_keyframes else None
        if known is not None:
            placed = known  # ground the map holds: tracked against that keyframe from now on
        elif self._moved_on(T_keyframe_new):
            started = time.perf_counter()
            placed = self._new_keyframe(stamp, new, view, anchor, result, reference)
            keyframe_added = True
            self._count("handoff", time.perf_counter() - started)
        self._last = _Last(stamp, new, view, placed)
        self._record(stamp, placed)
        self.scans_accepted += 1
        self.scans_placed_by[chosen.context] = self.scans_placed_by.get(chosen.context, 0) + 1
        return LocalUpdate(
            True,
            self.pose,
            keyframe_added,
            chosen.confidence,
            "",
            self.piece,
            False,
            chosen.context,
        )

    def _moved_on(self, T_keyframe_scan: Pose) -> bool:
        """The scan moved or turned enough from its keyframe to be a keyframe itself."""
        x, y, theta = T_keyframe_scan
        return bool(
            np.hypot(x, y) > self.config.keyframe_distance
            or abs(theta) > self.config.keyframe_angle
        )

    def _follows_held(
        self, stamp: float, segments: FloatArray, view: LaserScanData
    ) -> MatchResult | None:
        """The placement of a scan from the newest held one (:func:`follow_match`)."""
        started = time.perf_counter()
        scan = HeldScan(stamp, segments, view)
        follow = follow_match(self.config, self._held[-1], scan, self._top_speed())
        self._count("search", time.perf_counter() - started)
        return follow

    def _hold(self, scan: HeldScan, confidence: float) -> LocalUpdate:
        """Hold ``scan`` (:mod:`.held`). Once the newest ``lost_confirm_scans`` held scans
        follow each other, or ``lost_confirm_scans + 2`` are held, the robot is lost: the held
        scans are mapped as a lost robot's (:meth:`_lost`)."""
        self._held.append(scan)
        chain = 1
        while chain < len(self._held) and self._held[-chain].follow is not None:
            chain += 1
        confirm = self.config.lost_confirm_scans
        if chain < confirm and len(self._held) < confirm + 2:
            reason = "not placed: held until the next scan"
            return LocalUpdate(False, None, False, confidence, reason, self.piece)
        return self._lost()

    def _lost(self) -> LocalUpdate:
        """The robot is lost: the held scans are mapped in order exactly as they would have
        been without holding (the first starts a new piece from its guess; each later one is
        matched as usual, and starts a piece of its own when nothing places it)."""
        held, self._held = self._held, []
        self._replaying = True
        try:
            first = held[0]
            update = self._start_piece(
                first.stamp, SegmentMap.of(first.segments), first.view, LOST, first.lost_from
            )
            for scan in held[1:]:
                update = self._place(scan.stamp, SegmentMap.of(scan.segments), scan.view)
        finally:
            self._replaying = False
        return dataclasses.replace(update, new_piece=True)

    def _set_aside_held(self) -> None:
        """The held scans were outliers: set aside (:data:`OUTLIER`), the map untouched."""
        if self._held:
            self.scans_set_aside += len(self._held)
            count = self.set_aside_reasons.get(OUTLIER, 0) + len(self._held)
            self.set_aside_reasons[OUTLIER] = count
            self._held = []

    def _match(
        self,
        last: _Last,
        new: SegmentMap,
        view: LaserScanData,
        dt: float,
        after_held: bool = False,
    ) -> tuple[Attempt, bool]:
        """The placement of the new scan and whether to integrate it (:func:`match_scan`),
        against the references as they are now. ``after_held``: the scans since the last
        placed one are held (not placed); the robot is then found only where it can have
        driven at its own top speed (as a lost robot is in the pieces it left)."""
        config = self.config
        keyframe = last.anchor.keyframe
        motions, period, worth = self._predictions(dt)
        with self._lock:
            piece = self._pieces[keyframe]
            newest_first = sorted(self._poses, reverse=True)
            older = [k for k in newest_first if k != keyframe and self._pieces[k] == piece]
            older = older[: config.recent_keyframes]
            # Also the newest keyframes of the other pieces: a robot lost for a few scans (a
            # person in front of the laser) sees its old surroundings again.
            others = [k for k in newest_first if self._pieces[k] != piece]
            older += others[: config.recent_keyframes]
            left = self._left(last.stamp + dt, {self._pieces[k] for k in older} - {piece})
            references = References(
                here=self._placed_pose_unlocked(last.anchor),
                last=Reference(last.segments, last.view, last.anchor, last.stamp),
                keyframe=keyframe,
                older=older,
                poses={k: self._poses[k] for k in (keyframe, *older)},
                pieces={k: self._pieces[k] for k in (keyframe, *older)},
                scans={k: self._scans[k] for k in (keyframe, *older)},
                left=left,
                top_speed=self._top_speed(),
                elapsed=dt,
                period=period,
                own_speed_only=after_held,
                prior_support=worth,
            )
        recent = [k for k in older if references.pieces[k] == piece]
        local_map = self._local_maps.around(keyframe, recent, references, config)
        references = dataclasses.replace(references, local_map=local_map)
        self.last_attempts = []  # this scan's (a lost robot's held scans are matched in turn)
        chosen, integrated, tracked = match_scan(
            config,
            references,
            new,
            view,
            motions,
            len(motions) > 1,
            self._count,
            self._shapes,
            self.last_attempts,
        )
        self.scans_tracked += tracked
        return chosen, integrated

    def _predictions(self, dt: float) -> tuple[list[Pose], float | None, float | None]:
        """The constant-velocity prediction (when a velocity is known) and "did not move",
        from the last scan ``dt`` seconds before; the robot's usual scan period; and what the
        prediction is worth as a motion prior (metres of wall; None: not weighed)."""
        motions: list[Pose] = [(0.0, 0.0, 0.0)]
        predicted = self._motion.predict(dt)
        if predicted is not None:
            motions.insert(0, predicted)
        period = self._motion.period()
        if not self.config.motion_prior:
            return motions, period, None
        sigma = self._motion.prior_sigma(dt, period)
        return (
            motions,
            period,
            None if sigma is None else prior_support(sigma, self.config.wall_sigma),
        )

    def _known_view(self, pose: Pose, piece: int) -> Anchor | None:
        """The anchor on the nearest keyframe of ``piece`` within ``keyframe_distance`` and
        ``keyframe_angle`` of ``pose`` (None: none is; the scan would be a view the map
        lacks)."""
        config = self.config
        with self._lock:
            keys = [k for k, of in self._pieces.items() if of == piece]
            if not keys:
                return None
            poses = np.array([self._poses[k] for k in keys])
        moved = np.hypot(poses[:, 0] - pose[0], poses[:, 1] - pose[1])
        turned = np.abs(se2.wrap_angle(poses[:, 2] - pose[2]))
        near = (moved <= config.keyframe_distance) & (turned <= config.keyframe_angle)
        if not near.any():
            return None
        best = keys[int(np.argmin(np.where(near, moved, np.inf)))]
        return Anchor(best, se2.between(tuple(poses[keys.index(best)]), pose))

    def _new_keyframe(
        self,
        stamp: float,
        segments: SegmentMap,
        view: LaserScanData,
        anchor: Anchor,
        result: MatchResult,
        reference: SegmentMap,
    ) -> Anchor:
        """Make the scan a keyframe, with an edge to the keyframe its match started from. The
        edge's information is the match's (against ``reference``, the segments it was matched
        with: a later scan's are composed onto its keyframe with the same information, the
        scans in between being close)."""
        config = self.config
        information = match_information(
            reference,
            segments,
            result.T_1_2,
            pair_tolerance(config.integrate),
            config.wall_sigma,
            (config.edge_sigma_floor, config.edge_angle_floor),
            (10.0, 1.0),
        )
        T_keyframe_new = se2.compose(anchor.T_keyframe_scan, pose_of_match(result.T_1_2))
        index = len(self._scans)
        with self._lock:
            piece = self._pieces[anchor.keyframe]
            pose = se2.compose(self._poses[anchor.keyframe], T_keyframe_new)
        edge = Edge(anchor.keyframe, index, T_keyframe_new, information, robust=False)
        self._add_keyframe(KeyframeScan(index, stamp, segments.segments, view), pose, piece, edge)
        return Anchor(index, (0.0, 0.0, 0.0))

    def _start_piece(
        self,
        stamp: float,
        segments: SegmentMap,
        view: LaserScanData,
        reason: str,
        lost_from: LostFrom | None = None,
    ) -> LocalUpdate:
        """This scan starts a new piece of map (the first scan: the robot's map frame).
        ``lost_from``: the keyframe the robot was lost near and the guess of this scan's pose
        in its frame (the best match, not confident enough)."""
        index = len(self._scans)
        scan = KeyframeScan(index, stamp, segments.segments, view)
        self._add_keyframe(scan, (0.0, 0.0, 0.0), index, None, lost_from)
        anchor = Anchor(index, (0.0, 0.0, 0.0))
        self._last = _Last(stamp, segments, view, anchor)
        self._record(stamp, anchor)
        self._motion.reset()
        self.scans_accepted += 1
        if index > 0:
            self.pieces_started += 1
            self.set_aside_reasons[reason] = self.set_aside_reasons.get(reason, 0) + 1
        return LocalUpdate(True, (0.0, 0.0, 0.0), True, 1.0, reason, index, index > 0)

    def _add_keyframe(
        self,
        scan: KeyframeScan,
        pose: Pose,
        piece: int,
        edge: Edge | None,
        lost_from: LostFrom | None = None,
    ) -> None:
        with self._lock:
            self._scans[scan.index] = scan
            self._poses[scan.index] = pose
            self._pieces[scan.index] = piece
            self._queue.append((scan, pose, piece, edge, lost_from))
        if self._worker is not None:
            self._worker.wake()
        elif self.inline_backend:
            self.run_backend()

    def reconfigure(self, config: LocalMapperConfig) -> None:
        """New settings from the next scan and the next keyframe on; the map is kept."""
        self.config = config
        self.backend.reconfigure(config)
        if config.shape != self._shapes.config:
            self._shapes = Shapes(config.shape)
        self._motion.window = config.velocity_window

    # --- reading ----------------------------------------------------------------------------

    @property
    def map_segments(self) -> FloatArray:
        """The fused partial map of the main piece (:meth:`main_piece`), in its frame."""
        main = self.main_piece()
        pieces = [
            se2.transform_segments(se2.matrix_from_pose(*kf.T_robotmap_keyframe), kf.segments)
            for kf in self.keyframes()
            if kf.piece == main
        ]
        return np.vstack(pieces) if pieces else np.zeros((0, 4))

    def _top_speed(self) -> float | None:
        return self._motion.top_speed()

    def _left(self, stamp: float, pieces: set[int]) -> dict[int, tuple[Pose, float]]:
        """For each of ``pieces``: the pose of the robot's last scan placed in it (in its
        frame, which joins may have changed) and the seconds from then to ``stamp``."""
        left: dict[int, tuple[Pose, float]] = {}
        newest: dict[int, float] = {}
        for placed_stamp, anchor in self._last_in_piece.values():
            piece = self._pieces[anchor.keyframe]
            if piece in pieces and placed_stamp > newest.get(piece, -np.inf):
                newest[piece] = placed_stamp
                left[piece] = (self._placed_pose_unlocked(anchor), max(stamp - placed_stamp, 0.0))
        return left

    def _record(self, stamp: float, anchor: Anchor) -> None:
        """A scan placed on ``anchor``: counted on its keyframe, and remembered for the
        trajectory when asked."""
        self._last_in_piece[self._pieces[anchor.keyframe]] = (stamp, anchor)
        self._scans_at[anchor.keyframe] = self._scans_at.get(anchor.keyframe, 0) + 1
        if self._placed is not None:
            self._placed.append((stamp, anchor))

    def main_piece(self) -> int:
        """The piece holding the most placed scans (ties: the oldest)."""
        counts: dict[int, int] = {}
        with self._lock:
            for keyframe, scans in self._scans_at.items():
                piece = self._pieces[keyframe]
                counts[piece] = counts.get(piece, 0) + scans
        return min(counts, key=lambda p: (-counts[p], p)) if counts else 0

    def trajectory(self, piece: int | None = None) -> tuple[FloatArray, FloatArray]:
        """Stamps (N,) and poses (N, 3) of the placed scans of ``piece`` (default: the main
        piece), at the keyframes' current poses."""
        if self._placed is None:
            raise ValueError("this mapper does not keep its trajectory (trajectory=False)")
        chosen = self.main_piece() if piece is None else piece
        stamps, poses = [], []
        with self._lock:
            for stamp, anchor in self._placed:
                if self._pieces[anchor.keyframe] == chosen:
                    stamps.append(stamp)
                    poses.append(self._placed_pose_unlocked(anchor))
        return np.asarray(stamps, dtype=np.float64), np.asarray(poses).reshape(-1, 3)

    def anchors(self, piece: int | None = None) -> tuple[FloatArray, IntArray, FloatArray]:
        """Where the placed scans of ``piece`` (default: the main piece) are relative to their
        keyframes: stamps (N,), keyframe indices (N,) and ``T_keyframe_scan`` (N, 3). A merger
        that moves keyframes places the scans with them."""
        if self._placed is None:
            raise ValueError("this mapper does not keep its trajectory (trajectory=False)")
        chosen = self.main_piece() if piece is None else piece
        with self._lock:
            kept = [(s, a) for s, a in self._placed if self._pieces[a.keyframe] == chosen]
        return (
            np.array([s for s, _ in kept], dtype=np.float64),
            np.array([a.keyframe for _, a in kept], dtype=np.int64),
            np.array([a.T_keyframe_scan for _, a in kept], dtype=np.float64).reshape(-1, 3),
        )

    def _placed_pose(self, anchor: Anchor) -> Pose:
        return se2.compose(self._poses[anchor.keyframe], anchor.T_keyframe_scan)

    _placed_pose_unlocked = _placed_pose

    def _count(self, stage: str, seconds: float) -> None:
        self.stage_seconds[stage] = self.stage_seconds.get(stage, 0.0) + seconds
        self._scan_seconds[stage] = self._scan_seconds.get(stage, 0.0) + seconds

    def _set_aside(self, reason: str) -> LocalUpdate:
        self.scans_set_aside += 1
        self.set_aside_reasons[reason] = self.set_aside_reasons.get(reason, 0) + 1
        return LocalUpdate(False, None, False, 0.0, reason, self.piece)
