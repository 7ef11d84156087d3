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
from multi_robot_mapper.core.evidence.correlation import Drawing
from multi_robot_mapper.core.evidence.model import join_features
from multi_robot_mapper.core.evidence.placement import (
    EVIDENCE_CORRELATION,
    PlacementEvidence,
    PlacementScorer,
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
    shared_a, shared_b = _shared_ground(
        units[a].poses[:, :2], units[b].poses[:, :2], T_a_b, 0.5 * config.place_radius
    )
    target_a, target_b = targets[a], targets[b]
    centres_b = np.vstack((linked_b, shared_b))
    centres_a = np.vstack((linked_a, shared_a))
    patch_b = patch_of(target_b.drawing, centres_b, config.place_radius)
    patch_a = patch_of(target_a.drawing, centres_a, config.place_radius)
    # The targets' correlation transforms, when made at the evidence's own scale.
    same = config.correlation_cell == EVIDENCE_CORRELATION.cell
    prepared_a = target_a.correlation if same else None
    prepared_b = target_b.correlation if same else None
    b_on_a = placement_evidence(
        target_a.drawing, patch_b, T_a_b, EVIDENCE_CORRELATION, prepared_a, target_a.rasters
    )
    a_on_b = placement_evidence(
        target_b.drawing,
        patch_a,
        se2.invert(T_a_b),
        EVIDENCE_CORRELATION,
        prepared_b,
        target_b.rasters,
    )
    return PairEvidence(b_on_a, a_on_b)


def group_conflict(
    group_a: Mapping[UnitKey, np.ndarray],
    group_b: Mapping[UnitKey, np.ndarray],
    T_a_b: np.ndarray,
    units: Mapping[UnitKey, MapUnit],
    targets: Mapping[UnitKey, Target],
    place_radius: float,
) -> float:
    """Metres of wall that joining two groups of maps puts in free space a robot of the other
    group saw, the larger way: group B (each map at its ``T_rootb_map``) placed at ``T_a_b``
    on group A (each at its ``T_roota_map``), the groups' maps drawn together, each wall once,
    the patch of every map of B on the shared ground (``place_radius`` wide) and of A
    likewise, each placement refined (issue 46: a join is checked against every member of the
    group it creates).

    Only the free space: whether the pair's placement is right is the pair's own evidence
    (its rivals searched over the whole of the other map); a join of groups is right when
    its pair is, and the other members can only add walls where their robots saw through."""
    drawing_a, positions_a = _group_drawing(group_a, units, targets)
    drawing_b, positions_b = _group_drawing(group_b, units, targets)
    shared_a, shared_b = _shared_ground(positions_a, positions_b, T_a_b, 0.5 * place_radius)
    patch_b = patch_of(drawing_b, shared_b, place_radius)
    patch_a = patch_of(drawing_a, shared_a, place_radius)
    worst = 0.0
    for target, patch, T in ((drawing_a, patch_b, T_a_b), (drawing_b, patch_a, se2.invert(T_a_b))):
        if len(patch.walls) == 0 or len(target.walls) == 0:
            continue
        scorer = PlacementScorer(target, patch, EVIDENCE_CORRELATION)
        x, y, theta = se2.pose_from_matrix(T)
        placed, _ = scorer.refine(np.array([theta, x, y]))
        _, through = scorer.parts(placed)
        worst = max(worst, float(through[0]))
    return worst


# A wall point of a group's map within this of an earlier map's is the same wall (drawn once).
_SAME_WALL = 0.1  # m


def _group_drawing(
    group: Mapping[UnitKey, np.ndarray],
    units: Mapping[UnitKey, MapUnit],
    targets: Mapping[UnitKey, Target],
) -> tuple[Drawing, np.ndarray]:
    """Every map of a group drawn in the group's frame, each wall once (a wall two robots
    mapped is one wall), and every keyframe's position there."""
    walls: list[np.ndarray] = []
    direction: list[np.ndarray] = []
    weight: list[np.ndarray] = []
    free: list[np.ndarray] = []
    positions: list[np.ndarray] = []
    for key in sorted(group):
        T = group[key]
        theta = float(np.arctan2(T[1, 0], T[0, 0]))
        drawing = targets[key].drawing.moved(T, theta)
        points = drawing.walls
        if walls and len(points):
            distance, _ = cKDTree(np.vstack(walls)).query(points, distance_upper_bound=_SAME_WALL)
            new = ~np.isfinite(distance)
        else:
            new = np.ones(len(points), dtype=bool)
        walls.append(points[new])
        direction.append(drawing.direction[new])
        weight.append(drawing.weight[new])
        free.append(drawing.free)
        positions.append(se2.transform_points(T, units[key].poses[:, :2]))
    return (
        Drawing(
            np.vstack(walls), np.concatenate(direction), np.concatenate(weight), np.vstack(free)
        ),
        np.vstack(positions),
    )


def _shared_ground(
    a: np.ndarray, b: np.ndarray, T_a_b: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray]:
    """Of the keyframe positions ``a`` (A's frame) those within ``reach`` of a position of
    ``b`` placed by ``T_a_b``, and of ``b`` (B's frame) those within ``reach`` of one of A's."""
    placed_b = se2.transform_points(T_a_b, b)
    if len(a) == 0 or len(placed_b) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    distance, _ = cKDTree(placed_b).query(a, distance_upper_bound=reach)
    near_a = np.isfinite(distance)
    distance, _ = cKDTree(a).query(placed_b, distance_upper_bound=reach)
    near_b = np.isfinite(distance)
    return np.asarray(a[near_a]), np.asarray(b[near_b])


def _positions(unit: MapUnit, keyframes: Sequence[int]) -> np.ndarray:
    rows = np.searchsorted(unit.index, np.unique(np.asarray(keyframes, dtype=np.int64)))
    return np.asarray(unit.poses[rows, :2])
