"""The verdicts of a merge update within its time (core/merging/verdicts.py, issue 50) with
known answers: three robots along the corridors world, each in a map frame anywhere; their
place matches made once by a whole merge. Without a deadline every pair is judged as the whole
merge judged it; with a deadline already passed one pair is judged per update, pairs never
judged first, the others keeping their last verdict, until none waits; a kept verdict never
links a keyframe a map dropped; a set judged before on the same maps keeps its evidence."""

from __future__ import annotations

import dataclasses
import functools

from test_joint import CONFIG, drives, moved
from test_link_graph import random_frames

from multi_robot_mapper.core.evidence.model import installed_model
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.core.merging.consistency import PairVerdict
from multi_robot_mapper.core.merging.joint import JointState, merge_joint
from multi_robot_mapper.core.merging.places import units_of
from multi_robot_mapper.core.merging.verdicts import Judged, judge_pairs, still_linked

MODEL = installed_model()


@functools.cache
def three_robots() -> tuple[dict[str, list[Keyframe]], MergeResult]:
    """The robots' keyframes and their whole merge (every place matched, every pair judged)."""
    _, runs = drives("corridors", 3)
    world = dict(zip("abc", runs, strict=True))
    frames = dict(zip(world, random_frames(3, seed=6), strict=True))
    keyframes = {name: moved(world[name], frames[name]) for name in world}
    return keyframes, merge_joint(keyframes, CONFIG, budget=0.0)


def state_of(result: MergeResult) -> JointState:
    assert isinstance(result.state, JointState)
    return result.state


def same_verdict(got: PairVerdict, want: PairVerdict) -> bool:
    return (
        [c.identity() for c in got.links] == [c.identity() for c in want.links]
        and got.accepted == want.accepted
        and got.probability == want.probability
    )


def judge(keyframes: dict[str, list[Keyframe]], last: Judged | None, deadline: float | None):
    state = state_of(three_robots()[1])
    return judge_pairs(
        units_of(keyframes), state.matches, CONFIG, MODEL, state.targets, last, deadline
    )


def test_without_a_deadline_every_pair_is_judged_as_the_whole_merge_judged_it() -> None:
    keyframes, whole = three_robots()
    verdicts, judged = judge(keyframes, None, None)
    assert judged.pending == 0
    assert list(verdicts) == list(whole.verdicts) and len(verdicts) == 3  # type: ignore[attr-defined]
    for pair, verdict in verdicts.items():
        assert same_verdict(verdict, whole.verdicts[pair])  # type: ignore[attr-defined]
    assert any(v.accepted for v in verdicts.values())


def test_past_its_deadline_an_update_judges_one_pair_and_the_rest_wait_their_turn() -> None:
    keyframes, whole = three_robots()
    last = None
    for update in range(3):
        verdicts, last = judge(keyframes, last, 0.0)  # the deadline long gone
        assert last.pending == 2 - update
        # Never judged pairs have no verdict yet: the pairs judged so far, in pair order.
        assert len(verdicts) == update + 1
    assert last is not None and last.pending == 0
    for pair, verdict in verdicts.items():
        assert same_verdict(verdict, whole.verdicts[pair])  # type: ignore[attr-defined]
    # Nothing changed since: every verdict kept, none waits.
    again, after = judge(keyframes, last, 0.0)
    assert after.pending == 0 and all(again[p] is verdicts[p] for p in verdicts)


def test_a_grown_map_keeps_its_pairs_last_verdicts_until_each_is_judged_again() -> None:
    keyframes, _ = three_robots()
    shorter = {**keyframes, "b": keyframes["b"][:-4]}
    before, last = judge(shorter, None, None)
    # b's map grew: its two pairs wait (one judged now), a-c keeps its verdict by its key.
    after, judged = judge(keyframes, last, 0.0)
    assert judged.pending == 1
    a_c = (("a", 0), ("c", 0))  # pairs of map pieces: (robot, piece)
    assert after[a_c] is before[a_c]
    waiting = [p for p in after if p != a_c and after[p] is before[p]]
    assert len(waiting) == 1 and judged.latest[waiting[0]][0] == last.update
    # The next update judges the pair that waited, on the grown map.
    _, next_judged = judge(keyframes, judged, 0.0)
    assert next_judged.pending == 0 and next_judged.latest[waiting[0]][0] == next_judged.update


def test_a_kept_verdict_never_links_a_keyframe_a_map_dropped() -> None:
    keyframes, whole = three_robots()
    verdict = next(v for v in whole.verdicts.values() if v.links)  # type: ignore[attr-defined]
    units = units_of(keyframes)
    assert still_linked(verdict, units)
    link = verdict.links[0]
    dropped = {
        **keyframes,
        link.target[0]: [k for k in keyframes[link.target[0]] if k.index != link.keyframe],
    }
    assert not still_linked(verdict, units_of(dropped))


def test_a_set_judged_before_on_the_same_maps_keeps_its_evidence() -> None:
    keyframes, _ = three_robots()
    first, judged = judge(keyframes, None, None)
    # New candidates that leave each pair's set as it was: the verdicts are made again, the
    # sets' evidence and walls in free space are those measured before.
    forgotten = dataclasses.replace(judged, by_key={}, latest={})
    again, _ = judge(keyframes, forgotten, None)
    for pair, verdict in again.items():
        assert verdict is not first[pair]
        assert verdict.evidence is first[pair].evidence
        assert same_verdict(verdict, first[pair])
