"""Wolter's shape-based matching as a second source of placements for the merger's places
(issue 14, item 3; ``merge.shape_hypotheses``).

A partial map carries no scans, but its keyframe poses say where the laser stood: the map's
walls ray cast all round from a keyframe are a synthetic scan in the laser's order, and
Wolter's shape (DCE polylines, Sec. 3) is made from it as from a real scan. All round, not
the laser's field: two robots crossing a place in opposite directions saw opposite halves of
it, while their maps hold all of it. A place's centre is matched on the target map's
viewpoints:

1. every target view is ranked by the shape it shares with the place's view: what the
   first-pass correspondence (Wolter Eq. 4 on shape alone, order-preserving) saves over
   leaving every polyline unmatched (:func:`shared_shape`). Ranking by Eq. 5's most reliable
   pair instead put the target's own view of the place 10th to 51st of 60 when a map was
   matched on itself: one long intricate polyline anywhere outranks a plain room;
2. the best ``shape_hypotheses`` views are matched in full (:func:`match_shapes`: Eq. 4's
   order-preserving correspondence, then Cox's alignment), and each aligned pose becomes a
   placement of the place's centre in the target's frame.

A full turn has no first bearing: the place's polylines are taken twice round
(:func:`_twice_round`), so that the order-preserving correspondence finds the target's
order starting anywhere in them (the paper's scans are 180 deg and not cyclic).

The correlation's placements and these are verified together by INTEGRATE
(:func:`~multi_robot_mapper.core.merging.place_links.match_place`): a shape placement counts only
where the map's walls and beams confirm it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.shape import (
    Shape,
    match_shapes,
    shape_of_scan,
    shared_shape,
)
from multi_robot_mapper.core.matching.shape_config import ShapeConfig
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import raycast_fans

FloatArray = NDArray[np.float64]

_BEAMS = 360  # bearings of a synthetic scan all round (1 deg)


def view_shapes(
    segments: FloatArray, poses: FloatArray, max_range: float, config: ShapeConfig
) -> list[Shape]:
    """Wolter's shape of a map seen all round from each of ``poses`` (its walls ray cast out
    to ``max_range``), each in its view's frame."""
    step = 2.0 * np.pi / _BEAMS
    first = -np.pi
    ranges = raycast_fans(
        segments, np.asarray(poses).reshape(-1, 3), first, step, _BEAMS, max_range
    )
    return [
        shape_of_scan(
            LaserScanData(
                ranges=row,
                angle_min=first,
                angle_max=first + step * (_BEAMS - 1),
                angle_increment=step,
                range_min=0.0,
                range_max=max_range,
            ),
            config,
        )
        for row in ranges
    ]


def _twice_round(shape: Shape) -> Shape:
    """The shape's polylines twice in a row (a full turn read from any first polyline)."""
    size = len(shape.vertices)
    return Shape(
        np.vstack((shape.vertices, shape.vertices)),
        np.concatenate((shape.start, shape.start + size)),
        np.concatenate((shape.stop, shape.stop + size)),
    )


def shape_placements(
    place_segments: FloatArray,
    target_poses: FloatArray,
    target_shapes: list[Shape],
    count: int,
    max_range: float,
    config: ShapeConfig,
) -> FloatArray:
    """Up to ``count`` placements of a place's centre on the target map, as rows
    (theta, x, y) in the target's frame: the place (``place_segments`` in its centre's frame)
    seen all round from its centre, matched on the ``count`` target views (``target_shapes``
    from ``target_poses``) that share the most shape with it (steps 1-2 above)."""
    if count <= 0 or not target_shapes:
        return np.zeros((0, 3))
    perceived = view_shapes(place_segments, np.zeros((1, 3)), max_range, config)[0]
    if len(perceived) == 0:
        return np.zeros((0, 3))
    perceived = _twice_round(perceived)
    shared = np.array([shared_shape(shape, perceived, config) for shape in target_shapes])
    ranked = np.argsort(-shared, kind="stable")[:count]
    rows = []
    for view in ranked.tolist():
        if shared[view] <= 0.0:
            continue
        found = match_shapes(target_shapes[view], perceived, config)
        if not found.valid:
            continue
        # T_target_centre = T_target_view · T_view_centre (the place's view is its centre)
        x, y, theta = se2.pose_from_matrix(se2.matrix_from_pose(*target_poses[view]) @ found.matrix)
        rows.append((theta, x, y))
    return np.asarray(rows, dtype=np.float64).reshape(-1, 3)
