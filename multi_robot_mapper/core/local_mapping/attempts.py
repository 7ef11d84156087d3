"""The front end's match attempts: where a scan is anchored, one match of a new scan against
one reference scan, what its confidence means in the context it was made in
(:func:`in_context`), when two attempts corroborate each other, and the order in which a new
scan is matched (:func:`match_scan`)."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.context import (
    CONTEXT_FEATURES as CONTEXT_FEATURES,
)
from multi_robot_mapper.core.local_mapping.context import (
    CONTEXT_MODEL_FILE as CONTEXT_MODEL_FILE,
)
from multi_robot_mapper.core.local_mapping.context import CONTEXTS as CONTEXTS
from multi_robot_mapper.core.local_mapping.context import (
    ContextCalibration as ContextCalibration,
)
from multi_robot_mapper.core.local_mapping.context import (
    context_model_json as context_model_json,
)
from multi_robot_mapper.core.local_mapping.context import in_context as in_context
from multi_robot_mapper.core.local_mapping.context import (
    installed_context_model as installed_context_model,
)
from multi_robot_mapper.core.local_mapping.context import (
    load_context_model as load_context_model,
)
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeScan
from multi_robot_mapper.core.local_mapping.local_map import LocalMap
from multi_robot_mapper.core.matching import HEURISTICS, MatchResult, integrate
from multi_robot_mapper.core.matching.beams import Viewpoint
from multi_robot_mapper.core.matching.confidence import (
    LIKELY,
    LOOK_ALIKE_TURNS,
    RIGHT_ANGLE,
    RIGHT_DISTANCE,
    TRACK_TURNS,
)
from multi_robot_mapper.core.matching.integrate import hypotheses_of, pose_of_match
from multi_robot_mapper.core.matching.prior import MotionPrior
from multi_robot_mapper.core.matching.shape import Shapes, match_shapes
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.segment_map import MapLike, SegmentMap

FloatArray = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class Anchor:
    """Where a scan is: relative to a keyframe, so that its pose follows the graph."""

    keyframe: int
    T_keyframe_scan: Pose


# A tracked scan refined this close to its constant-velocity prediction needs no rivals: a
# third of the correctness tolerance.
NEAR = RIGHT_DISTANCE / 3.0
NEAR_ANGLE = RIGHT_ANGLE / 3.0
# A confident track far from its prediction is confirmed by a search, unless it is this sure:
# on every shared log cut into 4 robots (bench/track_near.py before this rule, b4c77be), the
# search changed whether the placement was right for 5 of 1 814 such tracks, all below 0.991,
# and for none of the 844 at 0.999 or more; it costs tens of milliseconds a scan. A
# prediction refined alone this sure needs no rivals within the whole tolerance either.
SURE = 0.999
# No robot turns faster than a full turn a second (ground robots that carry a laser turn at
# 1-5 rad/s): a placement in the robot's own piece turned more than this allows, plus the
# correctness tolerance, since the last placed scan (or in the robot's usual scan period when
# the stamps say less: a clock can lie) is a look-alike. Generated building 111:
# in a U-turn at 18 deg a scan, a search placed a scan -72 deg from the last (0.987 in
# context, a right-angle look-alike); the constant-velocity prediction carried it on and the
# next scan was tracked at 0.999 turned 180 deg, and the robot's map with it.
PLAUSIBLE_TURN_RATE = 2.0 * np.pi  # rad/s


def reach_in(top_speed: float, seconds: float) -> float:
    """How far the robot can have driven in ``seconds`` (m): at its ``top_speed`` (m/s, the
    95th percentile of its placed motions), plus the correctness tolerance."""
    return top_speed * seconds + RIGHT_DISTANCE


def close_to(a: Pose, b: Pose, distance: float, angle: float) -> bool:
    dx, dy, dtheta = se2.between(b, a)
    return bool(np.hypot(dx, dy) <= distance and abs(dtheta) <= angle)


@dataclasses.dataclass(frozen=True)
class Attempt:
    """One match of the new scan against one reference scan."""

    result: MatchResult
    anchor: Anchor  # where the reference scan is (its keyframe, and the offset from it)
    reference: SegmentMap  # the reference scan's segments
    pose: Pose  # the new scan's pose in the piece, by this match
    piece: int  # the reference's piece
    stage: str  # "track", "search" or "recent"
    context: str  # one of CONTEXTS
    confidence: float  # P(right) in its context (:func:`in_context` of the match's)
    reference_stamp: float  # when the reference scan was taken (s)


def corroborated(
    attempts: list[Attempt], reachable: Callable[[Attempt], bool] = lambda _: True
) -> Attempt | None:
    """The more confident of two attempts against different reference scans, each more likely
    right than wrong by its own evidence, that place the scan within the correctness
    tolerance of each other: wrong matches rarely agree on one placement from two scans
    (when they do, it is the same structure misleading both, and their confidence is low).
    "By its own evidence" is the match confidence, not the one in context: the two matches
    are of one scan in one situation, so their context's prior is shared, and counting it in
    each would count it twice (on fhw a search at 0.20, 0.57 in context, corroborated a
    look-alike 5 m and 98 deg off). ``reachable`` says whether the robot can have driven to
    an attempt's placement (:func:`match_scan`)."""
    likely = [a for a in attempts if a.result.confidence >= LIKELY and reachable(a)]
    for i, a in enumerate(likely):
        for b in likely[i + 1 :]:
            if a.anchor == b.anchor or a.piece != b.piece:
                continue  # the same reference scan (not independent), or unrelated frames
            dx, dy, dtheta = se2.between(a.pose, b.pose)
            if np.hypot(dx, dy) < RIGHT_DISTANCE and abs(dtheta) < RIGHT_ANGLE:
                return a if a.confidence >= b.confidence else b
    return None


