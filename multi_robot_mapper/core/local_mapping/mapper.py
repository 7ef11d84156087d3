"""Odometry-free local mapping: one robot's scans in, its segment partial map out.

Frames: ``robotmap`` is the robot's own map frame (the laser frame of its first accepted
scan); ``T_robotmap_laser`` places a scan in it. Each new scan is matched by INTEGRATE against
the partial map near the robot's last pose, with the constant-velocity prediction as one more
hypothesis (never a requirement). A scan the last scan cannot place is searched on the partial
map around the last pose, within reach of it. A scan whose best transformation fails the
validity threshold is set aside and counted: a wrong integration is worse than a missing one.
Scans that moved more than ``keyframe_distance`` or turned more than ``keyframe_angle`` since the
last keyframe become keyframes and are fused into the partial map (Amigoni Alg. 5).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import SegmentScan
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.geometry import point_segment_distance
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.matching import (
    HEURISTICS,
    MatchResult,
    best_prescreened,
    cross_support,
    distinct_hypotheses,
    endpoint_hypotheses,
    hypotheses,
    integrate,
    landmarks,
    lines_of,
    refine,
)
from multi_robot_mapper.core.scan import LaserScanData

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
Pose = tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class Keyframe:
    """One keyframe of the partial map: its pose and the map segments it owns (own frame)."""

    index: int
    stamp: float
    T_robotmap_keyframe: FloatArray  # (3,) x, y, theta
    segments: FloatArray  # (N, 4) in the keyframe's frame


@dataclasses.dataclass(frozen=True)
class LocalUpdate:
    """What one scan did to the partial map."""

    accepted: bool
    pose: Pose | None  # T_robotmap_laser of this scan when accepted
    keyframe_added: bool
    value: float  # overlap length of the accepted match (m); 0 for the first scan
    fraction: float  # net value / shorter set's length
    reason: str  # why a scan was set aside ("" when accepted)
    restarted: bool = False  # the map started again at this scan: earlier poses are void


class LocalMapper:
    """One robot's partial map, built scan by scan with no odometry.

    ``add_scan`` is the whole method (the node, ``mrm replay`` and the benches call it):
    predict, track, search when tracking fails, accept or set aside, fuse keyframes.
    """

    def __init__(self, config: LocalMapperConfig | None = None) -> None:
        self.config = config if config is not None else LocalMapperConfig()
        self.pose: Pose | None = None  # T_robotmap_laser of the newest accepted scan
        self.stamp: float | None = None
        self.version = 0  # bumped whenever the partial map changes
        self.scans_accepted = 0
        self.scans_set_aside = 0
        self.scans_tracked = 0  # accepted from the prediction alone, without a global search
        self.scans_on_submap = 0  # placed by a match against the partial map, not the last scan
        self.set_aside_reasons: dict[str, int] = {}
        self._map_segments = np.zeros((0, 4))  # fused partial map, robotmap frame
        self._map_owner = np.zeros(0, dtype=np.int64)  # keyframe index owning each segment
        self._keyframe_poses: list[FloatArray] = []
        self._keyframe_stamps: list[float] = []
        self._last_segments = np.zeros((0, 4))  # newest accepted scan, its own frame
        self._last_view: LaserScanData | None = None
        self._velocity: FloatArray | None = None  # T_prev_last per second (x, y, theta)
        # The newest set-aside scan and its best (invalid) T_last_pending, while no scan since
        # was accepted: the next scan's motion through it is one more hypothesis.
        self._pending: tuple[FloatArray, LaserScanData, FloatArray, bool] | None = None
        self._cross_memo: tuple[MatchResult, FloatArray, FloatArray, float] | None = None

    # --- the method -------------------------------------------------------------------------

    def add_scan(self, stamp: float, segments: SegmentScan, view: LaserScanData) -> LocalUpdate:
        """Place one scan (its segments and the scan they came from) and extend the map."""
        new = np.asarray(segments.segments, dtype=np.float64).reshape(-1, 4)
        new = new[np.isfinite(new).all(axis=1)]  # a NaN would never fuse nor leave the map
        integrate_config = self.config.integrate
        if float(lines_of(new).length.sum()) < integrate_config.min_match_value:
            return self._set_aside("too little structure in the scan")
        if self.pose is None:  # the first scan defines the robot's map frame
            return self._start(stamp, new, view)
        assert self.stamp is not None
        T_robotmap_last = np.asarray(self.pose, dtype=np.float64)
        dt = max(stamp - self.stamp, 0.0)
        predictions = [np.zeros(3)]  # "did not move" is always worth a look
        if self._velocity is not None:
            predictions.insert(0, _scaled_motion(self._velocity, dt))
        last = self._last_segments
        views = (self._last_view, view)
        # Tracking: the predictions alone, refined and judged against the last scan; accepted
        # without a search when they explain most of the scan (every scan of a fast laser).
        result = integrate(
            last,
            new,
            integrate_config,
            heuristics=(),
            extra_hypotheses=_as_hypotheses(predictions),
            views=views,
        )
        if self._passes(last, new, result) and result.fraction >= self.config.tracking_fraction:
            self.scans_tracked += 1
        else:
            # INTEGRATE with no guess between the last scan and the new one (both scans' free
            # space known); the predictions stay candidates.
            searched = integrate(
                last,
                new,
                integrate_config,
                extra_hypotheses=_as_hypotheses(predictions),
                views=views,
            )
            if searched.fraction > result.fraction or not self._passes(last, new, result):
                result = searched
        accepted = self._passes(last, new, result)
        if not accepted and self._pending is not None:
            result, accepted = self._through_pending(last, new, view, result)
        if not accepted and self.config.submap_reach > 0.0:
            result, accepted = self._on_submap(T_robotmap_last, new, view, result)
        if accepted:
            # Hold drift down: pull the scan onto the partial map around it (Cox least
            # squares), unless that moves it far from what the scans agreed on.
            result = self._refined_on_map(T_robotmap_last, new, result)
        else:
            if self.scans_accepted == 1:
                # A start that no second scan confirms is not a map (a poor first scan would
                # otherwise hold the robot forever): start again from this scan.
                self.scans_accepted = 0
                self.set_aside_reasons["start not confirmed"] = (
                    self.set_aside_reasons.get("start not confirmed", 0) + 1
                )
                self.scans_set_aside += 1
                return self._start(stamp, new, view)
            # Only a match that failed on cross support alone (a corridor) may be bridged.
            plausible = self._passes(last, new, result, cross=0.0)
            self._pending = (new, view, _pose_triple(result.T_1_2), plausible)
            return self._set_aside("no valid match", result.value, result.fraction)
        T_last_new = _pose_triple(result.T_1_2)
        T_robotmap_new = se2.pose_from_matrix(
            se2.matrix_from_pose(*T_robotmap_last) @ se2.matrix_from_pose(*T_last_new)
        )
        motion = T_last_new / dt if dt > 0.0 else None
        keyframe = self._accept(stamp, new, view, np.asarray(T_robotmap_new), motion)
        return LocalUpdate(
            True,
            (float(T_robotmap_new[0]), float(T_robotmap_new[1]), float(T_robotmap_new[2])),
            keyframe,
            result.value,
            result.fraction,
            "",
        )

    def _start(self, stamp: float, new: FloatArray, view: LaserScanData) -> LocalUpdate:
        """(Re)start the map at this scan: it becomes keyframe 0 and the map frame."""
        restart = self.pose is not None
        self._map_segments = np.zeros((0, 4))
        self._map_owner = np.zeros(0, dtype=np.int64)
        self._keyframe_poses, self._keyframe_stamps = [], []
        self._velocity = None
        self.pose = None
        self._accept(stamp, new, view, np.zeros(3), None)
        return LocalUpdate(True, (0.0, 0.0, 0.0), True, 0.0, 1.0, "", restarted=restart)

    def _through_pending(
        self, last: FloatArray, new: FloatArray, view: LaserScanData, result: MatchResult
    ) -> tuple[MatchResult, bool]:
        """After a set-aside scan P: the motion last -> P -> new, and whether it is accepted.

        Accepted when the new scan validly matches P and P's own match with the last scan
        failed on cross support alone (a corridor, where the offset along the walls rests on
        free space): one weak link is bridged by a strong one, instead of losing the robot
        for good as it drives out of the last scan's view. Otherwise the composed motion is
        only one more candidate, judged against the last scan like any other.
        """
        assert self._pending is not None
        segments_p, view_p, T_last_pending, plausible = self._pending
        via = integrate(segments_p, new, self.config.integrate, views=(view_p, view))
        if not self._passes(segments_p, new, via):
            return result, False
        composed = _compose(T_last_pending, _pose_triple(via.T_1_2))
        if plausible:
            return dataclasses.replace(via, T_1_2=_as_hypotheses([composed])[0]), True
        judged = integrate(
            last,
            new,
            self.config.integrate,
            heuristics=(),
            extra_hypotheses=_as_hypotheses([composed]),
            views=(self._last_view, view),
        )
        best = judged if judged.fraction > result.fraction else result
        return best, self._passes(last, new, best)

    def _on_submap(
        self, T_robotmap_last: FloatArray, new: FloatArray, view: LaserScanData, result: MatchResult
    ) -> tuple[MatchResult, bool]:
        """INTEGRATE of a scan the last scan could not place against the partial map around
        the last pose; returns the result to use and whether the scan is accepted.

        A scan that overlaps the last one little (a turn, a door, a set-aside scan before it)
        is where the mapper loses the robot, although the map behind it holds the walls it
        sees: on aces 9 scans in a row were set aside whose true pose explains 25-36 % of
        them on the map, and each set-aside scan makes the next match harder. The map lies
        in the last scan's frame, so both scans' free space applies; the scan-to-scan result
        stays a hypothesis. The map has far more walls to overlap by chance than one scan,
        and every wrong map match on the logs jumped metres or turned half round (a symmetric
        corridor): the result must stay within ``submap_reach`` / ``submap_turn`` of the last
        scan.
        """
        reference = self._submap(T_robotmap_last)
        if len(reference) < 2:
            return result, False
        candidates = np.vstack(
            (
                _as_hypotheses([_pose_triple(result.T_1_2)]),
                self._hypotheses_in_reach(reference, new),
            )
        )
        on_map = integrate(
            reference,
            new,
            self.config.integrate,
            heuristics=(),
            extra_hypotheses=candidates,
            views=(self._last_view, view),
        )
        theta, tx, ty = (float(v) for v in on_map.T_1_2)
        if (
            float(np.hypot(tx, ty)) > self.config.submap_reach
            or abs(float(se2.wrap_angle(theta))) > self.config.submap_turn
            or not self._passes(reference, new, on_map)
        ):
            return result, False
        self.scans_on_submap += 1
        return on_map, True

    def _hypotheses_in_reach(self, reference: FloatArray, new: FloatArray) -> FloatArray:
        """INTEGRATE's hypotheses (Alg. 2 and the heuristics) of the scan on the map, only
        those within ``submap_reach`` / ``submap_turn`` of the last scan, the
        ``candidate_pool`` best by the prescreen value: the search of :func:`integrate`
        restricted to where the robot can be, so that a far, wrong match that happens to
        overlap more cannot hide a right one nearby."""
        config = self.config.integrate
        rng = np.random.default_rng(config.seed)
        # The map's segments are in no scan order: no consecutive pairs on that side.
        marks1 = landmarks(reference, HEURISTICS, config, False, rng)
        marks2 = landmarks(new, HEURISTICS, config, True, rng) if len(new) > 1 else None
        raw = [endpoint_hypotheses(reference, new, config)]
        if marks2 is not None:
            raw.append(hypotheses(reference, marks1, new, marks2, config))
        transforms, _ = distinct_hypotheses(
            np.vstack(raw),
            config.hypothesis_angle_cell,
            config.hypothesis_distance_cell,
            config.max_hypotheses,
        )
        reach = (np.hypot(transforms[:, 1], transforms[:, 2]) <= self.config.submap_reach) & (
            np.abs(se2.wrap_angle(transforms[:, 0])) <= self.config.submap_turn
        )
        transforms = transforms[reach]
        best = best_prescreened(
            reference, new, transforms, config.candidate_pool, config.prescreen_segments, config
        )
        return np.asarray(transforms[best], dtype=np.float64).reshape(-1, 3)

    def _refined_on_map(
        self, T_robotmap_last: FloatArray, new: FloatArray, result: MatchResult
    ) -> MatchResult:
        """``result`` refined on the submap around the last pose (no free space: the map holds
        walls the last scan never saw), kept only within ``map_refine_limit``."""
        reference = self._submap(T_robotmap_last)
        if len(reference) < 2:
            return result
        refined = refine(reference, new, result.T_1_2, self.config.integrate)
        shift = refined - result.T_1_2
        if (
            float(np.hypot(shift[1], shift[2])) > self.config.map_refine_limit
            or abs(float(se2.wrap_angle(shift[0]))) > self.config.map_refine_limit
        ):
            return result
        return dataclasses.replace(result, T_1_2=refined)

    def snapshot(self) -> dict[str, object]:
        """The mapper's state (containers and arrays copied one level deep, cheap: a few
        arrays and lists), so a caller can undo a scan that failed half-way."""
        return {
            name: value.copy() if isinstance(value, (list, dict, set, np.ndarray)) else value
            for name, value in vars(self).items()
        }

    def restore(self, saved: dict[str, object]) -> None:
        """Put back a :meth:`snapshot`."""
        vars(self).clear()
        vars(self).update(saved)

    # --- the partial map --------------------------------------------------------------------

    @property
    def map_segments(self) -> FloatArray:
        """The fused partial map, (M, 4) in the robot's map frame."""
        return self._map_segments.copy()

    def keyframes(self) -> list[Keyframe]:
        """Every keyframe with the map segments it owns, in its own frame."""
        frames = []
        order = np.argsort(self._map_owner, kind="stable")
        bounds = np.searchsorted(
            self._map_owner[order], np.arange(len(self._keyframe_poses) + 1), side="left"
        )
        for index, T_robotmap_keyframe in enumerate(self._keyframe_poses):
            owned = self._map_segments[order[bounds[index] : bounds[index + 1]]]
            T_keyframe_robotmap = se2.invert(se2.matrix_from_pose(*T_robotmap_keyframe))
            frames.append(
                Keyframe(
                    index,
                    self._keyframe_stamps[index],
                    T_robotmap_keyframe.copy(),
                    se2.transform_segments(T_keyframe_robotmap, owned),
                )
            )
        return frames

    # --- steps ------------------------------------------------------------------------------

    def _near(self, T_robotmap_laser: FloatArray, radius: float | None = None) -> BoolArray:
        """Which map segments pass within ``radius`` (default ``submap_radius``) of the laser."""
        segments = self._map_segments
        x, y = float(T_robotmap_laser[0]), float(T_robotmap_laser[1])
        distance = point_segment_distance(
            np.full(len(segments), x),
            np.full(len(segments), y),
            segments[:, 0],
            segments[:, 1],
            segments[:, 2],
            segments[:, 3],
        )
        limit = self.config.submap_radius if radius is None else radius
        return np.asarray(distance <= limit)

    def _submap(self, T_robotmap_last: FloatArray) -> FloatArray:
        """Map segments within ``submap_radius`` of the last pose, in the last scan's frame."""
        near = self._map_segments[self._near(T_robotmap_last)]
        T_last_robotmap = se2.invert(se2.matrix_from_pose(*T_robotmap_last))
        return se2.transform_segments(T_last_robotmap, near)

    def _accept(
        self,
        stamp: float,
        segments: FloatArray,
        view: LaserScanData,
        T_robotmap_new: FloatArray,
        motion: FloatArray | None,
    ) -> bool:
        """Record an accepted scan; fuse it into the map when it is a keyframe."""
        self.scans_accepted += 1
        self.pose = (float(T_robotmap_new[0]), float(T_robotmap_new[1]), float(T_robotmap_new[2]))
        self.stamp = stamp
        self._last_segments, self._last_view = segments, view
        self._pending = None
        if motion is not None:
            self._velocity = motion
        if self._keyframe_poses:
            last = self._keyframe_poses[-1]
            moved = float(np.hypot(*(T_robotmap_new[:2] - last[:2])))
            turned = abs(float(se2.wrap_angle(T_robotmap_new[2] - last[2])))
            if moved <= self.config.keyframe_distance and turned <= self.config.keyframe_angle:
                return False
            if self.config.revisit_keyframes and self._near_keyframe(T_robotmap_new):
                return False
        index = len(self._keyframe_poses)
        self._keyframe_poses.append(T_robotmap_new.copy())
        self._keyframe_stamps.append(stamp)
        placed = se2.transform_segments(se2.matrix_from_pose(*T_robotmap_new), segments)
        self._fuse(placed, index, T_robotmap_new)
        self.version += 1
        return True

    def _near_keyframe(self, T_robotmap_new: FloatArray) -> bool:
        """Whether some keyframe (not only the last) lies within ``keyframe_distance`` and
        ``keyframe_angle`` of this pose: ground the map already holds from here."""
        poses = np.asarray(self._keyframe_poses, dtype=np.float64)
        moved = np.hypot(poses[:, 0] - T_robotmap_new[0], poses[:, 1] - T_robotmap_new[1])
        turned = np.abs(se2.wrap_angle(poses[:, 2] - T_robotmap_new[2]))
        near = (moved <= self.config.keyframe_distance) & (turned <= self.config.keyframe_angle)
        return bool(near.any())

    def _fuse(self, placed: FloatArray, index: int, T_robotmap_new: FloatArray) -> None:
        """Alg. 5 between the map near the new keyframe and the keyframe's segments."""
        segments, owner = self._map_segments, self._map_owner
        # Candidates: map segments near any placed one (the laser sees beyond submap_radius).
        reach = float(
            np.hypot(placed[:, 0::2] - T_robotmap_new[0], placed[:, 1::2] - T_robotmap_new[1]).max(
                initial=0.0
            )
        )
        near = self._near(T_robotmap_new, max(self.config.submap_radius, reach) + 0.5)
        fused, fused_owner = fuse(
            segments[near],
            owner[near],
            placed,
            np.full(len(placed), index, dtype=np.int64),
            self.config.integrate,
            self.config.fusion_tolerance,
        )
        self._map_segments = np.vstack((segments[~near], fused))
        self._map_owner = np.concatenate((owner[~near], fused_owner))

    def _passes(
        self,
        reference: FloatArray,
        new: FloatArray,
        result: MatchResult,
        cross: float | None = None,
    ) -> bool:
        """The validity threshold of a scan against a reference (``min_match_fraction``,
        ``min_cross_support`` unless ``cross`` replaces it)."""
        needed = self.config.min_cross_support if cross is None else cross
        return (
            result.value >= self.config.integrate.min_match_value
            and result.fraction >= self.config.min_match_fraction
            and self._cross_support(reference, new, result) >= needed
        )

    def _cross_support(self, reference: FloatArray, new: FloatArray, result: MatchResult) -> float:
        """``cross_support`` of a result, computed once: one scan asks it of the same result
        up to four times (tracking, search, gate, bridge)."""
        memo = self._cross_memo
        if memo is not None and memo[0] is result and memo[1] is reference and memo[2] is new:
            return memo[3]
        support = cross_support(reference, new, result.T_1_2, self.config.integrate)
        self._cross_memo = (result, reference, new, support)
        return support

    def _set_aside(self, reason: str, value: float = 0.0, fraction: float = 0.0) -> LocalUpdate:
        self.scans_set_aside += 1
        self.set_aside_reasons[reason] = self.set_aside_reasons.get(reason, 0) + 1
        return LocalUpdate(False, None, False, value, fraction, reason)


def _scaled_motion(velocity: FloatArray, dt: float) -> FloatArray:
    """The constant-velocity prediction of the motion since the last scan."""
    return np.asarray(velocity * dt, dtype=np.float64)


def _compose(T_a_b: FloatArray, T_b_c: FloatArray) -> FloatArray:
    """T_a_c of two (x, y, theta) motions."""
    composed = se2.pose_from_matrix(se2.matrix_from_pose(*T_a_b) @ se2.matrix_from_pose(*T_b_c))
    return np.asarray(composed, dtype=np.float64)


def _as_hypotheses(motions: list[FloatArray]) -> FloatArray:
    """(x, y, theta) motions as INTEGRATE hypotheses (theta, tx, ty)."""
    stacked = np.asarray(motions, dtype=np.float64).reshape(-1, 3)
    return np.column_stack((stacked[:, 2], stacked[:, 0], stacked[:, 1]))


def _pose_triple(T_1_2: FloatArray) -> FloatArray:
    """INTEGRATE's (theta, tx, ty) as an (x, y, theta) pose."""
    return np.array([T_1_2[1], T_1_2[2], T_1_2[0]], dtype=np.float64)
