"""Is the reference right where it judges a match? (the benches that count wrong closures/links)

The shared logs' reference poses come from an offline SLAM solution, and a few of them are
wrong: on csail, scans 42 and 364 are placed 11 and 21 deg off the heading that both their
neighbours' scans agree on, while the reference between those neighbours is right (every
search below confident at >= 0.93). A loop closure to such a scan that is right by the
scans is then "wrong by the reference". :class:`ReferenceJudge` tells those apart: a match
wrong by the reference is checked again with the reference of each of its two scans
replaced, where the scans either side show it wrong, by the pose they agree on
(:func:`pose_by_neighbours`; a stretch of up to three scans wrong together is seen past the
same way). It is called only for matches wrong by the reference, so a bench pays a few
searches per such end, and never overrules the reference elsewhere.

The plain judgement, within 0.30 m / 5 deg of the reference, is :func:`bench.harness.right`.
Used by ``bench/local_table.py`` (closures and joins) and ``bench/merge_table.py`` (links
between robots); both print the matches wrong by the reference and, of those, the ones
right once the reference's own error at one scan is set aside.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from bench.harness import right
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import LocalMapperConfig
from multi_robot_mapper.core.matching import HEURISTICS, integrate
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.io.bags import (
    RobotRecording,
    TimedPose,
    TimedScan,
    nearest_stamps,
    reference_poses,
)

# Each search between consecutive scans must be right with this probability (the loop-closure
# threshold).
CONFIDENT = 0.9


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
    scans: Sequence[LaserScanData],
    reference: Sequence[Pose],
    index: int = 1,
    search: Callable[[int, int], tuple[Pose, float]] | None = None,
) -> Pose | None:
    """Where scan ``index`` of a stretch (``scans[1:-1]``, the scans either side of it first
    and last) lies in the reference's frame by the scans either side, when that shows its
    reference pose wrong; None otherwise.

    Consecutive searches with no guess, each confident, chain the scan before the stretch to
    the scan after it. The chain must land where the reference puts the scan after (the
    reference holds on either side), and put scan ``index`` farther than the tolerance from
    its reference pose. ``search(i, j)``: scan j placed in scan i's frame and the confidence
    (default :func:`_search` of the two scans; a judge passes one that remembers)."""
    find = search or (lambda i, j: _search(scans[i], scans[j]))
    chain = [reference[0]]
    for i in range(len(scans) - 1):
        T_i_next, confidence = find(i, i + 1)
        if confidence < CONFIDENT:
            return None
        chain.append(se2.compose(chain[-1], T_i_next))
    if not right(chain[-1], reference[-1]) or right(chain[index], reference[index]):
        return None
    return chain[index]


# The longest stretch of consecutive scans whose reference is wrong that the judge sees past:
# csail's scans 42 and 364 are wrong alone, 11 and 21 deg off; scans 93-95 of csail cut into 4
# robots (robot4) together, 11-12 deg (each of the scans either side placed the stretch at
# confidence 0.99-1.0, 10.5-12.5 deg from the reference).
_STRETCH = 3


class ReferenceJudge:
    """Judges matches between scans of a bag's robots by the reference, and checks the
    reference itself at the scans of a match it calls wrong."""

    def __init__(self, recordings: Mapping[str, RobotRecording]) -> None:
        self.recordings = recordings
        self._corrected: dict[tuple[str, int], Pose | None] = {}
        self._searches: dict[tuple[str, int, int], tuple[Pose, float]] = {}
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
        """The pose the neighbouring scans agree on, where they show the reference wrong: at
        this scan alone, or over a stretch of up to :data:`_STRETCH` scans that holds it
        (the shortest first)."""
        index = self._index(robot, stamp)
        key = (robot, index)
        if key not in self._corrected:
            self._corrected[key] = None
            count = len(self.recordings[robot].scans)
            for length in range(1, _STRETCH + 1):
                for start in range(index - length + 1, index + 1):
                    before, after = start - 1, start + length
                    if before < 0 or after >= count:
                        continue
                    found = self._by_neighbours(robot, before, after, index)
                    if found is not None:
                        self._corrected[key] = found
                        return found
        return self._corrected[key]

    def _by_neighbours(self, robot: str, before: int, after: int, index: int) -> Pose | None:
        """:func:`pose_by_neighbours` of scan ``index`` between scans ``before`` and
        ``after`` of ``robot``, the searches between consecutive scans remembered."""
        scans = self.recordings[robot].scans[before : after + 1]
        poses = [self.reference(robot, s.stamp) for s in scans]
        if any(p is None for p in poses):
            return None

        def search(i: int, j: int) -> tuple[Pose, float]:
            key = (robot, before + i, before + j)
            if key not in self._searches:
                self._searches[key] = _search(scans[i].scan, scans[j].scan)
            return self._searches[key]

        return pose_by_neighbours(
            [s.scan for s in scans],
            poses,  # type: ignore[arg-type]
            index - before,
            search,
        )

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


def judge_of_log(
    name: str, views: Sequence[LaserScanData], poses: Sequence[Pose]
) -> ReferenceJudge:
    """A judge of one log's scans (a CARMEN log read directly, not a bag): robot ``name``,
    each scan's index standing for its time."""
    stamps = [float(k) for k in range(len(views))]
    recording = RobotRecording(
        name=name,
        scans=[TimedScan(t, "laser", view) for t, view in zip(stamps, views, strict=True)],
        ground_truth=[
            TimedPose(t, (float(pose[0]), float(pose[1]), float(pose[2])), "world")
            for t, pose in zip(stamps, poses, strict=True)
        ],
    )
    return ReferenceJudge({name: recording})
