"""Free-space consistency: what one scan's beams say about another scan's walls and returns."""

from __future__ import annotations

import dataclasses
import math
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import TypeVar, cast

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import sample_segments
from multi_robot_mapper.core.matching.config import IntegrateConfig
from multi_robot_mapper.core.scan import LaserScanData, scan_points
from multi_robot_mapper.core.segment_map import MapLike, SegmentMap

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
T = TypeVar("T")


def seen_through(
    view: LaserScanData, points: FloatArray, margin: float, spread: int = 0
) -> BoolArray:
    """Points (in the view's laser frame) lying in free space that the view's beams crossed.

    A point is seen through when every beam within ``spread`` beams of its bearing returned
    from more than ``margin`` beyond it: a wall seen at a grazing angle returns very different
    ranges on neighbouring beams. Beams without a valid return say nothing.
    """
    return _beam_evidence(view, points, margin, spread)[0]


def _beam_position(view: LaserScanData, bearing: FloatArray) -> FloatArray:
    """Each bearing's position in beams from the view's first beam, clipped to one beam
    outside either end (-1 or the beam count): a tiny angle_increment (a broken driver
    let through with ``min_field_of_view`` 0) puts bearings up to 1e300 beams away or at
    infinity, which the integer cast of the callers would overflow."""
    with np.errstate(over="ignore"):
        position = (bearing - view.angle_min) / view.angle_increment
    return np.clip(position, -1.0, float(np.asarray(view.ranges).size))


@dataclasses.dataclass(frozen=True)
class _BeamTable:
    """What a view's beams say before any point is asked (read only)."""

    ranges: FloatArray
    valid: BoolArray  # a return within the laser's limits
    returned: FloatArray  # the range where valid, else inf (confirms nothing)
    nearest: FloatArray  # the shortest valid return within ``spread`` beams, else -inf


class _KeptPerView:
    """What was made from the views matched most recently (a keyframe's scan is judged many
    times per match: each hypothesis, rival and slide), keyed by the view object and one
    parameter; the view is kept with it, so its id is not reused while kept. Thread-safe: a
    node's front end and back end share it."""

    def __init__(self, size: int = 256) -> None:
        self._size = size
        self._kept: OrderedDict[int, tuple[LaserScanData, object, object]] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, view: LaserScanData, parameter: object, make: Callable[[], T]) -> T:
        with self._lock:
            kept = self._kept.get(id(view))
            if kept is not None and kept[0] is view and kept[1] == parameter:
                self._kept.move_to_end(id(view))
                return cast(T, kept[2])
        made = make()
        with self._lock:
            self._kept[id(view)] = (view, parameter, made)
            if len(self._kept) > self._size:
                self._kept.popitem(last=False)
        return made


_TABLES = _KeptPerView()


def _beam_table(view: LaserScanData, spread: int) -> _BeamTable:
    return _TABLES.get(view, spread, lambda: _make_beam_table(view, spread))


def _make_beam_table(view: LaserScanData, spread: int) -> _BeamTable:
    ranges = np.array(view.ranges, dtype=np.float64)  # a copy: the table is read only
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(ranges) & (ranges >= view.range_min) & (ranges < view.range_max)
    # Invalid beams never contradict nor confirm; the shortest return around each beam is the
    # free-space test.
    nearest = np.where(valid, ranges, -np.inf)
    if spread > 0:
        padded = np.concatenate((np.full(spread, -np.inf), nearest, np.full(spread, -np.inf)))
        window = np.lib.stride_tricks.sliding_window_view(padded, 2 * spread + 1).min(axis=1)
        nearest = np.where(valid, window, -np.inf)
    table = _BeamTable(ranges, valid, np.where(valid, ranges, np.inf), nearest)
    for array in (table.ranges, table.valid, table.returned, table.nearest):
        array.flags.writeable = False
    return table


