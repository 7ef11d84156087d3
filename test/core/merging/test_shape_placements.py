"""Wolter's shape matching as a source of placements for the merger's places
(core/merging/shape_placements.py), on geometry with a known answer."""

from __future__ import annotations

import numpy as np
import pytest

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.shape import shape_of_points, shared_shape
from multi_robot_mapper.core.matching.shape_config import ShapeConfig
from multi_robot_mapper.core.merging.places import clip_to_disk
from multi_robot_mapper.core.merging.shape_placements import shape_placements, view_shapes
from multi_robot_mapper.core.worlds import office_world

CONFIG = ShapeConfig()
RANGE = 6.0  # the place holds walls this far from its centre (place_radius)


def _placed_right(rows: np.ndarray, truth: np.ndarray) -> bool:
    """Is any row (theta, x, y) within 5 cm / 0.5 deg of the pose ``truth`` (x, y, theta)?"""
    for theta, x, y in rows:
        error = se2.between(truth, (x, y, theta))
        if np.hypot(error[0], error[1]) < 0.05 and abs(error[2]) < np.radians(0.5):
            return True
    return False


def test_a_shape_shares_all_of_itself_and_nothing_with_nothing() -> None:
    t = np.linspace(0.0, 1.0, 40)[:, None]
    points = np.vstack(((0.0, 2.0) + t * (3.0, 0.0), (3.0, 2.0) + t * (0.0, 2.0)))
    shape = shape_of_points(points, CONFIG)
    assert shared_shape(shape, shape, CONFIG) == pytest.approx(1.0)
    empty = shape_of_points(np.zeros((0, 2)), CONFIG)
    assert shared_shape(shape, empty, CONFIG) == 0.0


@pytest.mark.parametrize("turn_deg", [0.0, 35.0, 170.0, -120.0])
def test_a_place_is_found_on_a_moved_copy_of_its_map_whatever_its_heading(turn_deg: float) -> None:
    # The place: the office's walls within 6 m of (14, 9.5), a room with furniture, in the
    # place centre's frame (in the corridor, Cox's alignment slides along the walls: the
    # verification's refinement, not the shape, fixes a placement along a corridor).
    # The target map is the office moved rigidly; its views stand at the place's centre and
    # at four other spots. The full turn read from any first polyline (twice round) finds
    # the centre at any heading: a robot crossing the place the other way sees it turned.
    world = office_world()
    centre = np.array([14.0, 9.5, np.radians(turn_deg)])
    T_world_centre = se2.matrix_from_pose(*centre)
    place = se2.transform_segments(
        se2.invert(T_world_centre), clip_to_disk(world, centre[:2], RANGE)
    )
    target_from_world = (3.0, -7.0, 0.8)  # T_target_world as (x, y, theta)
    T_target_world = se2.matrix_from_pose(*target_from_world)
    target = se2.transform_segments(T_target_world, world)
    spots = [
        (14.0, 9.5, 0.3),
        (15.0, 2.5, 0.0),
        (4.0, 9.0, 1.0),
        (13.0, 11.0, -2.0),
        (2.0, 2.5, 0.5),
    ]
    poses = se2.compose_each(np.tile(target_from_world, (len(spots), 1)), np.array(spots))
    shapes = view_shapes(target, poses, RANGE, CONFIG)
    rows = shape_placements(place, poses, shapes, 2, RANGE, CONFIG)
    truth = se2.pose_from_matrix(T_target_world @ T_world_centre)
    assert _placed_right(rows, np.asarray(truth))
