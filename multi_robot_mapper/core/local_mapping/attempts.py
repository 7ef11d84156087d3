"""The front end's match attempts: where a scan is anchored, one match of a new scan against
one reference scan, and when two attempts corroborate each other."""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching import MatchResult
from multi_robot_mapper.core.matching.confidence import LIKELY, RIGHT_ANGLE, RIGHT_DISTANCE

FloatArray = NDArray[np.float64]
Pose = tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class Anchor:
    """Where a scan is: relative to a keyframe, so that its pose follows the graph."""

    keyframe: int
    T_keyframe_scan: Pose


# A tracked scan refined this close to its constant-velocity prediction needs no rivals: a
# third of the correctness tolerance.
NEAR = RIGHT_DISTANCE / 3.0
NEAR_ANGLE = RIGHT_ANGLE / 3.0


def close_to(a: Pose, b: Pose, distance: float, angle: float) -> bool:
    dx, dy, dtheta = se2.between(b, a)
    return bool(np.hypot(dx, dy) <= distance and abs(dtheta) <= angle)


@dataclasses.dataclass(frozen=True)
class Attempt:
    """One match of the new scan against one reference scan."""

    result: MatchResult
    anchor: Anchor  # where the reference scan is (its keyframe, and the offset from it)
    reference: FloatArray  # the reference scan's segments
    pose: Pose  # the new scan's pose in the piece, by this match
    piece: int  # the reference's piece
    stage: str  # "track", "search" or "recent"


def corroborated(attempts: list[Attempt]) -> Attempt | None:
    """The more confident of two attempts against different reference scans, each more likely
    right than wrong, that place the scan within the correctness tolerance of each other:
    wrong matches rarely agree on one placement from two scans (when they do, it is the
    same structure misleading both, and their confidence is low)."""
    likely = [a for a in attempts if a.result.confidence >= LIKELY]
    for i, a in enumerate(likely):
        for b in likely[i + 1 :]:
            if a.anchor == b.anchor or a.piece != b.piece:
                continue  # the same reference scan (not independent), or unrelated frames
            dx, dy, dtheta = se2.between(a.pose, b.pose)
            if np.hypot(dx, dy) < RIGHT_DISTANCE and abs(dtheta) < RIGHT_ANGLE:
                return a if a.result.confidence >= b.result.confidence else b
    return None


def pose_of_match(T_1_2: FloatArray) -> Pose:
    """INTEGRATE's (theta, tx, ty) as an (x, y, theta) pose."""
    return (float(T_1_2[1]), float(T_1_2[2]), float(T_1_2[0]))


def hypotheses_of(poses: list[Pose]) -> FloatArray:
    """(x, y, theta) poses as INTEGRATE hypotheses (theta, tx, ty)."""
    stacked = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return np.column_stack((stacked[:, 2], stacked[:, 0], stacked[:, 1]))