def _beam_evidence(
    view: LaserScanData, points: FloatArray, margin: float, spread: int
) -> tuple[BoolArray, BoolArray]:
    """For points in the view's laser frame: seen through (:func:`seen_through`), and
    confirmed, lying within ``margin`` of the return of the beam nearest their bearing."""
    table = _beam_table(view, spread)
    ranges, nearest, returned = table.ranges, table.nearest, table.returned
    bearing = np.arctan2(points[:, 1], points[:, 0])
    distance = np.hypot(points[:, 0], points[:, 1])
    beam = np.rint(_beam_position(view, bearing)).astype(np.int64)
    outside = (beam < 0) | (beam >= ranges.size)
    beam[outside] = 0
    free = np.where(outside, -np.inf, nearest[beam])
    hit = np.where(outside, np.inf, returned[beam])
    return np.asarray(distance < free - margin), np.asarray(np.abs(distance - hit) <= margin)


@dataclasses.dataclass(frozen=True)
class Viewpoint:
    """A scan and where its laser stood in the frame of the set it belongs to."""

    scan: LaserScanData
    T_set_laser: FloatArray  # 3x3

    @staticmethod
    def at_origin(scan: LaserScanData) -> Viewpoint:
        return Viewpoint(scan, np.eye(3))


@dataclasses.dataclass(frozen=True)
class ViewReturns:
    """A set's returns in the set's frame, each weighted by the surface it stands for."""

    points: FloatArray  # (P, 2)
    weights: FloatArray  # (P,) metres of surface

    @staticmethod
    def of(viewpoints: list[Viewpoint], cap: float) -> ViewReturns:
        """Every viewpoint's returns (at most one per degree), moved into the set's frame; each
        return stands for the smaller gap to a neighbouring return, at most ``cap``."""
        pieces, weights = [], []
        for viewpoint in viewpoints:
            points, weight = scan_returns(viewpoint.scan, cap)
            pieces.append(se2.transform_points(viewpoint.T_set_laser, points))
            weights.append(weight)
        if not pieces:
            return ViewReturns(np.zeros((0, 2)), np.zeros(0))
        return ViewReturns(np.vstack(pieces), np.concatenate(weights))

    @property
    def total(self) -> float:
        return float(self.weights.sum())


_RETURNS = _KeptPerView()


def scan_returns(view: LaserScanData, cap: float) -> tuple[FloatArray, FloatArray]:
    """A scan's returns in its laser frame (at most one per degree), each weighted by the
    surface it stands for: the smaller gap to a neighbouring return, at most ``cap``. Kept
    for the scans matched most recently (read only)."""
    return _RETURNS.get(view, cap, lambda: _scan_returns(view, cap))


def _scan_returns(view: LaserScanData, cap: float) -> tuple[FloatArray, FloatArray]:
    points = scan_points(view).points
    # About one return per degree; a tiny increment asks for a stride beyond the scan (at
    # 5e-324 rad an infinite one, which round() refuses): the first return is then kept.
    stride = min(math.radians(1.0) / abs(view.angle_increment), max(len(points), 1))
    points = points[:: max(1, round(stride))]
    if len(points) < 2:
        weights = np.full(len(points), cap)
    else:
        gap = np.hypot(*np.diff(points, axis=0).T)
        gap = np.minimum(np.concatenate((gap, gap[-1:])), np.concatenate((gap[:1], gap)))
        weights = np.minimum(gap, cap)
    points.flags.writeable = False  # kept: read only
    weights.flags.writeable = False
    return points, weights


@dataclasses.dataclass(frozen=True)
class BeamAgreement:
    """Metres of surface of one set, judged by the other set's beams."""

    confirmed: float  # where a beam of the other ended (within the margin)
    seen_through: float  # where the other's beams passed on (a contradiction)
    occluded: float  # behind what the other saw
    outside: float  # outside the other's fields of view and ranges
    total: float

    @staticmethod
    def nothing() -> BeamAgreement:
        """No returns at all."""
        return BeamAgreement(0.0, 0.0, 0.0, 0.0, 0.0)

    @staticmethod
    def unjudged(total: float) -> BeamAgreement:
        """Returns of ``total`` metres that no beam judged (the other side's views unknown)."""
        return BeamAgreement(0.0, 0.0, 0.0, total, total)

    def as_array(self) -> FloatArray:
        return np.array(
            [self.confirmed, self.seen_through, self.occluded, self.outside, self.total]
        )

    def __add__(self, other: BeamAgreement) -> BeamAgreement:
        return BeamAgreement(
            self.confirmed + other.confirmed,
            self.seen_through + other.seen_through,
            self.occluded + other.occluded,
            self.outside + other.outside,
            self.total + other.total,
        )