def _turned_from_prediction(motion: Pose, predicted: Pose) -> bool:
    """Is ``motion`` turned from the prediction by more than a turn that starts between two
    scans (TRACK_TURNS) explains: refined from a quarter or half turn (LOOK_ALIKE_TURNS), or
    a prediction that carried a turn on after the robot stopped turning?"""
    # Such a placement contradicts the motion model however sure the match (a room of right
    # angles fits a quarter turn too): it is confirmed by the search with no guess. Generated
    # building 103: after a 0.5 s gap in robot1's scans mid-spin, the constant-velocity
    # prediction carried it +90 deg, a rival refined to a 90 deg look-alike at 0.9993 was
    # taken without the search, and the map turned (2 closures 90 deg off followed; 0 with
    # this rule).
    turn = abs(float(se2.wrap_angle(motion[2] - predicted[2])))
    return turn > max(TRACK_TURNS) + RIGHT_ANGLE


@dataclasses.dataclass(frozen=True)
class Reference:
    """A scan a new scan can be matched against, and where it is."""

    segments: SegmentMap
    view: LaserScanData
    anchor: Anchor
    stamp: float  # when it was taken (s)
    # several scans fused (a local map): where each was taken, in the reference's frame
    viewpoints: list[Viewpoint] | None = None

    def __post_init__(self) -> None:
        # Segments given as an array (an edge: tests, one-off callers) become a map once.
        object.__setattr__(self, "segments", SegmentMap.of(self.segments))

    @property
    def views(self) -> LaserScanData | list[Viewpoint]:
        """What its beams saw: its scan, or each fused scan where it was taken."""
        return self.view if self.viewpoints is None else self.viewpoints


@dataclasses.dataclass(frozen=True)
class References:
    """What the front end matches a new scan against, copied under the mapper's lock."""

    here: Pose  # the last placed scan's pose in its piece
    last: Reference  # the last placed scan
    keyframe: int  # its keyframe
    older: list[int]  # recent keyframes of its piece, then the newest of the other pieces
    poses: dict[int, Pose]  # of ``keyframe`` and ``older``, each in its piece
    pieces: dict[int, int]
    scans: dict[int, KeyframeScan]
    # piece -> (pose of the robot's last placed scan in it, seconds since), for the pieces
    # of ``older`` other than the current one
    left: dict[int, tuple[Pose, float]] = dataclasses.field(default_factory=dict)
    # how fast the robot drives at most (m/s; the 95th percentile of its placed motions)
    top_speed: float | None = None
    elapsed: float | None = None  # seconds from the last placed scan to the new one
    # the robot's usual seconds between placed scans (their median): how long a turn between
    # two scans may have taken when their stamps say less (a log's clock can repeat or step
    # back: intel's corrected log has 13 such steps, set 1 ms apart on import)
    period: float | None = None
    # the scans since the last placed one are held, not placed (core.local_mapping.held): in
    # its own piece too the robot is found only where its own top speed takes it
    own_speed_only: bool = False
    # metres of wall the constant-velocity prediction is worth as a motion prior along the
    # direction a tracked match cannot observe (core.matching.prior); None: not decisive
    prior_support: float | None = None
    # the keyframe with the recent keyframes of its piece, fused: what tracking matches
    # against (core.local_mapping.local_map; None: the keyframe alone)
    local_map: LocalMap | None = None


