"""Is the reference right where it judges a match? (the benches that count wrong closures/links)

The shared logs' reference poses come from an offline SLAM solution, and a few of them are
wrong: on csail, scans 42 and 364 are placed 11 and 21 deg off the heading that both their
neighbours' scans agree on, while the reference between those neighbours is right (every
search below confident at >= 0.93). A loop closure to such a scan that is right by the
scans is then "wrong by the reference". :class:`ReferenceJudge` tells those apart: a match
wrong by the reference is checked again with the reference of each of its two scans
replaced, where the scans either side show it wrong, by the pose they agree on
(:func:`pose_by_neighbours`). It is called only for matches wrong by the reference, so a
bench pays three searches per such end, and never overrules the reference elsewhere.

Used by ``bench/local_table.py`` (closures and joins) and ``bench/merge_table.py`` (links
between robots); both print the matches wrong by the reference and, of those, the ones
right once the reference's own error at one scan is set aside.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import LocalMapperConfig
from multi_robot_mapper.core.matching import HEURISTICS, integrate
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.io.bags import RobotRecording, nearest_stamps, reference_poses

Pose = tuple[float, float, float]
# Each of the three searches must be right with this probability (the loop-closure threshold).
CONFIDENT = 0.9


def right(T_found: Pose, T_true: Pose) -> bool:
    """Within the correctness tolerance (0.30 m / 5 deg) of the truth?"""
    dx, dy, dtheta = se2.between(T_true, T_found)
    return bool(np.hypot(dx, dy) < RIGHT_DISTANCE and abs(dtheta) < RIGHT_ANGLE)


def _search(first: LaserScanData, second: LaserScanData) -> tuple[Pose, float]:
    """``second`` placed in ``first``'s frame by INTEGRATE with no guess, and its confidence."""
    extraction = ExtractionConfig()
    segments = [extract_scan(scan, extraction)[0].segments for scan in (first, second)]
    result = integrate(
        segments[0],
        segments[1],
        LocalMapperConfig().integrate,
        heuristics=HEURISTICS,
        views=(first, second),
    )
    theta, x, y = (float(v) for v in result.T_1_2)
    return (x, y, theta), float(result.confidence)


def pose_by_neighbours(
    scans: tuple[LaserScanData, LaserScanData, LaserScanData],
    reference: tuple[Pose, Pose, Pose],
) -> Pose | None:
    """Where the middle scan lies in the reference's frame by the scans either side, when that
    shows its reference pose wrong; None otherwise.

    Three searches with no guess, each confident: the scan before placed the scan after where
    the reference does (the reference holds on either side), the scans before and after put
    the middle scan at one pose (within the tolerance of each other), and that pose is
    farther than the tolerance from the middle scan's reference pose."""
    before, middle, after = scans
    ref_before, ref_middle, ref_after = reference
    T_before_after, c1 = _search(before, after)
    if c1 < CONFIDENT or not right(T_before_after, se2.between(ref_before, ref_after)):
        return None
    T_before_middle, c2 = _search(before, middle)
    T_middle_after, c3 = _search(middle, after)
    if min(c2, c3) < CONFIDENT:
        return None
    by_before = se2.compose(ref_before, T_before_middle)
    by_after = se2.compose(ref_after, se2.between(T_middle_after, (0.0, 0.0, 0.0)))
    if not right(by_before, by_after) or right(by_before, ref_middle):
        return None
    return by_before


class ReferenceJudge:
    """Judges matches between scans of a bag's robots by the reference, and checks the
    reference itself at the scans of a match it calls wrong."""

    def __init__(self, recordings: Mapping[str, RobotRecording]) -> None:
        self.recordings = recordings
        self._corrected: dict[tuple[str, int], Pose | None] = {}
        self._stamps = {
            robot: np.array([s.stamp for s in recording.scans], dtype=np.float64)
            for robot, recording in recordings.items()
        }

    def _index(self, robot: str, stamp: float) -> int:
        index, _ = nearest_stamps(self._stamps[robot], np.array([stamp], dtype=np.float64))
        return int(index[0])

    def reference(self, robot: str, stamp: float) -> Pose | None:
        poses, found = reference_poses(self.recordings[robot], np.array([stamp], np.float64))
        return tuple(float(v) for v in poses[0]) if found[0] else None  # type: ignore[return-value]

    def corrected(self, robot: str, stamp: float) -> Pose | None:
        """The pose the neighbouring scans agree on, where they show the reference wrong."""
        index = self._index(robot, stamp)
        key = (robot, index)
        if key not in self._corrected:
            scans = self.recordings[robot].scans
            self._corrected[key] = None
            if 0 < index < len(scans) - 1:
                trio = [scans[i] for i in (index - 1, index, index + 1)]
                poses = [self.reference(robot, s.stamp) for s in trio]
                if all(p is not None for p in poses):
                    self._corrected[key] = pose_by_neighbours(
                        (trio[0].scan, trio[1].scan, trio[2].scan),
                        (poses[0], poses[1], poses[2]),  # type: ignore[arg-type]
                    )
        return self._corrected[key]

    def verdict(
        self, robot_a: str, stamp_a: float, robot_b: str, stamp_b: float, T_a_b: Pose
    ) -> str | None:
        """ "right" or "wrong" by the reference, or "reference" (wrong by the reference, right
        with the reference of one or both scans replaced by the pose its neighbours agree
        on); None when a scan has no reference pose."""
        a, b = self.reference(robot_a, stamp_a), self.reference(robot_b, stamp_b)
        if a is None or b is None:
            return None
        if right(T_a_b, se2.between(a, b)):
            return "right"
        fixed_a = self.corrected(robot_a, stamp_a) or a
        fixed_b = self.corrected(robot_b, stamp_b) or b
        if (fixed_a, fixed_b) != (a, b) and right(T_a_b, se2.between(fixed_a, fixed_b)):
            return "reference"
        return "wrong"
