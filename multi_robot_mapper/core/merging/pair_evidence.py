"""The evidence for placing one map on another through a consistent set of place links
(:mod:`~multi_robot_mapper.core.evidence.placement`), measured both ways.

A set of links between maps A and B places B on A. Its patch on B is B's walls and free space
within ``place_radius`` of the keyframes of B that the placement says A saw too: the linked
ones, and every keyframe of B it puts within half ``place_radius`` of a keyframe of A (the
ground the placement claims both robots shared: each wall there is evidence, whether or not a
place of it matched). The patch is placed on the whole of A and set against its best rival
there; and A's patch likewise on the whole of B. A look-alike fails one way or the other: B's
corridor fits A turned round (a rival as good as the placement), or A's room fits B at
another door.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.spatial import cKDTree

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.model import join_features
from multi_robot_mapper.core.evidence.placement import (
    EVIDENCE_CORRELATION,
    PlacementEvidence,
    patch_of,
    placement_evidence,
)
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.place_links import LinkCandidate, Target
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey


@dataclasses.dataclass(frozen=True)
class PairEvidence:
    """A set's placement of B on A, each way: B's patch on A, and A's patch on B."""

    b_on_a: PlacementEvidence
    a_on_b: PlacementEvidence

    @property
    def margin(self) -> float:
        """The weaker way's margin (metres of wall no rival explains)."""
        return min(self.b_on_a.margin, self.a_on_b.margin)

    @property
    def score(self) -> float:
        """The weaker way's score (m)."""
        return min(self.b_on_a.score, self.a_on_b.score)

    @property
    def rival_ratio(self) -> float:
        """The larger share of its placement's score a rival reaches, either way."""
        return max(self.b_on_a.rival_ratio, self.a_on_b.rival_ratio)

    @property
    def conflict(self) -> float:
        """Metres of wall the placement puts in free space near the places, the larger way."""
        return max(self.b_on_a.conflict, self.a_on_b.conflict)

    def features(self, conflict: float = 0.0) -> dict[str, float]:
        """The join model's features, the conflict the larger of the patches' and
        ``conflict`` (walls in free space measured over more of the maps)."""
        return join_features((self.b_on_a, self.a_on_b), conflict)


def pair_evidence(
    pair: tuple[UnitKey, UnitKey],
    links: Sequence[LinkCandidate],
    T_a_b: np.ndarray,
    units: Mapping[UnitKey, MapUnit],
    targets: Mapping[UnitKey, Target],
    config: MergeConfig,
) -> PairEvidence:
    """The evidence of placing map ``pair[1]`` at ``T_a_b`` (3x3) in map ``pair[0]``, the
    links' keyframes giving each side's patch (module doc)."""
    a, b = pair
    linked_a = _positions(units[a], [c.keyframe if c.target == a else c.centre for c in links])
    linked_b = _positions(units[b], [c.keyframe if c.target == b else c.centre for c in links])
    shared_a, shared_b = _shared_ground(units[a], units[b], T_a_b, 0.5 * config.place_radius)
    target_a, target_b = targets[a], targets[b]
    centres_b = np.vstack((linked_b, shared_b))
    centres_a = np.vstack((linked_a, shared_a))
    patch_b = patch_of(target_b.drawing, centres_b, config.place_radius)
    patch_a = patch_of(target_a.drawing, centres_a, config.place_radius)
    # The targets' correlation transforms, when made at the evidence's own scale.
    same = config.correlation_cell == EVIDENCE_CORRELATION.cell
    prepared_a = target_a.correlation if same else None
    prepared_b = target_b.correlation if same else None
    b_on_a = placement_evidence(target_a.drawing, patch_b, T_a_b, EVIDENCE_CORRELATION, prepared_a)
    a_on_b = placement_evidence(
        target_b.drawing, patch_a, se2.invert(T_a_b), EVIDENCE_CORRELATION, prepared_b
    )
    return PairEvidence(b_on_a, a_on_b)


def _shared_ground(
    a: MapUnit, b: MapUnit, T_a_b: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray]:
    """The positions of A's keyframes within ``reach`` of a keyframe of B placed by
    ``T_a_b`` (in A's frame), and of B's within ``reach`` of one of A's (in B's frame)."""
    placed_b = se2.transform_points(T_a_b, b.poses[:, :2])
    if len(a.poses) == 0 or len(placed_b) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    distance, _ = cKDTree(placed_b).query(a.poses[:, :2], distance_upper_bound=reach)
    near_a = np.isfinite(distance)
    distance, _ = cKDTree(a.poses[:, :2]).query(placed_b, distance_upper_bound=reach)
    near_b = np.isfinite(distance)
    return np.asarray(a.poses[near_a, :2]), np.asarray(b.poses[near_b, :2])


def _positions(unit: MapUnit, keyframes: Sequence[int]) -> np.ndarray:
    rows = np.searchsorted(unit.index, np.unique(np.asarray(keyframes, dtype=np.int64)))
    return np.asarray(unit.poses[rows, :2])