def match_scan(
    config: LocalMapperConfig,
    references: References,
    new: MapLike,
    view: LaserScanData,
    motions: list[Pose],
    tracking: bool,
    count: Callable[[str, float], None],
    shapes: Shapes | None = None,
    record: list[Attempt] | None = None,
) -> tuple[Attempt, bool, bool]:
    """The placement of the new scan, whether to integrate it, and whether it was tracked:
    against the last keyframe from the predictions ``motions`` (the constant-velocity one
    first, when ``tracking``: a velocity is known), else searched against the last scan, until
    one match reaches ``integrate_confidence``; else against the ``older`` keyframes, until two
    matches against different scans corroborate each other (:func:`corroborated`; in another
    piece than the robot's, only where it can have driven since it was last placed there).
    When none does, the most confident attempt the robot can have driven to is returned (the
    guess a new piece starts from). A search that is not confident is searched again with the
    shape matching's placements as more hypotheses (``shapes``, Wolter; None: never). Every
    decision reads an attempt's confidence in its context (:func:`in_context`).
    ``count(stage, seconds)`` is told where the time went; ``record`` (a list) receives every
    attempt kept."""
    attempts: list[Attempt] = record if record is not None else []
    matching = _ScanMatching(config, references, SegmentMap.of(new), view, count, shapes, attempts)
    if tracking:
        # Tracking needs a prediction: after a new piece starts nothing is known of the
        # motion, and "did not move" refined in a corridor stays where it started.
        tracked = matching.track(motions)
        if tracked is not None:
            return tracked
    return matching.search(motions)


