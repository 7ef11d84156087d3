"""A place's placement hypotheses through the merger's own place search
(core/merging/place_links.py): the correlation's alone by default, the shapes' too when asked,
verified."""

from __future__ import annotations

import dataclasses

import numpy as np
from test_shape_placements import RANGE, _placed_right

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.merging.place_links import Target, placement_hypotheses
from multi_robot_mapper.core.merging.places import clip_to_disk, places_of, units_of
from multi_robot_mapper.core.worlds import office_world


def test_no_shape_hypotheses_unless_asked_and_then_verified_with_the_correlations() -> None:
    # Through the merger's own place search: a robot's map searched for its own place gives
    # the correlation's placements only by default, and the shape's too when asked.
    world = office_world()
    poses = np.array([(3.0, 2.5, 0.0), (6.5, 2.5, 0.0), (10.0, 2.5, 0.0), (14.0, 2.5, 0.0)])
    keyframes = []
    for index, pose in enumerate(poses):
        T = se2.matrix_from_pose(*pose)
        own = se2.transform_segments(se2.invert(T), clip_to_disk(world, pose[:2], RANGE))
        keyframes.append(Keyframe(index, float(index), pose, own))
    unit = next(iter(units_of({"robot1": keyframes}).values()))
    config = MergeConfig()
    place = places_of(unit, config)[1]
    _, none = placement_hypotheses(place, Target.of(unit, config), config)
    assert len(none) == 0
    asked = dataclasses.replace(config, shape_hypotheses=2)
    _, shaped = placement_hypotheses(place, Target.of(unit, asked), asked)
    assert 1 <= len(shaped) <= 2
    assert _placed_right(shaped, place.T_unit_centre)
