"""Diagnostics built without a node: rates, levels, merge scores."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.core.merging.consistency import PairVerdict
from multi_robot_mapper.core.merging.pairwise import Link, MapSignature, PairRecord
from multi_robot_mapper.io.messages import stamp_from_seconds
from multi_robot_mapper.ros.diagnostics import (
    OK,
    STALE,
    WARN,
    MapperHealth,
    MergerRobotHealth,
    RateMeter,
    diagnostic_array,
    link_scores,
    mapper_status,
    merger_status,
    unmerged_reasons,
)


def test_the_rate_comes_from_the_stamps_of_the_last_messages() -> None:
    meter = RateMeter(window=10)
    assert meter.rate() is None
    for k in range(30):
        meter.add(100.0 + k / 40.0)  # 40 Hz
    assert meter.rate() == pytest.approx(40.0)
    meter.add(100.0 + 29 / 40.0)  # a repeated stamp does not divide by zero
    assert meter.rate() is not None


def mapper(**changes: object) -> MapperHealth:
    values: dict[str, object] = {
        "robot": "robot1",
        "scan_rate": 40.0,
        "silent_for": 0.02,
        "stale_timeout": 5.0,
        "scans_received": 400,
        "scans_accepted": 390,
        "rejected": {"nan_ranges": 4},
        "set_aside": {"no valid match": 6},
        "keyframes": 20,
        "map_segments": 80,
        "recent_received": 40,
        "recent_accepted": 40,
        "recent_rejected": 0,
    }
    values.update(changes)
    return MapperHealth(**values)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("changes", "level", "words"),
    [
        ({}, OK, "40.00 Hz"),
        ({"recent_rejected": 3}, WARN, "3 scans rejected"),
        ({"recent_accepted": 0}, WARN, "could be placed"),
        ({"silent_for": 6.0}, STALE, "no scan for 6.0 s"),
        ({"silent_for": None}, STALE, "no scan received yet"),
    ],
)
def test_mapper_levels(changes: dict[str, object], level: bytes, words: str) -> None:
    status = mapper_status(mapper(**changes))
    assert status.level == level and words in status.message
    assert status.name == "robot1/robot_mapper" and status.hardware_id == "robot1"
    values = {kv.key: kv.value for kv in status.values}
    assert values["rejected: nan_ranges"] == "4" and values["scans rejected"] == "4"
    assert values["set aside: no valid match"] == "6" and values["scan rate (Hz)"] == "40.00"


def merger(**changes: object) -> MergerRobotHealth:
    values: dict[str, object] = {
        "robot": "robot2",
        "placement": (1.0, 2.0, 0.5),
        "reference": False,
        "link_value": 42.0,
        "best_value": 42.0,
        "pose_rate": 39.5,
        "maps_received": 7,
        "keyframes": 12,
        "segments": 50,
        "silent_for": 0.5,
        "stale_timeout": 5.0,
    }
    values.update(changes)
    return MergerRobotHealth(**values)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("changes", "level", "words"),
    [
        ({}, OK, "link value 42.00 m"),
        ({"reference": True, "placement": (0.0, 0.0, 0.0)}, OK, "reference"),
        ({"placement": None, "link_value": None, "best_value": 9.0}, WARN, "best pair value 9.0"),
        ({"silent_for": 8.0}, STALE, "its map stays in the global map"),
        (
            {"silent_for": 8.0, "placement": None, "why_unmerged": "with robot1: P 0.97 < 0.99"},
            STALE,
            "silent for 8.0 s; unmerged: with robot1: P 0.97 < 0.99",
        ),
        ({"silent_for": None, "segments": 0}, STALE, "nothing received"),
        ({"session_of": "robot2", "silent_for": 99.0}, OK, "earlier session"),
    ],
)
def test_merger_levels(changes: dict[str, object], level: bytes, words: str) -> None:
    status = merger_status(merger(**changes))
    assert status.level == level and words in status.message, status.message
    assert status.name == "map_merger/robot2"


def test_an_array_is_stamped_as_given() -> None:
    stamp = stamp_from_seconds(1e9 + 1.5)
    array = diagnostic_array([merger_status(merger())], stamp)
    assert array.header.stamp == stamp and len(array.status) == 1


def link(a: str, b: str, value: float, valid: bool = True) -> Link:
    return Link(a, b, (0.0, 0.0, 0.0), value, 0.5, valid)


def test_each_robot_scores_the_tree_edge_it_was_reached_by() -> None:
    # A chain c - a - b with c the reference; d unmerged with a weak pair.
    signature = MapSignature(1, 1.0, "x")
    links = [link("a", "b", 30.0), link("a", "c", 50.0)]
    pairs = {
        ("a", "b"): PairRecord(links[0], signature, signature, False),
        ("a", "c"): PairRecord(links[1], signature, signature, False),
        ("b", "d"): PairRecord(link("b", "d", 7.0, valid=False), signature, signature, False),
    }
    result = MergeResult(
        robots=["a", "b", "c", "d"],
        placements={"a": (0, 0, 0), "b": (0, 0, 0), "c": (0, 0, 0), "d": None},
        reference="c",
        links=links,
        pairs=pairs,
        segments=np.zeros((0, 4)),
        segment_robot=np.zeros(0, dtype=np.int64),
        timings={},
        stats={},
    )
    scores = link_scores(result)
    assert scores == {"a": (50.0, 50.0), "b": (30.0, 30.0), "c": (None, 50.0), "d": (None, 7.0)}
    assert link_scores(None) == {}


def test_an_unmerged_robot_says_why_its_best_pair_placed_it_nowhere() -> None:
    # The joint merger's verdicts: d's best pair (with b, 40 m of matched wall) was refused as
    # ambiguous, its pair with a (10 m) for too few places; e's pair was accepted within
    # itself but did not join it to the reference's group; merged robots get no reason.
    def verdict(a: str, b: str, value: float, reason: str) -> PairVerdict:
        candidate = SimpleNamespace(value=value)
        links = [candidate] if value else []
        return PairVerdict(((a, 0), (b, 0)), links, 1.0, 0.0, 1, not reason, reason)  # type: ignore[arg-type]

    verdicts = [
        verdict("b", "d", 40.0, "ambiguous: a contradicting set of links weighs about as much"),
        verdict("a", "d", 10.0, "too few consistent places"),
        verdict("a", "b", 30.0, ""),
        verdict("c", "e", 20.0, ""),
    ]
    result = MergeResult(
        robots=["a", "b", "c", "d", "e"],
        placements={"a": (0, 0, 0), "b": (0, 0, 0), "c": None, "d": None, "e": None},
        reference="a",
        links=[],
        pairs={},
        segments=np.zeros((0, 4)),
        segment_robot=np.zeros(0, dtype=np.int64),
        timings={},
        stats={},
    )
    result.verdicts = {v.pair: v for v in verdicts}
    reasons = unmerged_reasons(result)
    assert reasons["d"].startswith("ambiguous")
    assert "not joined to the reference" in reasons["e"] and "c" in reasons
    assert "a" not in reasons and "b" not in reasons
    assert unmerged_reasons(None) == {}
    status = merger_status(merger(placement=None, link_value=None, why_unmerged=reasons["d"]))
    assert status.message.endswith("weighs about as much"), status.message
