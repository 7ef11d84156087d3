"""Keyframe windows matched against each other: what local edges, loop closures and joins
share (:class:`WindowMatcher`), and what a closure or a join records (:class:`Closure`).

A window is a keyframe and its nearest neighbours in time in its piece, their scans fused in
the keyframe's frame: a window sees more of a place than one scan, and its matches are surer
(README, "Match confidence": window pairs).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.local_mapping.attempts import hypotheses_of, pose_of_match
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeMap
from multi_robot_mapper.core.matching import HEURISTICS, MatchResult, integrate
from multi_robot_mapper.core.matching.beams import Viewpoint
from multi_robot_mapper.core.matching.confidence import TRACK_TURNS
from multi_robot_mapper.core.matching.refine import match_information
from multi_robot_mapper.core.pose_graph import Edge, PoseGraph

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Pose = tuple[float, float, float]

# Keyframes per window matched for loop closures and joins: the keyframe and its nearest
# neighbours in time (the confidence is calibrated on windows of three scans).
_WINDOW = 3


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


class WindowMatcher:
    """The keyframe map, the pose graph its keyframes are nodes of, and the matching of
    keyframes and their windows that the back end's edges come from."""

    def __init__(self, config: LocalMapperConfig, keyframes: KeyframeMap) -> None:
        self.config = config
        self.keyframes = keyframes
        self.graph = PoseGraph()
        self.accepted: dict[int, Closure] = {}  # graph edge id -> closure in the graph
        self.refused: dict[str, int] = {}  # reason -> closures refused
        self._path_since_closure: dict[int, float] = {}  # piece -> metres since a closure

    def _match(self, first: int, second: int, predicted: Pose | None, search: bool) -> MatchResult:
        """Keyframe ``second``'s scan placed in keyframe ``first``'s frame: from the prediction
        alone (``search`` False) or with no guess (INTEGRATE, the prediction one more
        hypothesis)."""
        a, b = self.keyframes.scans[first], self.keyframes.scans[second]
        extra = None if predicted is None else hypotheses_of([predicted])
        return integrate(
            a.segments,
            b.segments,
            self.config.integrate,
            heuristics=HEURISTICS if search else (),
            extra_hypotheses=extra,
            views=(a.view, b.view),
        )

    def _window_members(self, center: int) -> IntArray:
        """The keyframes of ``center``'s window: it and its nearest neighbours in time in its
        piece, ``_WINDOW`` in all."""
        candidates = np.flatnonzero(self.keyframes.pieces == self.keyframes.piece(center))
        return candidates[np.argsort(np.abs(candidates - center), kind="stable")[:_WINDOW]]

    def _window(self, center: int) -> tuple[FloatArray, list[Viewpoint]]:
        """Keyframe ``center`` and its nearest neighbours in time in its piece (``_WINDOW``
        keyframes in all), their scans fused in its frame, and their viewpoints: a window
        sees more of a place than one scan, and its matches are surer (README, "Match
        confidence": window pairs)."""
        members = self._window_members(center)
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
        return self._edge(first, second, hypotheses_of([T_first_second])[0], robust=True)

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
        return Edge(first, second, pose_of_match(T_1_2), information, robust)

    def _refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1
