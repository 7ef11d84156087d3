"""A loop closure's edge (core/local_mapping/windows.py): the windows' placement kept, between the
members whose scans constrain it most, with the information of their walls."""

from __future__ import annotations

import numpy as np
from local_mapping_drives import (
    mapped,
)

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.integrate import hypotheses_of


def test_a_closure_edge_is_the_windows_placement_between_the_members_that_see_most(
    office_drive,  # type: ignore[no-untyped-def]
    monkeypatch,  # type: ignore[no-untyped-def]
) -> None:
    # Two keyframes' windows agree on a placement; the closure's edge keeps it as it is (the
    # two scans alone refined it to worse placements on the shared logs), expressed between
    # one member of each window through their poses in the windows: the pair whose own scans
    # constrain it most, with the information of their walls.
    stamps, scans, _ = office_drive
    local = mapped(stamps, scans)
    closer = local.backend.closer
    pose = closer.keyframes.pose
    last = len(closer.keyframes.scans) - 1
    first_window, last_window = closer._window_members(0), closer._window_members(last)
    assert not set(first_window.tolist()) & set(last_window.tolist())

    def no_match(*args: object, **kwargs: object) -> None:
        raise AssertionError("the closure edge must not match the scans again")

    monkeypatch.setattr(closer, "_match", no_match)
    # The windows' placement as the graph has it: every member pair's edge is then the graph's
    # own relative pose of the two members.
    placement = se2.between(pose(0), pose(last))
    edge = closer._scan_edge(0, last, placement)
    assert edge.first in first_window and edge.second in last_window
    np.testing.assert_allclose(
        edge.T_first_second, se2.between(pose(edge.first), pose(edge.second)), atol=1e-9
    )
    assert edge.robust
    volume = np.linalg.slogdet(edge.information)[1]
    for i in first_window.tolist():
        for j in last_window.tolist():
            T_i_j = hypotheses_of([se2.between(pose(i), pose(j))])[0]
            other = closer._edge(i, j, T_i_j, robust=True)
            assert np.linalg.slogdet(other.information)[1] <= volume + 1e-9
    # Walls of both scans overlap there: tighter than the ceiling of an unconstrained edge
    # (10 m, 1 rad), in every direction; 40 m away nothing overlaps.
    assert np.all(np.linalg.eigvalsh(edge.information) > 1.0)
    apart = closer._scan_edge(0, last, (placement[0] + 40.0, placement[1], placement[2]))
    assert np.linalg.eigvalsh(apart.information).min() < np.linalg.eigvalsh(edge.information).min()
