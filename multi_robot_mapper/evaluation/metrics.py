"""Metrics of a multi-robot map against reference poses (issue 3, section 5).

Inputs are plain arrays: for every robot the stamp, reference pose (``world`` frame) and
estimated pose (``map`` frame, NaN rows for scans the method left unposed) of each scan, the
map's segments in ``map`` and reference-posed scan points in ``world``. ``T_ref_map`` maps
``map`` coordinates into the reference (``world``) frame.

Where evo is used, and where not:

- SE(2) alignment goes through :func:`evo.core.geometry.umeyama_alignment` called with 2-D
  points (``2 x N``). evo's Umeyama is dimension-generic and its determinant correction makes
  the 2x2 result a proper rotation, so the planar fit can never come out as a reflection (which
  a 3-D fit of z = 0 trajectories may do: a half-turn about an in-plane axis). Degenerate input
  (one scan, or a robot that never moved) has no position-only solution; there the rotation is
  the circular mean of the heading differences and the translation matches the centroids.
- The pair errors are evo's RPE (delta = 1 frame, ``E = rel_ref^-1 rel_est``, translation
  part and rotation angle) written out in numpy for SE(2): evo pairs consecutive *posed*
  poses, whereas here a pair is two consecutive *scans* and an unposed scan must fail its
  pairs. ``test/evaluation/test_evaluation.py`` checks the numbers equal evo's RPE on a posed track.
- ATE is the RMSE of aligned positions (evo's APE translation part), a one-liner in numpy.

Point-to-segment distances are exact distances to candidate segments found through a KD-tree
over samples taken every <= 2 cm along the map: never below the true nearest-segment distance,
at most 1 cm above it, and equal to it except where many segments overlap (see
:func:`point_segment_distances`). Map precision is judged on the midpoints of <= 2 cm pieces of
each segment, weighted by piece length.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from evo.core.geometry import GeometryException, umeyama_alignment
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import ranges_index
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Robots = tuple[str, ...]
PairErrors = tuple[NDArray[np.bool_], FloatArray, FloatArray]  # both posed, translation, rotation

PAIR_TRANSLATION_M = 0.30
PAIR_ROTATION_RAD = math.radians(5.0)
STRICT_TRANSLATION_M = 0.10
STRICT_ROTATION_RAD = math.radians(2.0)
MERGE_RMSE_M = 0.30  # a robot is placed by an alignment when its position RMSE is below this
MAP_TOLERANCE_M = 0.10  # coverage and precision distance
SEGMENT_STEP_M = 0.02  # map segments are sampled at least this densely
_DEGENERATE_SPREAD_M = 1e-9


@dataclasses.dataclass
class RobotTrack:
    """Every scan of one robot, in order: reference pose and estimated pose (NaN = unposed)."""

    stamps: FloatArray  # (N,) s
    reference: FloatArray  # (N, 3) x, y, theta of each scan in the reference frame
    estimate: FloatArray  # (N, 3) x, y, theta in map; NaN rows for unposed scans

    def __post_init__(self) -> None:
        self.stamps = np.asarray(self.stamps, dtype=np.float64).ravel()
        self.reference = np.asarray(self.reference, dtype=np.float64).reshape(-1, 3)
        self.estimate = np.asarray(self.estimate, dtype=np.float64).reshape(-1, 3)
        n = len(self.stamps)
        if len(self.reference) != n or len(self.estimate) != n:
            raise ValueError(
                f"RobotTrack needs one reference and one estimate per stamp: {n} stamps, "
                f"{len(self.reference)} references, {len(self.estimate)} estimates"
            )
        if not np.all(np.isfinite(self.reference)):
            raise ValueError("RobotTrack reference poses must all be finite")

    @property
    def posed(self) -> NDArray[np.bool_]:
        """(N,) True where the method gave the scan a pose."""
        return np.asarray(np.all(np.isfinite(self.estimate), axis=1))


@dataclasses.dataclass
class RobotMetrics:
    """One robot's figures. Rates and errors are NaN when there is nothing to measure."""

    scans: int
    scans_unposed: int
    pairs: int  # consecutive scan pairs (scans - 1)
    pair_success: float
    pair_success_strict: float
    median_translation_error_m: float  # over pairs with both scans posed
    median_rotation_error_rad: float
    rmse_m: float  # position RMSE under the chosen alignment T_ref_map
    ate_own_frame_m: float  # position RMSE after aligning this robot alone
    merged: bool
    reported_unmerged: bool  # the method said "unmerged" for this robot's frame


