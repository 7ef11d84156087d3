"""The evidence model (:mod:`~multi_robot_mapper.core.evidence`) for the back end's decisions:
a loop closure places the robot's recent stretch of map on its older map, a join places one
piece of map on another. Either is believed only when the probability that it is right
reaches ``join_probability``, as a link between robots is.

The *patch* is the walls of the keyframes the decision moves, near the keyframe it was found
from, with the free space their scans crossed; the *target* is the map it is placed on (the
older keyframes of the piece for a closure, the other piece for a join), with its scans'
free space. The placement is searched for rivals on the whole target
(:func:`~core.evidence.placement.placement_evidence`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.correlation import Drawing
from multi_robot_mapper.core.evidence.model import join_features
from multi_robot_mapper.core.evidence.placement import (
    EVIDENCE_CORRELATION,
    PlacementEvidence,
    Reach,
    placement_evidence,
)
from multi_robot_mapper.core.evidence.seen import SEEN_REACH, scan_free_points
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.local_mapping.keyframe_map import KeyframeMap
from multi_robot_mapper.core.logistic import LogisticModel
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclasses.dataclass(frozen=True)
class Weighed:
    """A closure or join the evidence model weighed: keyframe ``mine`` placed at ``found`` in
    keyframe ``first``'s frame, its probability and evidence."""

    kind: str  # "loop" or "join"
    first: int
    mine: int
    found: Pose
    probability: float
    evidence: PlacementEvidence
    prior: float | None = None  # a loop closure's graph prior (nats; core.evidence.model)


# A decision's patch: the keyframes it moves within this distance of the keyframe it was
# found from (the merger's place_radius: a place).
PATCH_RADIUS = 6.0  # m
PATCH_KEYFRAMES = 20
# Free space from the scans of keyframes at least this far apart, at most this many of them
# (the merger's view_spacing and max_views).
VIEW_SPACING = 1.0  # m
# The approach's keyframes that can touch a patch (walls within PATCH_RADIUS of its keyframe,
# free space SEEN_REACH from theirs).
APPROACH_RADIUS = PATCH_RADIUS + SEEN_REACH  # m
MAX_VIEWS = 60


def drawing_of(keyframes: KeyframeMap, members: IntArray, own_scans: bool = False) -> Drawing:
    """The walls of keyframes ``members`` and the free space their scans crossed, in their
    piece's frame: the map segments they own, or with ``own_scans`` their scans' segments
    fused (Alg. 5: a wall seen again is one wall). A keyframe that revisits a place owns
    little of the map (its walls fused into the older keyframes'), so a stretch of map that
    is placed is drawn from its own scans."""
    members = np.asarray(members, dtype=np.int64)
    poses = keyframes.poses[members]
    if own_scans:
        walls, owner = np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
        for k, pose in zip(members.tolist(), poses, strict=True):
            placed = se2.transform_segments(
                se2.matrix_from_pose(*pose), keyframes.scans[k].segments
            )
            walls, owner = fuse(
                walls,
                owner,
                placed,
                np.full(len(placed), k, dtype=np.int64),
                keyframes.pair,
                keyframes.tolerance,
            )
    else:
        walls = keyframes.owned_segments(members)
    views = _thinned(poses, VIEW_SPACING, MAX_VIEWS)
    scans = [keyframes.scans[int(k)].view for k in members[views]]
    free = scan_free_points(scans, poses[views], 0.5 * EVIDENCE_CORRELATION.cell)
    return Drawing.of(walls, free, EVIDENCE_CORRELATION.cell)


def decision_evidence(
    keyframes: KeyframeMap,
    patch: IntArray,
    target: IntArray,
    T_target_patch: FloatArray,
    reach: Reach | None = None,
) -> PlacementEvidence:
    """The evidence of placing keyframes ``patch`` (their piece's frame) at ``T_target_patch``
    (3x3) on keyframes ``target`` (theirs); rivals only where ``reach`` allows (the robot's
    motion bounds where the patch can lie)."""
    if len(patch) == 0 or len(target) == 0:
        return PlacementEvidence.nothing()
    return placement_evidence(
        drawing_of(keyframes, target),
        drawing_of(keyframes, patch, own_scans=True),
        T_target_patch,
        EVIDENCE_CORRELATION,
        reach=reach,
    )


def patch_around(keyframes: KeyframeMap, candidates: IntArray, centre: int) -> IntArray:
    """Of ``candidates``, the keyframes within PATCH_RADIUS of keyframe ``centre``, at most
    PATCH_KEYFRAMES of them (spread evenly: a robot that drove round a room holds many)."""
    candidates = np.asarray(candidates, dtype=np.int64)
    here = keyframes.poses[centre, :2]
    distance = np.hypot(*(keyframes.poses[candidates, :2] - here).T)
    near = candidates[distance <= PATCH_RADIUS]
    if len(near) > PATCH_KEYFRAMES:
        near = near[np.linspace(0, len(near) - 1, PATCH_KEYFRAMES).astype(int)]
    return np.asarray(near)


def without_approach(
    poses: FloatArray, older: IntArray, first_stretch_end: int, mine: int
) -> IntArray:
    """The loop closure's target: keyframes ``older`` (rows of ``poses``) without the robot's
    own approach to the place, the run of keyframes just before the recent stretch (the newest
    of ``older`` back to the first one more than APPROACH_RADIUS from keyframe ``mine``; never
    a keyframe up to ``first_stretch_end``, the end of the stretch the closure returns to).

    The approach was mapped with the drift the closure corrects: its walls and free space sit
    where the uncorrected recent stretch sits. In the target, the right placement meets them
    as walls in free space, the more so the larger the drift: on freiburg-079 cut into 2
    robots, 238 of 482 right closures (gate open) had no margin over their rival, 129 to 155
    without the approach (issue 46; docs/decisions.md)."""
    newest_first = np.sort(np.asarray(older, dtype=np.int64))[::-1]
    distance = np.hypot(*(poses[newest_first, :2] - poses[mine, :2]).T)
    outside = (distance > APPROACH_RADIUS) | (newest_first <= first_stretch_end)
    length = int(np.argmax(outside)) if outside.any() else len(newest_first)
    return np.sort(newest_first[length:])


def moved_to(
    keyframes: KeyframeMap, mine: int, T_piece_mine: tuple[float, float, float]
) -> FloatArray:
    """T_target_patch that puts keyframe ``mine`` at ``T_piece_mine`` (in the target's frame)
    and its piece rigidly with it."""
    return np.asarray(
        se2.matrix_from_pose(*T_piece_mine)
        @ se2.invert(se2.matrix_from_pose(*keyframes.pose(mine)))
    )


def probability_of(
    evidence: PlacementEvidence, model: LogisticModel, prior: float | None = None
) -> float:
    """P(right) of a decision with this evidence (and a loop closure's graph ``prior``), by
    the model of its kind."""
    return model.probability(join_features([evidence], prior=prior))


def _thinned(poses: FloatArray, spacing: float, most: int) -> IntArray:
    """Rows of ``poses`` kept greedily, each at least ``spacing`` from those kept, then at
    most ``most`` of them evenly."""
    kept: list[int] = []
    for row in range(len(poses)):
        if not kept or np.min(np.hypot(*(poses[kept, :2] - poses[row, :2]).T)) >= spacing:
            kept.append(row)
    rows = np.asarray(kept, dtype=np.int64)
    if len(rows) > most:
        rows = rows[np.linspace(0, len(rows) - 1, most).astype(int)]
    return rows