class _ScanMatching:
    """The match attempts of one new scan (:func:`match_scan`): what it is matched against,
    every attempt kept so far, and whether two likely ones disagree."""

    def __init__(
        self,
        config: LocalMapperConfig,
        references: References,
        new: SegmentMap,
        view: LaserScanData,
        count: Callable[[str, float], None],
        shapes: Shapes | None,
        attempts: list[Attempt],
    ) -> None:
        self.config = config
        self.references = references
        self.new = new
        self.view = view
        self.count = count
        self.shapes = shapes
        self.attempts = attempts
        self.threshold = config.integrate_confidence
        self.current = references.pieces[references.keyframe]
        self.rivals_disagree = False
        self.searched: Attempt | None = None  # the search against the last scan, once made

    def attempt(
        self,
        stage: str,
        reference: Reference,
        search: bool,
        guesses_from_last: list[Pose],
        judge_near_prediction: bool = False,
    ) -> Attempt:
        """The new scan matched against ``reference`` from the predictions
        ``guesses_from_last`` (motions from the last placed scan; with ``search``,
        INTEGRATE's own hypotheses too, and the shapes' where that is not confident), kept
        with its confidence in context; the time it took counted. ``judge_near_prediction``:
        its confidence read only near the first prediction. A track's first prediction is a
        motion prior (:meth:`_motion_prior`)."""
        started = time.perf_counter()
        anchor = reference.anchor
        guesses = self._predictions(anchor, guesses_from_last)
        result = integrate(
            reference.segments,
            self.new,
            self.config.integrate,
            heuristics=HEURISTICS if search else (),
            extra_hypotheses=hypotheses_of(guesses),
            views=(reference.views, self.view),
            judged=(
                (lambda T: close_to(pose_of_match(T), guesses[0], RIGHT_DISTANCE, RIGHT_ANGLE))
                if judge_near_prediction
                else None
            ),
            prior=self._motion_prior(guesses[0]) if stage == "track" else None,
        )
        checked = result.seconds.get("confidence", 0.0)
        shaping = 0.0
        piece = self.references.pieces[anchor.keyframe]
        context = "other" if piece != self.current else stage
        if (
            search
            and self.shapes is not None
            and in_context(result.confidence, context) < self.threshold
        ):
            result, shaping = self._shaped(self.shapes, reference, guesses, result)
        T_keyframe_new = se2.compose(anchor.T_keyframe_scan, pose_of_match(result.T_1_2))
        done = Attempt(
            result,
            anchor,
            reference.segments,
            se2.compose(self.references.poses[anchor.keyframe], T_keyframe_new),
            piece,
            stage,
            context,
            in_context(result.confidence, context),
            reference.stamp,
        )
        self.attempts.append(done)
        self.count(stage, time.perf_counter() - started - checked - shaping)
        self.count("confidence", checked)
        if shaping:
            self.count("shape", shaping)
        return done

    def _motion_prior(self, predicted: Pose) -> MotionPrior | None:
        """The prediction ``predicted`` (in the reference's frame) as a motion prior, where it
        is decisive (``prior_support``)."""
        support = self.references.prior_support
        if support is None:
            return None
        return MotionPrior(hypotheses_of([predicted])[0], support, self.config.wall_sigma)

    def _predictions(self, anchor: Anchor, motions: list[Pose]) -> list[Pose]:
        """The new scan's predicted placements in the frame of the reference scan at
        ``anchor``: ``motions`` from the last placed scan."""
        poses = self.references.poses
        # The predictions, from the reference's frame.
        T_ref_last = se2.between(
            se2.compose(poses[anchor.keyframe], anchor.T_keyframe_scan), self.references.here
        )
        return [se2.compose(T_ref_last, m) for m in motions]

    def _shaped(
        self, shapes: Shapes, reference: Reference, guesses: list[Pose], result: MatchResult
    ) -> tuple[MatchResult, float]:
        """The search ``result`` searched again with the shape matching's placements as more
        hypotheses: the more confident of the two, and the seconds it took."""
        # A search that is not confident is searched again with Wolter's shape matching
        # as a second source of hypotheses: its polylines keep clusters too small for
        # segments. Only then: a confident search keeps the hypotheses its confidence
        # was calibrated on.
        shaped = time.perf_counter()
        found = match_shapes(shapes(reference.view), shapes(self.view), shapes.config)
        shaped_result = integrate(
            reference.segments,
            self.new,
            self.config.integrate,
            heuristics=HEURISTICS,
            extra_hypotheses=hypotheses_of(guesses + list(found.alternatives)),
            views=(reference.view, self.view),
        )
        if shaped_result.confidence > result.confidence:
            result = shaped_result
        return result, time.perf_counter() - shaped

    def reachable(self, a: Attempt) -> bool:
        """Can the robot have driven to the placement of ``a`` since it was last placed (in
        its own piece, or in another where it was last placed there), and in its own piece
        turned to it (PLAUSIBLE_TURN_RATE)? In another piece, not once the scan has matched
        its own piece likely where the robot cannot be (:meth:`_fooled`), nor more surely where
        it can (:meth:`_outmatched_at_home`)."""
        if a.piece != self.current and (self._fooled() or self._outmatched_at_home(a)):
            return False
        return self._driven_to(a)

    def _outmatched_at_home(self, a: Attempt) -> bool:
        """Does the robot's own piece match the scan, where the robot can be, more surely than
        ``a`` matches it in another piece?"""
        # Then the move has a better-supported rival at home: the scan is held. Generated
        # building 119, robot3 scan 1019: its own keyframe 160 matched it at 0.98, right (an
        # older keyframe settles nothing alone), two keyframes of another piece agreed at 0.93,
        # 8.3 m and 90 deg off, and it moved there (4 wrong closures followed). Building 110's
        # robot2, going back right to the piece it had left, matched its own at 0.74: moved.
        return any(
            b.piece == self.current
            and b.result.confidence >= max(LIKELY, a.result.confidence)
            and self._driven_to(b)
            for b in self.attempts
        )

    def _fooled(self) -> bool:
        """Has the scan matched the robot's own piece likely where the robot cannot be?"""
        # Then the scan fools matching (a look-alike of where the robot is), and a move to
        # another piece, which no motion bounds in heading (nor in position but by the reach
        # of the seconds since it left there), has only such matches to vouch for it: the
        # scan is held, and the back end joins the pieces on the evidence of their windows.
        # Generated building 119 (a hall of pillars, 90 deg look-alikes): the front end moved
        # its robots between pieces 7 times, all wrong (8-16 m or 90-180 deg off; two maps
        # turned 90 deg, 8 wrong loop closures on them), 6 of them with such a match: robot1
        # scan 655, tracked at 0.999 the scan before, matched its own keyframes at
        # 0.96-0.998 turned 81 deg in 0.1 s, and two keyframes of the piece it had left 20 s
        # before at 0.998 and 0.997, 11.4 m and 90 deg off. A likely match where the robot
        # can be stops the move only when surer (:meth:`_outmatched_at_home`): building 110's
        # robot2 went back to the piece it had left 12.6 s before, right, its own piece's 0.74.
        return any(
            a.piece == self.current and a.result.confidence >= LIKELY and not self._driven_to(a)
            for a in self.attempts
        )

    def _driven_to(self, a: Attempt) -> bool:
        """:meth:`reachable`, by the robot's motion alone."""
        # In its own piece, the robot is no farther from its last placed scan than it drives
        # at ``plausible_speed`` (or its own top speed, when faster) in the time since, plus
        # the correctness tolerance: a scan of another place or of another building can match
        # the last scan confidently metres away (a corridor seen from elsewhere in it), a
        # jump no robot makes between two scans. Right after held scans (an anomaly: the next
        # scan is matched across their gap) and in another piece (the placement puts the
        # robot back where it was when it got lost there), no farther than its own top speed
        # takes it: two attempts against neighbouring keyframes of one look-alike place agree
        # as well as two right ones (intel: 7.2 m off at 0.64 and 0.76; intel 4 robot1, after
        # a held scan: 7.2 m off at 0.92).
        references = self.references
        top_speed = references.top_speed
        if a.piece == self.current and references.elapsed is not None:
            pose, elapsed = references.here, references.elapsed
            if not (references.own_speed_only and top_speed is not None):
                top_speed = max(top_speed or 0.0, self.config.plausible_speed)
        elif a.piece != self.current and top_speed is not None and a.piece in references.left:
            pose, elapsed = references.left[a.piece]
        else:
            return True
        reach = reach_in(top_speed, elapsed)
        if np.hypot(a.pose[0] - pose[0], a.pose[1] - pose[1]) > reach:
            return False
        if a.piece != self.current:
            return True  # back where it was lost: it may have turned any way since
        turn = abs(float(se2.wrap_angle(a.pose[2] - pose[2])))
        turning = max(elapsed, references.period or 0.0)
        return turn <= PLAUSIBLE_TURN_RATE * turning + RIGHT_ANGLE

    def settled(self) -> Attempt | None:
        """The attempt that settles the placement, if one does yet."""
        # A match against the last keyframe or the last scan settles it alone; one against an
        # older keyframe (tried because those failed: the best of several tries), or any
        # match once two likely ones disagree, only with another match that corroborates it.
        if self.rivals_disagree:
            return corroborated(self.attempts, self.reachable)
        recent = [a for a in self.attempts if a.stage != "recent" and self.reachable(a)]
        best = max(recent, key=lambda a: a.confidence, default=None)
        if best is not None and best.confidence >= self.threshold:
            return best
        return corroborated(self.attempts, self.reachable)

    def keyframe_reference(self, keyframe: int) -> Reference:
        """A keyframe's scan as a reference."""
        scan = self.references.scans[keyframe]
        return Reference(scan.segment_map, scan.view, Anchor(keyframe, (0.0, 0.0, 0.0)), scan.stamp)

    def tracked_against(self) -> Reference:
        """The last keyframe's scan, or the local map around it where there is one."""
        start = self.keyframe_reference(self.references.keyframe)
        local = self.references.local_map
        if local is None:
            return start
        return dataclasses.replace(start, segments=local.segment_map, viewpoints=local.viewpoints)

    def track(self, motions: list[Pose]) -> tuple[Attempt, bool, bool] | None:
        """The placement tracked from the predictions (:meth:`tracked_against`), when the
        motion model and the match agree (or a likely search does not disagree); None when
        tracking settles nothing (the search goes on, :meth:`search`)."""
        here = self.references.here
        start = self.tracked_against()
        # A fast laser's prediction is good: refined alone, it lands next to it. When it lands
        # farther, or is not confident, it is refined again with rivals a wrong minimum cannot
        # hide from: turned either way (a turn that starts between two scans is the usual
        # miss), and a quarter and a half turn (a room of right angles fits those ways too:
        # the look-alike's rival, or the right answer when the prediction found the look-alike).
        # Its confidence is read only within the tolerance of the prediction: beyond it the
        # placement is discarded whatever its confidence (most scans that need the rivals).
        quick = self.attempt("track", start, False, motions[:1], judge_near_prediction=True)
        # A sure one settles anywhere within the tolerance: on every shared log cut into 4
        # robots (bench/track_near.py, its fourth table) the 1 599 sure ones there were all
        # right; the 0.81 that stayed 17 deg off on aces (below) is far from sure.
        near = (NEAR, NEAR_ANGLE) if quick.confidence < SURE else (RIGHT_DISTANCE, RIGHT_ANGLE)
        if (
            quick.confidence >= self.threshold
            and close_to(se2.between(here, quick.pose), motions[0], *near)
            and self.reachable(quick)
        ):
            return quick, True, True
        self.attempts.remove(quick)
        x, y, theta = motions[0]
        rivals = [(x, y, theta + d) for d in (*TRACK_TURNS, *LOOK_ALIKE_TURNS) if d]
        track = self.attempt("track", start, False, motions + rivals)
        if track.confidence >= self.threshold and self.reachable(track):
            motion = se2.between(here, track.pose)
            if close_to(motion, motions[0], RIGHT_DISTANCE, RIGHT_ANGLE) or (
                track.confidence >= SURE and not _turned_from_prediction(motion, motions[0])
            ):
                # No rival moved it out of the correctness tolerance of the prediction: the
                # motion model and the match agree, and a search would only cost time.
                # Measured on every shared log cut into 4 robots (bench/track_near.py): 1917
                # of 1917 such placements were right, 1802 of 1813 beyond the tolerance.
                # Without the rivals a prediction refined alone stayed 17 deg off on aces
                # (README "Local mapping", front end). Or it is sure (``SURE``).
                return track, True, True
            # Far from the prediction, the placement may be a look-alike the prediction led
            # to: the search with no guess confirms it, or finds a likely rival, and then
            # neither settles alone.
            search = (
                self.searched
                if self.searched is not None
                else self.attempt("search", self.references.last, True, motions)
            )
            self.searched = search
            self.rivals_disagree = (
                search.confidence >= LIKELY
                and self.reachable(search)
                and not close_to(search.pose, track.pose, RIGHT_DISTANCE, RIGHT_ANGLE)
            )
            if not self.rivals_disagree:
                return track, True, True
        elif (done := self.settled()) is not None:
            return done, True, True
        return None

    def search(self, motions: list[Pose]) -> tuple[Attempt, bool, bool]:
        """The placement searched against the last scan (unless tracking searched already),
        then against the older keyframes, until one settles it; else the guess a new piece
        starts from, not to be integrated."""
        if self.searched is None:
            self.attempt("search", self.references.last, True, motions)
        if (done := self.settled()) is not None:
            return done, True, False
        for k in self.references.older:
            self.attempt("recent", self.keyframe_reference(k), True, motions)
            if (done := self.settled()) is not None:
                return done, True, False
        # The guess a new piece starts from: the most confident placement the robot can have
        # driven to (a look-alike far off misleads the join's search).
        guesses = [a for a in self.attempts if self.reachable(a)] or self.attempts
        return max(guesses, key=lambda a: a.confidence), False, False