@dataclasses.dataclass
class Metrics:
    """Everything ``mrm evaluate`` reports; :meth:`to_dict` gives the JSON form."""

    robots_total: int
    robots_merged: int
    merged_robots: list[str]
    scans_total: int
    scans_unposed: int
    pair_success: float
    pair_success_strict: float
    median_translation_error_m: float
    median_rotation_error_rad: float
    ate_rmse_m: float  # merged robots, own least-squares fit
    ate_all_rmse_m: float  # every posed scan, own least-squares fit
    map_error_m: float
    map_coverage: float
    map_precision: float
    map_segments: int
    reference_points: int
    T_ref_map: FloatArray  # the chosen alignment (3x3)
    robots: dict[str, RobotMetrics]

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: NaN becomes None, the alignment becomes ``{"x", "y", "theta"}``."""
        out: dict[str, Any] = {}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.name == "T_ref_map":
                x, y, theta = se2.pose_from_matrix(value)
                out["alignment_T_ref_map"] = {"x": x, "y": y, "theta": theta}
            elif field.name == "robots":
                out["robots"] = {
                    name: {k: _jsonable(v) for k, v in dataclasses.asdict(m).items()}
                    for name, m in value.items()
                }
            else:
                out[field.name] = _jsonable(value)
        out["thresholds"] = {
            "pair_translation_m": PAIR_TRANSLATION_M,
            "pair_rotation_rad": PAIR_ROTATION_RAD,
            "pair_strict_translation_m": STRICT_TRANSLATION_M,
            "pair_strict_rotation_rad": STRICT_ROTATION_RAD,
            "merge_rmse_m": MERGE_RMSE_M,
            "map_tolerance_m": MAP_TOLERANCE_M,
            "segment_step_m": SEGMENT_STEP_M,
        }
        return out


def _jsonable(value: Any) -> Any:
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, list):
        return [_jsonable(v) for v in value]
    return value


# ----------------------------------------------------------------------------------- alignment


def align_se2(estimate: FloatArray, reference: FloatArray) -> FloatArray:
    """Least-squares SE(2) (no scale) ``T_ref_est`` taking estimated positions onto reference.

    ``estimate`` and ``reference`` are matching ``(N, 3)`` poses, N >= 1, all finite. Positions
    are fitted with evo's Umeyama in 2-D; without a position spread the headings fix the
    rotation (circular mean of the differences).
    """
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    if len(est) == 0 or len(est) != len(ref):
        raise ValueError(f"align_se2 needs matching non-empty poses ({len(est)}, {len(ref)})")
    spread = np.max(np.linalg.norm(est[:, :2] - est[:, :2].mean(axis=0), axis=1))
    if len(est) >= 2 and spread > _DEGENERATE_SPREAD_M:
        try:
            r, t, _ = umeyama_alignment(est[:, :2].T, ref[:, :2].T, with_scale=False)
        except GeometryException:
            pass
        else:
            T = np.eye(3)
            T[:2, :2] = r
            T[:2, 2] = t
            return T
    dtheta = se2.wrap_angle(ref[:, 2] - est[:, 2])
    theta = float(np.arctan2(np.sin(dtheta).mean(), np.cos(dtheta).mean()))
    T = se2.matrix_from_pose(0.0, 0.0, theta)
    T[:2, 2] = ref[:, :2].mean(axis=0) - T[:2, :2] @ est[:, :2].mean(axis=0)
    return T


def aligned_rmse(estimate: FloatArray, reference: FloatArray) -> float:
    """The positions' RMS error (m) after :func:`align_se2`: a trajectory's ATE against its
    reference, in one frame fitted to it."""
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    T = align_se2(est, ref)
    moved = est[:, :2] @ T[:2, :2].T + T[:2, 2]
    return float(np.sqrt(np.mean(np.sum((moved - ref[:, :2]) ** 2, axis=1))))


# --------------------------------------------------------------------------------------- pairs


def pair_errors(track: RobotTrack) -> PairErrors:
    """For the N-1 consecutive scan pairs: both posed, translation error (m), rotation error (rad).

    The error of a pair is ``E = rel_ref^-1 rel_est`` with ``rel = T_i^-1 T_i+1``; its
    translation is ``|t_rel_est - t_rel_ref|`` and its rotation ``|wrap(dtheta_est -
    dtheta_ref)|``. Errors are NaN where a scan of the pair is unposed.
    """

    def relative(poses: FloatArray) -> tuple[FloatArray, FloatArray]:
        step = poses[1:, :2] - poses[:-1, :2]
        c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
        local = np.column_stack((c * step[:, 0] + s * step[:, 1], -s * step[:, 0] + c * step[:, 1]))
        return local, se2.wrap_angle(poses[1:, 2] - poses[:-1, 2])

    posed = track.posed
    both = posed[1:] & posed[:-1]
    t_ref, r_ref = relative(track.reference)
    t_est, r_est = relative(track.estimate)
    translation = np.linalg.norm(t_est - t_ref, axis=1)
    rotation = np.abs(se2.wrap_angle(r_est - r_ref))
    translation[~both] = np.nan
    rotation[~both] = np.nan
    return both, translation, rotation


def _pair_summary(
    both: NDArray[np.bool_], translation: FloatArray, rotation: FloatArray
) -> tuple[float, float, float, float]:
    """(success, strict success, median translation error, median rotation error)."""
    pairs = len(both)
    if pairs == 0:
        return math.nan, math.nan, math.nan, math.nan
    with np.errstate(invalid="ignore"):
        ok = both & (translation <= PAIR_TRANSLATION_M) & (rotation <= PAIR_ROTATION_RAD)
        strict = both & (translation <= STRICT_TRANSLATION_M) & (rotation <= STRICT_ROTATION_RAD)
    if np.any(both):
        med_t, med_r = float(np.median(translation[both])), float(np.median(rotation[both]))
    else:
        med_t = med_r = math.nan
    return float(ok.sum()) / pairs, float(strict.sum()) / pairs, med_t, med_r


# ----------------------------------------------------------------------------------------- map


def sample_segments(
    segments: FloatArray, step: float = SEGMENT_STEP_M, midpoints: bool = False
) -> tuple[FloatArray, IntArray, FloatArray]:
    """Points along each segment no further apart than ``step``.

    Segment i of length L is cut into ``n = max(1, ceil(L / step))`` equal pieces. Returns
    ``(points (S, 2), segment index (S,), weight (S,))``: with ``midpoints=False`` the n + 1 piece
    ends (so every point of the segment is within step / 2 of a sample), weight 0; with
    ``midpoints=True`` the n piece midpoints, weight L / n (the length each one stands for).
    """
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    pieces = np.maximum(1, np.ceil(length / step)).astype(np.int64)
    if len(seg) == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64), np.zeros(0)
    count = pieces if midpoints else pieces + 1  # never 0: ranges_index needs no empty range
    k, index, _ = ranges_index(np.zeros(len(seg), dtype=np.int64), count)
    t = ((k + 0.5) if midpoints else k.astype(np.float64)) / pieces[index]
    a, b = seg[index, :2], seg[index, 2:]
    points = a + t[:, None] * (b - a)
    weight = (length / pieces)[index] if midpoints else np.zeros(index.size)
    return points, index, weight


def _distance_to_segments(points: FloatArray, segments: FloatArray) -> FloatArray:
    """Exact distance from points (..., 2) to segments (..., 4), elementwise (broadcasting).

    Not :func:`multi_robot_mapper.core.geometry.point_segment_distance`: that one ends in
    ``np.hypot``, which differs from this ``sqrt(x^2 + y^2)`` in the last bit, and the
    evaluator's published numbers must stay bit-for-bit the same.
    """
    a = segments[..., :2]
    d = segments[..., 2:] - a
    ap = points - a
    denom = np.sum(d * d, axis=-1)
    t = np.clip(np.sum(ap * d, axis=-1) / np.where(denom > 0.0, denom, 1.0), 0.0, 1.0)
    return np.asarray(np.linalg.norm(ap - t[..., None] * d, axis=-1))


def point_segment_distances(
    points: FloatArray, segments: FloatArray, step: float = SEGMENT_STEP_M, k: int = 8
) -> FloatArray:
    """Distance from each point (P, 2) to the nearest of the segments (M, 4), within step / 2.

    Segments are sampled every <= ``step`` (piece ends), so the nearest segment's closest point
    has a sample within ``step / 2``. The segments owning a point's ``k`` nearest samples are
    its candidates and the result is the exact point-to-segment distance to the nearest
    candidate: never below the true distance d and never above d + step / 2 (the nearest
    sample's own segment is a candidate). It equals d unless more than ``k`` samples of other
    segments lie closer than the true nearest segment's samples, which happens only where many
    segments overlap (a map of every scan's segments) and then they are within millimetres of
    one another. Proving exactness there would cost hundreds of samples per point.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    if len(seg) == 0:
        return np.full(len(pts), np.inf)
    if len(pts) == 0:
        return np.zeros(0)
    samples, owner, _ = sample_segments(seg, step)
    k = min(k, len(samples))
    tree = cKDTree(samples, balanced_tree=False, compact_nodes=False)  # faster build, same answer
    _, sample_idx = tree.query(pts, k=k, workers=-1)
    candidates = seg[owner[np.asarray(sample_idx).reshape(len(pts), k)]]  # (P, k, 4)
    return np.asarray(_distance_to_segments(pts[:, None, :], candidates).min(axis=1))


def map_scores(segments: FloatArray, reference_points: FloatArray) -> tuple[float, float, float]:
    """``(map_error_m, map_coverage, map_precision)`` of segments and points in one frame.

    - error: mean distance from the points to the nearest segment (point_segment_distances);
    - coverage: fraction of points within MAP_TOLERANCE_M of a segment;
    - precision: fraction of segment length within MAP_TOLERANCE_M of a point (midpoints of
      <= SEGMENT_STEP_M pieces, weighted by piece length).
    NaN where undefined (no points; no map for error and precision, coverage is then 0).
    """
    pts = np.asarray(reference_points, dtype=np.float64).reshape(-1, 2)
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    if len(pts) == 0:
        return math.nan, math.nan, math.nan
    if len(seg) == 0:
        return math.nan, 0.0, math.nan
    distance = point_segment_distances(pts, seg)
    error = float(distance.mean())
    coverage = float(np.mean(distance <= MAP_TOLERANCE_M))
    mids, _, weight = sample_segments(seg, SEGMENT_STEP_M, midpoints=True)
    total = float(weight.sum())
    if total <= 0.0:
        return error, coverage, math.nan
    near, _ = cKDTree(pts).query(mids, k=1, distance_upper_bound=2.0 * MAP_TOLERANCE_M, workers=-1)
    precision = float(weight[near <= MAP_TOLERANCE_M].sum()) / total
    return error, coverage, precision


# ------------------------------------------------------------------------------------ evaluate


def _pooled_rmse(squares: Sequence[FloatArray]) -> float:
    values = np.concatenate(list(squares)) if squares else np.zeros(0)
    return float(np.sqrt(values.mean())) if values.size else math.nan


class _Alignments:
    """The candidate alignments of :func:`evaluate`. A candidate is named by the robots it is
    fitted to; each is fitted and scored once (evaluate asks for the same ones several times):
    its squared position errors for every posed robot, the robots it places and their pooled
    RMSE."""

    def __init__(
        self,
        est: Mapping[str, FloatArray],
        ref: Mapping[str, FloatArray],
        reported_unmerged: set[str],
    ) -> None:
        self.est, self.ref = est, ref
        self.with_poses = [r for r in est if len(est[r])]
        self.reported_unmerged = reported_unmerged
        self._fits: dict[Robots, FloatArray] = {}
        self._errors: dict[Robots, dict[str, FloatArray]] = {}
        self._placements: dict[Robots, tuple[list[str], float]] = {}

    def fit(self, robots: Robots) -> FloatArray:
        """``T_ref_map`` fitted to the posed scans of ``robots`` (the identity for none)."""
        if robots not in self._fits:
            self._fits[robots] = (
                align_se2(
                    np.vstack([self.est[r] for r in robots]),
                    np.vstack([self.ref[r] for r in robots]),
                )
                if robots
                else np.eye(3)
            )
        return self._fits[robots]

    def squares_under(self, robots: Robots) -> dict[str, FloatArray]:
        """Every posed robot's squared position errors under the fit to ``robots``."""
        if robots not in self._errors:
            T = self.fit(robots)
            self._errors[robots] = {r: self._squares(T, r) for r in self.with_poses}
        return self._errors[robots]

    def _squares(self, T: FloatArray, robot: str) -> FloatArray:
        moved = se2.transform_points(T, self.est[robot][:, :2])
        return np.asarray(np.sum((moved - self.ref[robot][:, :2]) ** 2, axis=1))

    def rmse(self, robots: Robots, robot: str) -> float:
        """``robot``'s position RMSE under the fit to ``robots``; NaN when it has no posed scan."""
        if robot not in self.with_poses:
            return math.nan
        return _pooled_rmse([self.squares_under(robots)[robot]])

    def ate(self, robots: Robots) -> float:
        """The pooled position RMSE of ``robots`` under their own joint fit; NaN for none."""
        if not robots:
            return math.nan
        sq = self.squares_under(robots)
        return _pooled_rmse([sq[r] for r in robots])

    def placement(self, robots: Robots) -> tuple[list[str], float]:
        """The robots the fit to ``robots`` places (RMSE below MERGE_RMSE_M, never one the
        method reported unmerged) and their pooled RMSE (0 when it places none)."""
        if robots not in self._placements:
            sq = self.squares_under(robots)
            placed = [
                r
                for r in self.with_poses
                if r not in self.reported_unmerged and _pooled_rmse([sq[r]]) < MERGE_RMSE_M
            ]
            rmse = _pooled_rmse([sq[r] for r in placed]) if placed else 0.0
            self._placements[robots] = placed, rmse
        return self._placements[robots]

    def best_of(self, candidates: Sequence[Robots]) -> tuple[Robots, list[str]]:
        """The candidate placing the most robots, then with the lowest RMSE over them (the
        earlier on a tie), and the robots it places."""
        best, best_placed, best_key = candidates[0], [], (-1, 0.0)
        for candidate in candidates:
            placed, rmse = self.placement(candidate)
            key = (len(placed), -rmse)
            if key > best_key:
                best, best_placed, best_key = candidate, placed, key
        return best, best_placed

    def chosen(self) -> tuple[Robots, list[str]]:
        """The winning candidate of :func:`evaluate` (its docstring says how it is chosen)
        and the robots it places."""
        candidates = [tuple(self.with_poses), *((r,) for r in self.with_poses)]
        winner, merged = self.best_of(candidates)
        if merged:
            winner, merged = self.best_of([*candidates, tuple(merged)])
        return winner, merged


def _robot_metrics(
    robot: str,
    track: RobotTrack,
    pairs: PairErrors,
    alignments: _Alignments,
    winner: Robots,
    merged: list[str],
) -> RobotMetrics:
    """One robot's figures, scored under the alignment fitted to ``winner``."""
    both, translation, rotation = pairs
    success, strict, med_t, med_r = _pair_summary(both, translation, rotation)
    return RobotMetrics(
        scans=len(track.stamps),
        scans_unposed=int(np.count_nonzero(~track.posed)),
        pairs=len(both),
        pair_success=success,
        pair_success_strict=strict,
        median_translation_error_m=med_t,
        median_rotation_error_rad=med_r,
        rmse_m=alignments.rmse(winner, robot),
        ate_own_frame_m=alignments.rmse((robot,), robot),
        merged=robot in merged,
        reported_unmerged=robot in alignments.reported_unmerged,
    )


def _pooled_pair_summary(errors: Sequence[PairErrors]) -> tuple[float, float, float, float]:
    """:func:`_pair_summary` over the consecutive scan pairs of every robot together."""
    return _pair_summary(
        np.concatenate([e[0] for e in errors]) if errors else np.zeros(0, dtype=bool),
        np.concatenate([e[1] for e in errors]) if errors else np.zeros(0),
        np.concatenate([e[2] for e in errors]) if errors else np.zeros(0),
    )


def evaluate(
    tracks: Mapping[str, RobotTrack],
    map_segments: FloatArray,
    reference_points: FloatArray,
    robot_frames: Mapping[str, Pose | None] | None = None,
) -> Metrics:
    """Every metric of section 5 of the evaluation issue.

    ``map_segments`` (M, 4) are in the ``map`` frame of the estimates, ``reference_points``
    (P, 2) in the reference frame. ``robot_frames`` as in the replay results: a robot whose
    frame is ``None`` ("unmerged") is never counted as merged.

    The merged robots are the most that one alignment places (position RMSE < MERGE_RMSE_M).
    Candidates are the least-squares fit to all posed scans and to each robot's own posed scans,
    then the fit to the best candidate's placed robots; the candidate placing the most robots
    wins, ties go to the lowest RMSE over the placed robots (then to the earlier candidate, the
    all-scan fit first). The winner is ``T_ref_map``: per-robot RMSE and the map are scored
    under it.
    """
    names = list(tracks)
    frames = dict(robot_frames or {})
    alignments = _Alignments(
        est={r: tracks[r].estimate[tracks[r].posed] for r in names},
        ref={r: tracks[r].reference[tracks[r].posed] for r in names},
        reported_unmerged={r for r in names if r in frames and frames[r] is None},
    )
    winner, merged = alignments.chosen()
    T_ref_map = alignments.fit(winner)
    pairs = {r: pair_errors(tracks[r]) for r in names}
    robot_metrics = {
        r: _robot_metrics(r, tracks[r], pairs[r], alignments, winner, merged) for r in names
    }
    success, strict, med_t, med_r = _pooled_pair_summary(list(pairs.values()))

    segments = np.asarray(map_segments, dtype=np.float64).reshape(-1, 4)
    points = np.asarray(reference_points, dtype=np.float64).reshape(-1, 2)
    error, coverage, precision = map_scores(se2.transform_segments(T_ref_map, segments), points)

    return Metrics(
        robots_total=len(names),
        robots_merged=len(merged),
        merged_robots=[r for r in names if r in merged],
        scans_total=sum(m.scans for m in robot_metrics.values()),
        scans_unposed=sum(m.scans_unposed for m in robot_metrics.values()),
        pair_success=success,
        pair_success_strict=strict,
        median_translation_error_m=med_t,
        median_rotation_error_rad=med_r,
        ate_rmse_m=alignments.ate(tuple(merged)),
        ate_all_rmse_m=alignments.ate(tuple(alignments.with_poses)),
        map_error_m=error,
        map_coverage=coverage,
        map_precision=precision,
        map_segments=len(segments),
        reference_points=len(points),
        T_ref_map=T_ref_map,
        robots=robot_metrics,
    )
