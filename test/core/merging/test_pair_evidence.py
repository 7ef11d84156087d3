"""The evidence for a pair's placement (core/merging/pair_evidence.py), measured both ways:
the weaker way decides; a bare corridor fits itself turned round as well as the right way; a
join of groups that crosses the other's corridor puts walls in its free space."""

from __future__ import annotations

import numpy as np
import pytest
from test_consistency import CONFIG, line_units, link

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.evidence.placement import PlacementEvidence
from multi_robot_mapper.core.merging.pair_evidence import (
    PairEvidence,
    group_conflict,
    pair_evidence,
)
from multi_robot_mapper.core.merging.place_matching import Targets, target_of
from multi_robot_mapper.core.merging.places import units_of

A, B = ("a", 0), ("b", 0)


def test_the_weaker_way_decides() -> None:
    one = PlacementEvidence(10.0, 2.0, 12.0, np.zeros(3), None, conflict=0.5)
    other = PlacementEvidence(8.0, 6.0, 9.0, np.zeros(3), None, conflict=1.5)
    for evidence in (PairEvidence(one, other), PairEvidence(other, one)):
        assert evidence.margin == 2.0  # min(10 - 2, 8 - 6)
        assert evidence.score == 8.0
        assert evidence.rival_ratio == 0.75  # max(0.2, 0.75)
        assert evidence.conflict == 1.5


def test_a_bare_corridor_fits_turned_round_and_only_a_crossing_join_conflicts() -> None:
    # Two robots along the same straight corridor, b's map 3 m along a's.
    frames = {"a": se2.matrix_from_pose(0.0, 0.0, 0.0), "b": se2.matrix_from_pose(3.0, 0.0, 0.0)}
    units = units_of(line_units(["a", "b"], [frames["a"], frames["b"]]))
    kept = Targets()
    targets = {key: target_of(unit, CONFIG, kept) for key, unit in units.items()}
    right = [link(units, frames, "b", k, "a", k + 3, 0.95) for k in (2, 7, 12)]
    T_a_b = se2.invert(frames["a"]) @ frames["b"]
    evidence = pair_evidence((A, B), right, T_a_b, units, targets, CONFIG)
    for way in (evidence.b_on_a, evidence.a_on_b):
        assert way.score > 30.0 and way.conflict == 0.0
        assert abs(way.placement[0]) < 1e-9  # refined at the right heading...
        assert abs(abs(way.rival_placement[0]) - np.pi) < 1e-9  # ... its rival turned round
    np.testing.assert_allclose(evidence.b_on_a.placement[1], 3.0, atol=1e-9)
    np.testing.assert_allclose(evidence.a_on_b.placement[1], -3.0, atol=1e-9)
    assert evidence.rival_ratio == pytest.approx(1.0) and evidence.margin == pytest.approx(0.0)
    # Joined as groups: the right placement puts no wall in free space, one across it does.
    group_a, group_b = {A: np.eye(3)}, {B: np.eye(3)}
    radius = CONFIG.place_radius
    assert group_conflict(group_a, group_b, T_a_b, units, targets, radius) == 0.0
    across = se2.matrix_from_pose(10.0, -10.0, np.pi / 2)
    assert group_conflict(group_a, group_b, across, units, targets, radius) > 1.0