def beam_categories(
    view: LaserScanData, points: FloatArray, margin: float, spread: int
) -> tuple[BoolArray, BoolArray, BoolArray]:
    """For points in the view's laser frame: (confirmed, seen through, visible).

    *Confirmed*: within ``margin`` of the range the view measured on that bearing, read
    between the two nearest beams when both returned from one surface (a slanted wall's
    range changes from beam to beam). *Seen through*: nearer than every return within
    ``spread`` beams by more than ``margin`` (a grazing wall's neighbouring beams differ;
    one short beam is not free space). *Visible*: on a bearing with a valid return and not
    behind it by more than ``margin``. Beams without a valid return say nothing.
    """
    table = _beam_table(view, spread)
    ranges, valid, nearest = table.ranges, table.valid, table.nearest
    count = ranges.size
    bearing = np.arctan2(points[:, 1], points[:, 0])
    distance = np.hypot(points[:, 0], points[:, 1])
    position = _beam_position(view, bearing)
    beam = np.rint(position).astype(np.int64)
    inside = (beam >= 0) & (beam < count)
    beam = np.clip(beam, 0, count - 1)
    low = np.clip(np.floor(position).astype(np.int64), 0, max(count - 2, 0))
    high = np.minimum(low + 1, count - 1)
    r_low, r_high = ranges[low], ranges[high]
    share = np.clip(position - low, 0.0, 1.0)
    with np.errstate(invalid="ignore"):  # where a beam has no return: not read below
        jump = np.abs(r_high - r_low) <= 2.0 * margin + 0.05 * r_low
        both = valid[low] & valid[high] & jump
        measured = np.where(both, r_low + share * (r_high - r_low), ranges[beam])
    hit = inside & valid[beam]
    with np.errstate(invalid="ignore"):
        confirmed = hit & (np.abs(distance - measured) <= margin)
        through = inside & (distance < nearest[beam] - margin) & ~confirmed
        visible = hit & (distance <= measured + margin)
    return np.asarray(confirmed), np.asarray(through), np.asarray(visible)


def beam_agreement(
    returns: ViewReturns,
    T_other_set: FloatArray,
    viewpoints: list[Viewpoint],
    margin: float,
    spread: int,
) -> BeamAgreement:
    """How the other set's viewpoints judge these returns (moved by ``T_other_set`` into the
    other set's frame). A return confirmed by any viewpoint is confirmed; else seen through by
    any, seen through; else visible to one, occluded; else outside."""
    count = len(returns.points)
    confirmed = np.zeros(count, dtype=bool)
    through = np.zeros(count, dtype=bool)
    visible = np.zeros(count, dtype=bool)
    if count:
        for viewpoint in viewpoints:
            T_laser_set = se2.invert(viewpoint.T_set_laser) @ T_other_set
            local = se2.transform_points(T_laser_set, returns.points)
            ok, passed, seen = beam_categories(viewpoint.scan, local, margin, spread)
            confirmed |= ok
            through |= passed
            visible |= seen | passed
    through &= ~confirmed
    occluded = visible & ~confirmed & ~through
    w = returns.weights
    return BeamAgreement(
        float(w[confirmed].sum()),
        float(w[through].sum()),
        float(w[occluded].sum()),
        float(w[~(confirmed | through | occluded)].sum()),
        returns.total,
    )


def _segment_points(segment_map: SegmentMap, min_length: float) -> tuple[FloatArray, FloatArray]:
    """Points every 5 cm along the segments of at least ``min_length`` (m)."""
    spacing = 0.05
    if len(segment_map) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    long = segment_map.segments[segment_map.length >= min_length]
    if len(long) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    points, _ = sample_segments(long, spacing)
    return points, np.full(len(points), spacing)


Views = LaserScanData | list[Viewpoint] | None
"""What one side of a match was seen from: one scan (its laser at the set's origin), several
(a submap: each keyframe's scan at its pose), or nothing known."""


