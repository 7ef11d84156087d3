"""What the joint merger matches: pieces of robots' maps and the places along them.

A robot's ``partial_map`` is a list of keyframes, each with its pose in its *piece*'s frame
and the fused map segments it owns in its own frame. A piece is rigid in itself and unrelated
to the robot's other pieces until its mapper joins them (the robot was lost in between), so
the merger treats every piece as a map of its own: a :class:`MapUnit`.

A :class:`Place` is a keyframe and the unit's map around it: every segment of the unit within
``place_radius`` of the keyframe (clipped there), in the keyframe's frame, with the unit's
keyframes near it as viewpoints. Links between robots are matches of places: a place is small
enough that the drift of a robot's map across it is negligible (a bent map is placed place by
place), and a robot pair gets as many links as it has places in common. A place's viewpoints
carry *synthetic* beams: the place's own walls ray cast from each keyframe pose. The merger has
no scans, but what a robot's map says it saw from where it stood is the same evidence
INTEGRATE's confidence weighs (walls of the other map lying in free space, returns confirmed),
and a bearing on which the map has no wall claims nothing (:func:`viewpoints`).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
from collections import OrderedDict
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.matching.beams import Viewpoint
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.free_space import MapViews, ViewFan
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.segment_map import SegmentMap

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
UnitKey = tuple[str, int]  # (robot, piece)


@dataclasses.dataclass(frozen=True)
class MapUnit:
    """One piece of one robot's map: its keyframes, in the piece's frame."""

    robot: str
    piece: int  # the piece's first keyframe index (0: the robot's map frame)
    index: IntArray  # (K,) keyframe indices (the wire's marker ids), ascending
    stamps: FloatArray  # (K,) keyframe stamps (s)
    poses: FloatArray  # (K, 3) T_unit_keyframe
    local: list[FloatArray]  # K arrays (N_k, 4): each keyframe's segments in its own frame
    segments: FloatArray  # (N, 4) every keyframe's segments in the unit's frame
    owner: IntArray  # (N,) row (into index) of each segment's keyframe

    @property
    def key(self) -> UnitKey:
        return (self.robot, self.piece)

    @functools.cached_property
    def segment_map(self) -> SegmentMap:
        """``segments`` as a map, made once per unit: its lines, length and digest."""
        return SegmentMap.of(self.segments)

    @functools.cached_property
    def content(self) -> str:
        """A digest of the keyframe poses and segments, made once per unit: what the merge's
        caches are keyed on (every stage of an update reads it)."""
        return hashlib.sha1(self.poses.tobytes() + self.segment_map.digest.encode()).hexdigest()

    @property
    def length(self) -> float:
        """Total wall length (m)."""
        return self.segment_map.total_length

    def row(self, keyframe: int) -> int:
        """Row of keyframe index ``keyframe`` in this unit's arrays."""
        return int(np.searchsorted(self.index, keyframe))


def unit_name(key: UnitKey) -> str:
    """``robot`` for a robot's main frame, ``robot/map_<piece>`` for another piece."""
    robot, piece = key
    return robot if piece == 0 else f"{robot}/map_{piece}"


def units_of(keyframes: Mapping[str, Sequence[Keyframe]]) -> dict[UnitKey, MapUnit]:
    """Every robot's keyframes grouped into units (one per piece), keyframes in index order.
    Keyframes with non-finite poses or segments are left out (bad input never spreads)."""
    units: dict[UnitKey, MapUnit] = {}
    for robot, frames in keyframes.items():
        by_piece: dict[int, list[Keyframe]] = {}
        for kf in frames:
            pose = np.asarray(kf.T_robotmap_keyframe, dtype=np.float64).reshape(3)
            segments = np.asarray(kf.segments, dtype=np.float64).reshape(-1, 4)
            if not np.isfinite(pose).all() or not np.isfinite(segments).all():
                continue
            by_piece.setdefault(int(kf.piece), []).append(kf)
        for piece, members in by_piece.items():
            members = sorted(members, key=lambda kf: kf.index)
            poses = np.array([kf.T_robotmap_keyframe for kf in members], dtype=np.float64)
            local = [np.asarray(kf.segments, dtype=np.float64).reshape(-1, 4) for kf in members]
            owner = np.concatenate(
                [np.full(len(s), row, dtype=np.int64) for row, s in enumerate(local)]
            )
            stacked = np.vstack(local)
            placed = se2.transform_segments_each(poses[owner], stacked)
            units[(str(robot), piece)] = MapUnit(
                robot=str(robot),
                piece=piece,
                index=np.array([kf.index for kf in members], dtype=np.int64),
                stamps=np.array([kf.stamp for kf in members], dtype=np.float64),
                poses=poses.reshape(-1, 3),
                local=local,
                segments=placed.reshape(-1, 4),
                owner=owner,
            )
    return units


@dataclasses.dataclass(frozen=True)
class Place:
    """A keyframe and its unit's map around it, in the keyframe's frame."""

    unit: UnitKey
    centre: int  # keyframe index
    T_unit_centre: FloatArray  # (3,) x, y, theta
    segments: FloatArray  # (M, 4) the unit's walls within place_radius, clipped, centre frame
    views: MapViews  # the place's walls seen from the unit's keyframes near the centre
    length: float  # total wall length (m)
    digest: str  # content hash (segments and viewpoints): equal digests, same place

    @functools.cached_property
    def segment_map(self) -> SegmentMap:
        """``segments`` as a map, made once per place (matched on every other map)."""
        return SegmentMap.of(self.segments)


