"""Free-space consistency: what one scan's beams say about another scan's walls and returns."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.geometry import lines_of, sample_segments
from multi_robot_mapper.core.matching.config import IntegrateConfig
from multi_robot_mapper.core.scan import LaserScanData, scan_points

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def seen_through(
    view: LaserScanData, points: FloatArray, margin: float, spread: int = 0
) -> BoolArray:
    """Points (in the view's laser frame) lying in free space that the view's beams crossed.

    A point is seen through when every beam within ``spread`` beams of its bearing returned
    from more than ``margin`` beyond it: a wall seen at a grazing angle returns very different
    ranges on neighbouring beams. Beams without a valid return say nothing.
    """
    return _beam_evidence(view, points, margin, spread)[0]


def _beam_evidence(
    view: LaserScanData, points: FloatArray, margin: float, spread: int
) -> tuple[BoolArray, BoolArray]:
    """For points in the view's laser frame: seen through (:func:`seen_through`), and
    confirmed, lying within ``margin`` of the return of the beam nearest their bearing."""
    ranges = np.asarray(view.ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(ranges) & (ranges >= view.range_min) & (ranges < view.range_max)
    # Invalid beams never contradict nor confirm; the shortest return around each beam is the
    # free-space test.
    returned = np.where(valid, ranges, np.inf)
    nearest = np.where(valid, ranges, -np.inf)
    if spread > 0:
        padded = np.concatenate((np.full(spread, -np.inf), nearest, np.full(spread, -np.inf)))
        window = np.lib.stride_tricks.sliding_window_view(padded, 2 * spread + 1).min(axis=1)
        nearest = np.where(valid, window, -np.inf)
    bearing = np.arctan2(points[:, 1], points[:, 0])
    distance = np.hypot(points[:, 0], points[:, 1])
    beam = np.rint((bearing - view.angle_min) / view.angle_increment).astype(np.int64)
    outside = (beam < 0) | (beam >= ranges.size)
    beam[outside] = 0
    free = np.where(outside, -np.inf, nearest[beam])
    hit = np.where(outside, np.inf, returned[beam])
    return np.asarray(distance < free - margin), np.asarray(np.abs(distance - hit) <= margin)


def _view_points(view: LaserScanData, cap: float) -> tuple[FloatArray, FloatArray]:
    """A view's returns in its laser frame, each weighted by the surface it stands for (the
    smaller gap to a neighbouring return, at most ``cap``); one return per degree at most."""
    points = scan_points(view).points
    points = points[:: max(1, round(np.radians(1.0) / abs(view.angle_increment)))]
    if len(points) < 2:
        return points, np.full(len(points), cap)
    gap = np.hypot(*np.diff(points, axis=0).T)
    gap = np.minimum(np.concatenate((gap, gap[-1:])), np.concatenate((gap[:1], gap)))
    return points, np.minimum(gap, cap)


def _segment_points(segments: FloatArray, config: IntegrateConfig) -> tuple[FloatArray, FloatArray]:
    """Points every 5 cm along the segments of at least ``free_space_min_length``."""
    spacing = 0.05
    if len(segments) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    long = segments[lines_of(segments).length >= config.free_space_min_length]
    if len(long) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    points, _ = sample_segments(long, spacing)
    return points, np.full(len(points), spacing)


def seen_through_many(
    segments1: FloatArray,
    segments2: FloatArray,
    transforms: FloatArray,
    views: tuple[LaserScanData | None, LaserScanData | None],
    config: IntegrateConfig,
) -> tuple[FloatArray, FloatArray]:
    """Per transform: the length of each scan lying in the other's observed free space, and
    the length the other's beams confirm (ending within ``free_space_margin`` of it).

    With both views the tested points are the views' own returns (a corridor's far end is a
    few sparse returns, too few for a segment, and it is what fixes the offset along the
    corridor); with one view, points along the other set's long segments (short ones are
    mostly people, who move between scans).
    """
    view1, view2 = views
    through = np.zeros(len(transforms))
    confirmed = np.zeros(len(transforms))
    if (view1 is None and view2 is None) or len(transforms) == 0:
        return through, confirmed
    cap = config.view_point_length
    if view1 is not None and view2 is not None:
        points2, weight2 = _view_points(view2, cap)
        points1, weight1 = _view_points(view1, cap)
    else:
        points2, weight2 = _segment_points(segments2, config)
        points1, weight1 = _segment_points(segments1, config)
    c, s = np.cos(transforms[:, 0])[:, None], np.sin(transforms[:, 0])[:, None]
    tx, ty = transforms[:, 1, None], transforms[:, 2, None]
    margin, spread = config.free_space_margin, config.free_space_spread
    shape = (len(transforms), -1)
    if view1 is not None and len(points2):
        # S2 points in S1's frame: q = R p + t, for every transform.
        qx = c * points2[None, :, 0] - s * points2[None, :, 1] + tx
        qy = s * points2[None, :, 0] + c * points2[None, :, 1] + ty
        hit, seen = _beam_evidence(view1, np.column_stack((qx.ravel(), qy.ravel())), margin, spread)
        through += hit.reshape(shape) @ weight2
        confirmed += seen.reshape(shape) @ weight2
    if view2 is not None and len(points1):
        # S1 points in S2's frame: p = R^T (q - t).
        dx, dy = points1[None, :, 0] - tx, points1[None, :, 1] - ty
        px, py = c * dx + s * dy, -s * dx + c * dy
        hit, seen = _beam_evidence(view2, np.column_stack((px.ravel(), py.ravel())), margin, spread)
        through += hit.reshape(shape) @ weight1
        confirmed += seen.reshape(shape) @ weight1
    return through, confirmed
