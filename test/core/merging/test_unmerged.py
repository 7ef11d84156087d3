"""Why a robot is not placed (core/merging/unmerged.py), on hand-made verdicts: each reason in
the order the merger says it, with the numbers and names it gives."""

from __future__ import annotations

import dataclasses

import numpy as np

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging.consistency import Accepted, PairVerdict
from multi_robot_mapper.core.merging.places import UnitKey, units_of
from multi_robot_mapper.core.merging.unmerged import unmerged_reason

WALL = np.array([[0.0, 1.0, 1.0, 1.0]])


def keyframes(*pieces: int) -> list[Keyframe]:
    """One keyframe per piece (0: the robot's main map frame)."""
    return [Keyframe(p, float(p), np.zeros(3), WALL, piece=p) for p in pieces]


UNITS = units_of({"a": keyframes(0), "b": keyframes(0), "c": keyframes(0), "d": keyframes(5)})
NOTHING = Accepted(pairs=[], refused=[], groups=[], tree={})


def verdict(first: UnitKey, second: UnitKey, probability: float, reason: str) -> PairVerdict:
    return PairVerdict((first, second), [], 1.0, 0.0, 1, False, reason, probability=probability)


def reason(robot: str, **given: object) -> str:
    arguments: dict[str, object] = {
        "units": UNITS,
        "verdicts": {},
        "accepted": NOTHING,
        "chains": {},
        "ref_unit": ("a", 0),
        "join_probability": 0.99,
    }
    arguments.update(given)
    return unmerged_reason(robot, **arguments)  # type: ignore[arg-type]


def test_no_map_an_empty_main_frame_or_no_reference_are_said_first() -> None:
    assert reason("e") == "no map yet"
    assert reason("d") == "its map frame is empty"  # only a piece, nothing in its own frame
    assert reason("b", ref_unit=None) == "no robot is placed yet"


def test_a_placement_below_the_threshold_gives_its_probability_and_the_reference() -> None:
    assert reason("b", chains={("b", 0): 0.9512}) == (
        "placement probability 0.951 below join_probability 0.99 (its paths of joins to a)"
    )


def test_a_group_of_its_own_names_the_robots_it_joined() -> None:
    grouped = dataclasses.replace(NOTHING, groups=[[("a", 0)], [("c", 0), ("b", 0), ("d", 5)]])
    assert (
        reason("b", accepted=grouped) == "joined to c, d, a group with no join to the reference a's"
    )


def test_the_likeliest_refused_or_weighed_pair_with_another_robot_says_why() -> None:
    refused = [
        verdict(("b", 0), ("a", 0), 0.4, "breaks a cycle"),
        verdict(("c", 0), ("b", 0), 0.7, "a robot would drive 9 m in 1 s"),
        verdict(("b", 0), ("b", 5), 0.99, "its own piece"),  # not across robots: never the reason
    ]
    accepted = dataclasses.replace(NOTHING, refused=refused)
    assert reason("b", accepted=accepted) == "with c: a robot would drive 9 m in 1 s"
    # Nothing refused over the groups: the likeliest weighed pair that has links.
    linked = dataclasses.replace(verdict(("b", 0), ("d", 5), 0.3, "ambiguous"), links=[None])
    unlinked = verdict(("b", 0), ("c", 0), 0.8, "no links")
    verdicts = {linked.pair: linked, unlinked.pair: unlinked}
    assert reason("b", verdicts=verdicts) == "with d/map_5: ambiguous"
    assert reason("c", verdicts={unlinked.pair: unlinked}) == (
        "no place of its map matches another robot's map"
    )