def clip_to_disk(segments: FloatArray, centre: FloatArray, radius: float) -> FloatArray:
    """The parts of ``segments`` inside the disk of ``radius`` around ``centre``."""
    if len(segments) == 0:
        return segments.reshape(0, 4)
    p0 = segments[:, :2] - centre
    d = segments[:, 2:] - segments[:, :2]
    a = np.einsum("ij,ij->i", d, d)
    b = 2.0 * np.einsum("ij,ij->i", p0, d)
    c = np.einsum("ij,ij->i", p0, p0) - radius**2
    disc = b * b - 4.0 * a * c
    hit = (disc > 0.0) & (a > 0.0)
    root = np.sqrt(np.where(hit, disc, 0.0))
    safe = np.where(a > 0.0, a, 1.0)
    low = np.clip((-b - root) / (2.0 * safe), 0.0, 1.0)
    high = np.clip((-b + root) / (2.0 * safe), 0.0, 1.0)
    keep = hit & (high - low > 1e-9)
    start = segments[keep, :2] + low[keep, None] * d[keep]
    end = segments[keep, :2] + high[keep, None] * d[keep]
    return np.asarray(np.hstack((start, end)))


def viewpoints(views: MapViews, view_range: float) -> list[Viewpoint]:
    """A map's synthetic views (its own walls ray cast from its keyframe poses) as the
    viewpoints INTEGRATE's beam evidence takes: one scan per pose, in the laser frame (no
    wall within ``view_range`` m on a bearing: no return)."""
    beams = views.ranges.shape[1]
    out = []
    for pose, row in zip(views.poses, views.ranges, strict=True):
        scan = LaserScanData(
            ranges=np.asarray(row, dtype=np.float64),
            angle_min=views.angle_min,
            angle_max=views.angle_min + views.angle_increment * (beams - 1),
            angle_increment=views.angle_increment,
            range_min=0.0,
            range_max=view_range,
        )
        out.append(Viewpoint(scan, se2.matrix_from_pose(*pose)))
    return out


def thin(poses: FloatArray, spacing: float) -> IntArray:
    """Rows of ``poses`` kept greedily in order, each at least ``spacing`` from those kept."""
    kept: list[int] = []
    for row in range(len(poses)):
        if not kept or np.min(np.hypot(*(poses[kept, :2] - poses[row, :2]).T)) >= spacing:
            kept.append(row)
    return np.asarray(kept, dtype=np.int64)


# A place's inputs (its unit and centre keyframe, the centre's pose, its clipped walls and its
# viewpoints, the config) to the place made of them: PlaceIndex, kept in the merge's state.
PlaceIndex = OrderedDict[tuple[UnitKey, int, str, MergeConfig], Place]


def places_of(unit: MapUnit, config: MergeConfig, index: PlaceIndex | None = None) -> list[Place]:
    """The unit's places: keyframes at least ``place_spacing`` apart (greedily, oldest first,
    so that a growing map keeps its earlier places), each with the unit's walls within
    ``place_radius``; places with less than ``place_min_length`` of wall are left out.

    ``index``: places made before, by their exact inputs. A robot's map grows at its end: of
    a map that changed, most places have the same walls and viewpoints as before, and their
    ray cast views (most of a place's cost) are taken from ``index`` (issue 50)."""
    places = []
    for row in thin(unit.poses, config.place_spacing):
        pose = unit.poses[row]
        T_centre_unit = se2.invert(se2.matrix_from_pose(*pose))
        inside = clip_to_disk(unit.segments, pose[:2], config.place_radius)
        segments = se2.transform_segments(T_centre_unit, inside)
        length = SegmentMap.of(segments).total_length
        if length < config.place_min_length:
            continue
        near = np.hypot(*(unit.poses[:, :2] - pose[:2]).T) <= config.place_radius
        rows = np.flatnonzero(near)
        rows = rows[thin(unit.poses[rows], config.view_spacing)]
        view_poses = np.array(
            [
                se2.pose_from_matrix(T_centre_unit @ se2.matrix_from_pose(*unit.poses[r]))
                for r in rows
            ]
        ).reshape(-1, 3)
        inputs = np.concatenate((pose, [len(segments)], segments.ravel(), view_poses.ravel()))
        key = (unit.key, int(unit.index[row]), hashlib.sha1(inputs.tobytes()).hexdigest(), config)
        place = index.get(key) if index is not None else None
        if place is None:
            place = _place(unit, row, segments, view_poses, length, config.view_fan())
        if index is not None:
            index[key] = place
            index.move_to_end(key)  # the oldest unused are dropped first (the caller's cap)
        places.append(place)
    return places


def _place(
    unit: MapUnit,
    row: int,
    segments: FloatArray,
    view_poses: FloatArray,
    length: float,
    fan: ViewFan,
) -> Place:
    """The place of ``unit``'s keyframe ``row``: its walls (``segments``, ``length`` m) and
    viewpoints (``view_poses``) in the centre's frame, ray cast (:meth:`MapViews.of` with
    ``fan``)."""
    digest = hashlib.sha1(
        np.round(segments, 3).tobytes() + np.round(view_poses, 3).tobytes()
    ).hexdigest()
    return Place(
        unit=unit.key,
        centre=int(unit.index[row]),
        T_unit_centre=unit.poses[row].copy(),
        segments=segments,
        views=MapViews.of(segments, view_poses, fan),
        length=length,
        digest=digest,
    )