def viewpoints_of(views: Views) -> list[Viewpoint] | None:
    """One side's views as a list of viewpoints (None: no views known)."""
    if views is None:
        return None
    if isinstance(views, LaserScanData):
        return [Viewpoint.at_origin(views)]
    return list(views) or None


def beam_limits(config: IntegrateConfig) -> tuple[float, int, float, float]:
    """What :func:`seen_through_many` reads of ``config`` (its ``limits``)."""
    return (
        config.free_space_margin,
        config.free_space_spread,
        config.view_point_length,
        config.free_space_min_length,
    )


def seen_through_many(
    map1: MapLike,
    map2: MapLike,
    transforms: FloatArray,
    views: tuple[Views, Views],
    limits: tuple[float, int, float, float],
) -> tuple[FloatArray, FloatArray]:
    """Per transform: the length of each set lying in the other's observed free space, and
    the length the other's beams confirm (ending within ``margin`` of it). ``limits``:
    ``(margin, spread, cap, min_length)``, IntegrateConfig's ``free_space_margin``,
    ``free_space_spread`` (beams), ``view_point_length`` and ``free_space_min_length``.

    With both sides' views the tested points are the views' own returns (a corridor's far end
    is a few sparse returns, too few for a segment, and it is what fixes the offset along the
    corridor); with one side's, points along the other set's long segments (short ones are
    mostly people, who move between scans). A side seen from several viewpoints (a submap)
    counts a point seen through, or confirmed, when any of its viewpoints does.
    """
    views1, views2 = viewpoints_of(views[0]), viewpoints_of(views[1])
    through = np.zeros(len(transforms))
    confirmed = np.zeros(len(transforms))
    if (views1 is None and views2 is None) or len(transforms) == 0:
        return through, confirmed
    margin, spread, cap, min_length = limits
    if views1 is not None and views2 is not None:
        returns1, returns2 = ViewReturns.of(views1, cap), ViewReturns.of(views2, cap)
        points1, weight1 = returns1.points, returns1.weights
        points2, weight2 = returns2.points, returns2.weights
    else:
        points2, weight2 = _segment_points(SegmentMap.of(map2), min_length)
        points1, weight1 = _segment_points(SegmentMap.of(map1), min_length)
    c, s = np.cos(transforms[:, 0])[:, None], np.sin(transforms[:, 0])[:, None]
    tx, ty = transforms[:, 1, None], transforms[:, 2, None]
    if views1 is not None and len(points2):
        # S2 points in S1's frame: q = R p + t, for every transform.
        qx = c * points2[None, :, 0] - s * points2[None, :, 1] + tx
        qy = s * points2[None, :, 0] + c * points2[None, :, 1] + ty
        hit, seen = _judged_by_any(np.stack((qx, qy), axis=-1), views1, margin, spread)
        through += hit @ weight2
        confirmed += seen @ weight2
    if views2 is not None and len(points1):
        # S1 points in S2's frame: p = R^T (q - t).
        dx, dy = points1[None, :, 0] - tx, points1[None, :, 1] - ty
        px, py = c * dx + s * dy, -s * dx + c * dy
        hit, seen = _judged_by_any(np.stack((px, py), axis=-1), views2, margin, spread)
        through += hit @ weight1
        confirmed += seen @ weight1
    return through, confirmed


def _judged_by_any(
    points: FloatArray, viewpoints: list[Viewpoint], margin: float, spread: int
) -> tuple[FloatArray, FloatArray]:
    """(T, P) seen through / confirmed of points (already in the viewpoints' set frame,
    one row per transform) by any of the viewpoints."""
    shape = (len(points), -1)
    hit = np.zeros(points.shape[:2], dtype=bool)
    seen = np.zeros(points.shape[:2], dtype=bool)
    for viewpoint in viewpoints:
        local = se2.transform_points(se2.invert(viewpoint.T_set_laser), points.reshape(-1, 2))
        h, k = _beam_evidence(viewpoint.scan, local, margin, spread)
        hit |= h.reshape(shape)
        seen |= k.reshape(shape)
    return hit, seen
