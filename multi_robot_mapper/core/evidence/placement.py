"""How sure a placement of one map on another is: the evidence of every place match
(issue 46).

A decision to place one map on another -- a consistent set of place links between two robots,
a join of two pieces of one robot, a loop closure -- rests on the places it links. Counting
those places as independent evidence is what let look-alikes through: places along one
corridor see the same walls, and a corridor turned 180 degrees fits at every one of them.
Here the evidence is measured once for the whole decision:

1. **The patch**: the placed map's walls (and the free space its robot saw) within
   ``radius`` of the keyframes the decision links -- the union of its places, each wall
   counted once however many places see it (:func:`patch_of`).
2. **The placement's score**: the patch on the other map at the decision's placement,
   refined locally, scored as the map correlation scores (metres of wall on a wall of the
   same direction, minus ``free_space_weight`` times the metres of wall either map puts in
   the other's free space; :class:`PlacementScorer`).
3. **The best rival**: the same patch searched on the *whole* other map (every translation,
   for the rotations the wall directions allow and for the placement's own rotation turned by
   0, 90, 180 and 270 degrees: symmetric corridors and wings), each peak refined the same
   way; the best placement distinct from the decision's (more than 1 m or 10 degrees away)
   is its rival.

What the rival cannot explain -- the *margin*, score minus rival score, in metres of wall --
is the evidence that tells a placement from its look-alikes; a building that fits two ways
has none. :class:`PlacementEvidence` carries the figures; the probability that the decision
is right is fitted on them (:mod:`~multi_robot_mapper.core.evidence.model`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.correlation import (
    CorrelationConfig,
    CorrelationTarget,
    Drawing,
    ScoringRasters,
    correlation_peaks,
    reach_of,
    rotation_candidates_of_drawings,
    score_bound,
    score_parts,
    scorer_rasters,
    weakest_direction,
)

FloatArray = NDArray[np.float64]

# How every decision's walls and free space are drawn and scored, whoever makes it (the
# merger's place matches, the local mapper's closures and joins): one scale of evidence for
# one fitted model: the merger's correlation cell (MergeConfig correlation_cell), and free
# space weighed 5, not the merger's search's 2 (a wall where the other robot saw through is no
# drift: 82ec02f).
EVIDENCE_CORRELATION = CorrelationConfig(cell=0.3, blur=1.0, free_space_weight=5.0)
# Placements farther apart than this (or turned more) are different answers: rivals. The
# same as a place's rivals (place_links).
DISTINCT_SHIFT = 1.0  # m
DISTINCT_TURN = float(np.radians(10.0))
# Rival peaks refined and scored, best first: the correlation's peak values are at cell
# resolution and rank a rival below a refined placement by up to a cell's blur. A peak below
# _RIVAL_FLOOR of the placement's score keeps its raw value: refining moves a score by a few
# tenths of it, and a rival that far below leaves a margin the model reads as certain anyway.
_RIVALS_REFINED = 6
_RIVAL_FLOOR = 0.5
# Slides searched as rivals: the placement moved along the direction its matched walls hold it
# least (a corridor's length), every cell, from DISTINCT_SHIFT to as far as the target map
# reaches that way (at most _MAX_SLIDE). The correlation's peaks along a corridor form a ridge,
# not peaks, and a corridor whose doors repeat every few metres fits as well slid by one
# period: a rival only this finds.
_MAX_SLIDE = 60.0  # m
# Slides scored in full at a time (PlacementScorer.best_of): those whose bound is highest.
_SCORED_BLOCK = 16
# Rotations searched: the wall-direction histograms' best peaks (each also turned by pi), and
# the placement's own rotation turned by 0, 90, 180 and 270 degrees (symmetric wings).
_HISTOGRAM_TURNS = 2
# Local refinement: a pattern search from half a cell and 1 degree, halved when no step helps.
_REFINE_ROUNDS = 6
_REFINE_TURN = float(np.radians(1.0))


@dataclasses.dataclass(frozen=True)
class PlacementEvidence:
    """A patch placed on a map, against its best rival placement on that map."""

    score: float  # m: the placement's correlation score, refined
    rival: float  # m: the best distinct rival's (0 when the patch fits nowhere else)
    wall: float  # m of wall in the patch
    placement: FloatArray  # (theta, tx, ty) the refined placement, T_target_patch
    rival_placement: FloatArray | None  # (theta, tx, ty) of the rival
    conflict: float = 0.0  # m of wall in the other's free space at the placement, either way
    matched: float = 0.0  # m of wall on a wall of the same direction at the placement

    @property
    def margin(self) -> float:
        """Metres of wall the placement explains and its best rival does not."""
        return self.score - max(self.rival, 0.0)

    @property
    def rival_ratio(self) -> float:
        """The share of the placement's score its best rival reaches (1 when it scores
        nothing)."""
        return max(self.rival, 0.0) / self.score if self.score > 0.0 else 1.0

    @property
    def conflict_share(self) -> float:
        """The walls in free space as a share of the walls matched: small for a placement
        that is right (the maps' drift, moving objects), large for a look-alike whose walls
        stand where the other robot saw through."""
        return self.conflict / max(self.matched, 1.0)

    @staticmethod
    def nothing() -> PlacementEvidence:
        return PlacementEvidence(0.0, 0.0, 0.0, np.zeros(3), None)


def patch_of(drawing: Drawing, centres: FloatArray, radius: float) -> Drawing:
    """The part of a map's drawing (walls and free space) within ``radius`` of any of
    ``centres`` (K, 2): the union of the places a decision links, each wall point once."""
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    # Each point's nearest centre from a k-d tree: a group's drawing holds 10^5 points and its
    # shared ground hundreds of centres, too many for a dense table of distances.
    tree = cKDTree(centres) if len(centres) else None

    def near(points: FloatArray) -> NDArray[np.bool_]:
        if len(points) == 0 or tree is None:
            return np.zeros(len(points), dtype=bool)
        gap, _ = tree.query(points)
        return np.asarray(gap <= radius)

    walls, free = near(drawing.walls), near(drawing.free)
    return Drawing(
        drawing.walls[walls], drawing.direction[walls], drawing.weight[walls], drawing.free[free]
    )


class PlacementScorer:
    """Correlation scores (metres) of placements ``(theta, tx, ty)`` of drawing b on drawing
    a, evaluated directly and many at once; a's rasters are made once (``rasters``: those of
    :func:`scorer_rasters`, to share between patches of one map)."""

    def __init__(
        self,
        a: Drawing,
        b: Drawing,
        config: CorrelationConfig,
        rasters: ScoringRasters | None = None,
    ) -> None:
        self.a, self.b, self.config = a, b, config
        self.rasters_a = (
            rasters if rasters is not None else scorer_rasters(a, config.cell, config.blur)
        )
        self.rasters_b = scorer_rasters(b, config.cell, config.blur, walls=False)
        # a's walls that can land in b's free space lie within b's reach of where b's middle
        # lands: looked up per placement instead of moving all of a's walls every time.
        self.middle = b.centre() if len(b.walls) or len(b.free) else np.zeros(2)
        self.reach = reach_of(b) + config.cell
        self.tree = cKDTree(a.walls) if len(a.walls) else None

    def scores(self, rows: FloatArray) -> FloatArray:
        """(N,) scores of the (N, 3) placements (near each other: a's walls looked up once
        for all, around the first's)."""
        matched, through = self.parts(rows)
        return np.asarray(matched - self.config.free_space_weight * through)

    def parts(self, rows: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(N,) metres of wall matched and (N,) metres of wall in the other's free space of
        the (N, 3) placements."""
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
        near = np.zeros(0, dtype=np.int64)
        if self.tree is not None and len(rows):
            T = se2.matrices_from_poses(rows[:, [1, 2, 0]])
            landed = T[:, :2, :2] @ self.middle + T[:, :2, 2]  # b's middle on a, (N, 2)
            spread = float(np.hypot(*(landed - landed[0]).T).max())
            near = np.asarray(self.tree.query_ball_point(landed[0], self.reach + spread), np.int64)
        walls_a = (self.a.walls[near], self.a.weight[near])
        blur_cell = (self.config.blur, self.config.cell)
        return score_parts(self.a, self.b, rows, self.rasters_a, self.rasters_b, blur_cell, walls_a)

    def best_of(self, rows: FloatArray) -> tuple[int, float]:
        """``np.argmax`` of :meth:`scores` of the (N, 3) placements, and that score: scored in
        full only those whose bound (:func:`~.correlation.score_bound`) reaches the best
        found, in blocks, highest bound first. A placement's slides along a corridor run to
        60 m either way, a few hundred of them, and most lie where the walls do not fit
        (issue 50: 60 % of the evidence model's time was the slides' scores)."""
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
        blur_cell = (self.config.blur, self.config.cell)
        weight = self.config.free_space_weight
        bound = score_bound(self.b, rows, self.rasters_a, blur_cell, weight)
        order = np.argsort(-bound, kind="stable")
        best, value = -1, -np.inf
        for start in range(0, len(order), _SCORED_BLOCK):
            block = order[start : start + _SCORED_BLOCK]
            if best >= 0 and bound[block[0]] < value:
                break  # no placement left can reach the best
            for k, score in zip(block.tolist(), self.scores(rows[block]).tolist(), strict=True):
                if score > value or (score == value and k < best):  # argmax: the first best
                    best, value = k, score
        return best, value

    def slides(self, row: FloatArray) -> FloatArray:
        """(N, 3) placements: ``row`` slid each way along its weakest direction
        (:func:`~.correlation.weakest_direction`), a cell apart, from DISTINCT_SHIFT to as
        far as a's walls reach that way."""
        row = np.asarray(row, dtype=np.float64)
        along = weakest_direction(self.a, self.b, row, self.rasters_a)
        span = np.ptp(self.a.walls @ along) if len(self.a.walls) else 0.0
        far = min(float(span), _MAX_SLIDE)
        if far <= DISTINCT_SHIFT:
            return np.zeros((0, 3))
        steps = np.arange(DISTINCT_SHIFT, far, self.config.cell)
        steps = np.concatenate((steps, -steps))
        moved = np.tile(row, (len(steps), 1))
        moved[:, 1:] += steps[:, None] * along[None, :]
        return moved

    def refine(self, row: FloatArray) -> tuple[FloatArray, float]:
        """The best placement near ``row`` (a pattern search: half a cell and one degree
        steps, halved when none helps) and its score."""
        best = np.asarray(row, dtype=np.float64).copy()
        score = float(self.scores(best)[0])
        step, turn = 0.5 * self.config.cell, _REFINE_TURN
        for _ in range(_REFINE_ROUNDS):
            moves = np.array(
                [
                    (turn, 0.0, 0.0),
                    (-turn, 0.0, 0.0),
                    (0.0, step, 0.0),
                    (0.0, -step, 0.0),
                    (0.0, 0.0, step),
                    (0.0, 0.0, -step),
                ]
            )
            tried = best[None, :] + moves
            values = self.scores(tried)
            k = int(np.argmax(values))
            if values[k] > score + 1e-9:
                best, score = tried[k], float(values[k])
            else:
                step, turn = 0.5 * step, 0.5 * turn
        return best, score


@dataclasses.dataclass(frozen=True)
class Reach:
    """Where a placement can lie at all, when the robot's own motion bounds it (a loop
    closure: the drift since the robot was last sure; a join after a loss: how far it can have
    driven): the patch's ``anchor`` (x, y, theta in the patch's frame) lands within ``radius``
    of ``centre`` (in the target's frame), turned at most ``turn`` from it. A rival beyond
    is no rival: the robot cannot have been there. Between robots nothing bounds it."""

    centre: tuple[float, float, float]
    radius: float  # m
    anchor: tuple[float, float, float]
    turn: float = float(np.pi)  # rad

    def allows(self, row: FloatArray) -> bool:
        """Does the placement (theta, tx, ty) put the anchor within reach?"""
        T = se2.matrix_from_pose(float(row[1]), float(row[2]), float(row[0]))
        x, y, theta = se2.pose_from_matrix(T @ se2.matrix_from_pose(*self.anchor))
        shift = float(np.hypot(x - self.centre[0], y - self.centre[1]))
        return shift <= self.radius and abs(float(se2.wrap_angle(theta - self.centre[2]))) <= (
            self.turn
        )

    def crop(self, drawing: Drawing, patch: Drawing) -> Drawing:
        """The target's walls and free space that a patch within reach can land on."""
        anchor = np.asarray(self.anchor[:2])
        extent = reach_of(patch) + float(np.hypot(*(patch.centre() - anchor)))
        return patch_of(drawing, np.asarray([self.centre[:2]]), self.radius + extent)


def distinct(row: FloatArray, other: FloatArray) -> bool:
    """Are two placements (theta, tx, ty) different answers?"""
    shift = float(np.hypot(row[1] - other[1], row[2] - other[2]))
    turn = abs(float(se2.wrap_angle(row[0] - other[0])))
    return shift > DISTINCT_SHIFT or turn > DISTINCT_TURN


def placement_evidence(
    target: Drawing,
    patch: Drawing,
    T_target_patch: FloatArray,
    config: CorrelationConfig,
    prepared: CorrelationTarget | None = None,
    rasters: ScoringRasters | None = None,
    reach: Reach | None = None,
) -> PlacementEvidence:
    """The patch at ``T_target_patch`` (3x3) on the target map, against its best rival
    anywhere on the target map, or, with ``reach``, anywhere the robot's motion allows
    (module doc). ``prepared``/``rasters``: the target's correlation transform and scoring
    rasters, when the caller keeps them (not with ``reach``: the target is cropped)."""
    if reach is not None:
        target, prepared, rasters = reach.crop(target, patch), None, None
    if len(patch.walls) == 0 or len(target.walls) == 0:
        return PlacementEvidence.nothing()
    x, y, theta = se2.pose_from_matrix(T_target_patch)
    scorer = PlacementScorer(target, patch, config, rasters)
    placed, score = scorer.refine(np.array([theta, x, y]))
    turns = se2.wrap_angle(placed[0] + np.array([0.0, 0.5 * np.pi, np.pi, -0.5 * np.pi]))
    rotations = np.concatenate(
        (rotation_candidates_of_drawings(target, patch, _HISTOGRAM_TURNS), turns)
    )
    peaks, values = correlation_peaks(target, patch, _unique_turns(rotations), config, prepared)
    rival, rival_row = _best_rival(scorer, placed, score, peaks, values, reach)
    slides = scorer.slides(placed)
    if reach is not None:
        slides = slides[[reach.allows(row) for row in slides]] if len(slides) else slides
    if len(slides):
        best, best_value = scorer.best_of(slides)
        # Refined, a slide along a uniform corridor creeps back towards the placement: it
        # counts as refined only while it stays a different answer.
        moved, value = scorer.refine(slides[best])
        if not distinct(moved, placed) or (reach is not None and not reach.allows(moved)):
            moved, value = slides[best], best_value
        if value > rival:
            rival, rival_row = value, moved
    matched, through = scorer.parts(placed)
    return PlacementEvidence(
        score,
        rival,
        float(patch.weight.sum()),
        placed,
        rival_row,
        float(through[0]),
        float(matched[0]),
    )


def _best_rival(
    scorer: PlacementScorer,
    placed: FloatArray,
    score: float,
    peaks: FloatArray,
    values: FloatArray,
    reach: Reach | None,
) -> tuple[float, FloatArray | None]:
    """The best of the correlation's peaks distinct from ``placed`` (and within ``reach``),
    the best few refined: its score and placement (0, None when there is none)."""
    rival, rival_row = 0.0, None
    refined = 0
    for row, raw in zip(peaks, values, strict=True):
        if refined == _RIVALS_REFINED:
            break
        if not distinct(row, placed) or (reach is not None and not reach.allows(row)):
            continue
        if raw < _RIVAL_FLOOR * score:
            if rival_row is None or raw > rival:
                rival, rival_row = float(raw), row
            break  # the peaks come best first: the rest are lower still
        refined += 1
        moved, value = scorer.refine(row)
        plausible = reach is None or reach.allows(moved)
        if plausible and distinct(moved, placed) and (rival_row is None or value > rival):
            rival, rival_row = value, moved
    return rival, rival_row


def _unique_turns(turns: FloatArray, tolerance: float = float(np.radians(2.0))) -> FloatArray:
    """The rotations, those within ``tolerance`` of one kept earlier dropped."""
    kept: list[float] = []
    for turn in np.asarray(turns, dtype=np.float64):
        if all(abs(float(se2.wrap_angle(turn - k))) > tolerance for k in kept):
            kept.append(float(turn))
    return np.asarray(kept)
