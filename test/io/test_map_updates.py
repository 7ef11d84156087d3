"""partial_map in small messages (io/map_updates.py): what the robot sends (snapshots, updates of
what changed) and how a receiver applies them (in sequence only; gaps, duplicates and updates out
of order refused with the map held kept)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.io.inputs import InputError
from multi_robot_mapper.io.map_updates import (
    POSE_TOLERANCE_M,
    POSE_TOLERANCE_RAD,
    SEGMENT_TOLERANCE_M,
    SEQUENCE_NAMESPACE,
    SNAPSHOT,
    UPDATE,
    MapStream,
    Publication,
    SequenceTag,
    UpdatePlanner,
    changed_keyframes,
    sequence_marker,
    sequence_of,
)
from multi_robot_mapper.io.messages import (
    keyframe_marker,
    keyframes_from_markers,
    partial_map_contents,
    partial_map_markers,
    stamp_from_seconds,
)

FRAME = "robot1/map"


def keyframes(count: int = 4) -> list[Keyframe]:
    rng = np.random.default_rng(5)
    return [
        Keyframe(
            k,
            1_000_000_000.0 + 0.5 * k,
            np.array([0.7 * k, 0.1 * k, 0.2 * k]),
            rng.uniform(-5, 5, (k + 1, 4)),
        )
        for k in range(count)
    ]


def moved(kf: Keyframe, dx: float = 0.0, dtheta: float = 0.0) -> Keyframe:
    pose = kf.T_robotmap_keyframe + np.array([dx, 0.0, dtheta])
    return dataclasses.replace(kf, T_robotmap_keyframe=pose)


def message(publication: Publication) -> MarkerArray:
    """The robot node's message of a publication."""
    header = Header(frame_id=FRAME, stamp=stamp_from_seconds(1_000_000_010.0))
    array = MarkerArray()
    array.markers = [keyframe_marker(kf, header, 0.03) for kf in publication.keyframes]
    array.markers.append(sequence_marker(publication.tag, header))
    return array


def sent(planner: UpdatePlanner, frames: list[Keyframe], snapshot: bool = False) -> MarkerArray:
    publication = planner.plan(frames, snapshot)
    assert publication is not None
    planner.commit(publication)
    return message(publication)


# --- what the robot sends ---------------------------------------------------------------------


def test_the_first_message_is_a_snapshot_of_every_keyframe() -> None:
    planner = UpdatePlanner("e1")
    publication = planner.plan(keyframes(), snapshot=False)
    assert publication is not None
    assert publication.tag == SequenceTag(SNAPSHOT, "e1", 1, 4)
    assert [kf.index for kf in publication.keyframes] == [0, 1, 2, 3]


def test_nothing_changed_sends_nothing() -> None:
    planner = UpdatePlanner("e1")
    sent(planner, keyframes())
    assert planner.plan(keyframes(), snapshot=False) is None
    assert changed_keyframes(planner.sent, keyframes()) == []


def test_a_new_keyframe_alone_is_sent() -> None:
    planner = UpdatePlanner("e1")
    sent(planner, keyframes(3))
    publication = planner.plan(keyframes(4), snapshot=False)
    assert publication is not None
    assert publication.tag == SequenceTag(UPDATE, "e1", 2, 4)
    assert [kf.index for kf in publication.keyframes] == [3]


def test_a_pose_moved_beyond_the_tolerance_is_sent_within_it_is_not() -> None:
    frames = keyframes()
    planner = UpdatePlanner("e1")
    sent(planner, frames)
    within = [
        moved(frames[0], dx=0.5 * POSE_TOLERANCE_M),
        moved(frames[1], dtheta=0.5 * POSE_TOLERANCE_RAD),
    ]
    assert planner.plan(within + frames[2:], snapshot=False) is None
    beyond = [
        moved(frames[0], dx=2 * POSE_TOLERANCE_M),
        moved(frames[1], dtheta=2 * POSE_TOLERANCE_RAD),
    ]
    publication = planner.plan(beyond + frames[2:], snapshot=False)
    assert publication is not None
    assert [kf.index for kf in publication.keyframes] == [0, 1]


def test_small_moves_do_not_add_up_unsent() -> None:
    """The tolerance is from the pose last sent: three moves of 0.4 of it go out at the third."""
    frames = keyframes()
    planner = UpdatePlanner("e1")
    sent(planner, frames)
    for step in (1, 2):
        now = [moved(frames[0], dx=0.4 * step * POSE_TOLERANCE_M), *frames[1:]]
        assert planner.plan(now, snapshot=False) is None
    now = [moved(frames[0], dx=1.2 * POSE_TOLERANCE_M), *frames[1:]]
    publication = planner.plan(now, snapshot=False)
    assert publication is not None and [kf.index for kf in publication.keyframes] == [0]


def test_fused_segments_are_sent_reordered_or_rounded_copies_are_not() -> None:
    frames = keyframes()
    planner = UpdatePlanner("e1")
    sent(planner, frames)
    same = frames[3].segments[::-1] + 1e-12  # another order, rounding
    fused = np.vstack([frames[2].segments, [[0.0, 0.0, 1.0, 0.0]]])  # a segment more
    shifted = frames[1].segments + np.array([3 * SEGMENT_TOLERANCE_M, 0.0, 0.0, 0.0])
    now = [
        frames[0],
        dataclasses.replace(frames[1], segments=shifted),
        dataclasses.replace(frames[2], segments=fused),
        dataclasses.replace(frames[3], segments=same),
    ]
    publication = planner.plan(now, snapshot=False)
    assert publication is not None
    assert [kf.index for kf in publication.keyframes] == [1, 2]


def test_a_new_piece_is_sent() -> None:
    frames = keyframes()
    planner = UpdatePlanner("e1")
    sent(planner, frames)
    publication = planner.plan([*frames[:3], dataclasses.replace(frames[3], piece=3)], False)
    assert publication is not None and [kf.index for kf in publication.keyframes] == [3]


def test_a_snapshot_asked_for_sends_everything_even_unchanged() -> None:
    planner = UpdatePlanner("e1")
    sent(planner, keyframes())
    publication = planner.plan(keyframes(), snapshot=True)
    assert publication is not None
    assert publication.tag == SequenceTag(SNAPSHOT, "e1", 2, 4)
    assert len(publication.keyframes) == 4


def test_the_sequence_tag_round_trips_and_viewers_draw_nothing_for_it() -> None:
    tag = SequenceTag(UPDATE, "abc123", 17, 250)
    marker = sequence_marker(tag, Header(frame_id=FRAME))
    assert marker.action == Marker.DELETE and marker.ns == SEQUENCE_NAMESPACE
    array = MarkerArray(markers=[marker])
    assert sequence_of(array) == tag
    assert sequence_of(MarkerArray()) is None
    # The readers of a whole map skip it.
    whole = partial_map_markers(keyframes(), stamp_from_seconds(1e9), FRAME, 0.03)
    whole.markers.append(marker)
    assert len(keyframes_from_markers(whole)) == 4


@pytest.mark.parametrize("text", ["update e1 x 3", "update e1 3", "later e1 3 3", ""])
def test_a_malformed_tag_is_refused_by_name(text: str) -> None:
    marker = sequence_marker(SequenceTag(UPDATE, "e1", 1, 1), Header())
    marker.text = text
    with pytest.raises(InputError) as error:
        sequence_of(MarkerArray(markers=[marker]))
    assert error.value.kind == "bad_sequence"


def test_an_epoch_is_one_word() -> None:
    with pytest.raises(ValueError, match="one word"):
        UpdatePlanner("two words")


# --- how a receiver applies them -------------------------------------------------------------


def receive(stream: MapStream, array: MarkerArray, kind: str) -> None:
    stream.commit(stream.apply(array, kind))


def whole(stream: MapStream) -> list[Keyframe]:
    return keyframes_from_markers(MarkerArray(markers=list(stream.markers.values())))


def assert_same_map(got: list[Keyframe], want: list[Keyframe]) -> None:
    assert [kf.index for kf in got] == [kf.index for kf in want]
    for a, b in zip(got, want, strict=True):
        np.testing.assert_allclose(a.T_robotmap_keyframe, b.T_robotmap_keyframe, atol=1e-12)
        np.testing.assert_allclose(a.segments, b.segments, atol=1e-12)
        assert (a.stamp, a.piece) == (b.stamp, b.piece)


def test_updates_applied_give_the_whole_map() -> None:
    frames = keyframes(6)
    planner, stream = UpdatePlanner("e1"), MapStream()
    receive(stream, sent(planner, frames[:3]), SNAPSHOT)
    now = [moved(frames[0], dx=0.3), frames[1], frames[2], frames[3]]
    receive(stream, sent(planner, now), UPDATE)
    now = [*now[:2], dataclasses.replace(frames[2], segments=np.zeros((0, 4))), *frames[3:]]
    receive(stream, sent(planner, now), UPDATE)
    assert (stream.seq, stream.snapshots, stream.updates) == (3, 1, 2)
    assert_same_map(whole(stream), now)
    # The merger's reading of it equals that of one whole map.
    applied = partial_map_contents(
        stream.apply(sent(planner, now, snapshot=True), SNAPSHOT).whole_map()
    )
    mine = partial_map_contents(
        MarkerArray(markers=[stream.markers[k] for k in sorted(stream.markers)])
    )
    np.testing.assert_allclose(mine.segments, applied.segments, atol=1e-12)
    np.testing.assert_allclose(mine.keyframe_poses, applied.keyframe_poses, atol=1e-12)
    assert mine.session == applied.session


def test_a_gap_is_refused_and_the_map_kept_until_the_next_snapshot() -> None:
    frames = keyframes(6)
    planner, stream = UpdatePlanner("e1"), MapStream()
    receive(stream, sent(planner, frames[:3]), SNAPSHOT)
    sent(planner, frames[:4])  # update 2: lost on the way
    third = sent(planner, frames[:5])  # update 3
    with pytest.raises(InputError, match="1 missed") as error:
        stream.apply(third, UPDATE)
    assert error.value.kind == "update_gap"
    assert_same_map(whole(stream), frames[:3])  # kept
    fourth = sent(planner, frames[:6])
    with pytest.raises(InputError, match="2 missed"):
        stream.apply(fourth, UPDATE)  # still waiting
    receive(stream, sent(planner, frames, snapshot=True), SNAPSHOT)
    assert_same_map(whole(stream), frames)
    receive(stream, sent(planner, [moved(frames[0], dx=1.0), *frames[1:]]), UPDATE)
    assert stream.seq == 6


def test_duplicates_and_updates_out_of_order_are_refused() -> None:
    frames = keyframes(5)
    planner, stream = UpdatePlanner("e1"), MapStream()
    receive(stream, sent(planner, frames[:3]), SNAPSHOT)
    second = sent(planner, frames[:4])
    third = sent(planner, frames[:5])
    receive(stream, second, UPDATE)
    with pytest.raises(InputError) as error:
        stream.apply(second, UPDATE)  # a duplicate
    assert error.value.kind == "old_update"
    receive(stream, third, UPDATE)
    with pytest.raises(InputError) as error:
        stream.apply(second, UPDATE)  # out of order
    assert error.value.kind == "old_update"
    assert_same_map(whole(stream), frames)
    # An old snapshot after newer updates is refused too.
    old = UpdatePlanner("e1")
    with pytest.raises(InputError) as error:
        stream.apply(sent(old, frames[:2]), SNAPSHOT)
    assert error.value.kind == "old_snapshot"


def test_an_update_before_any_snapshot_or_of_another_stream_waits() -> None:
    frames = keyframes(4)
    stream = MapStream()
    planner = UpdatePlanner("e1")
    sent(planner, frames[:2])
    with pytest.raises(InputError, match="no map of a stream") as error:
        stream.apply(sent(planner, frames[:3]), UPDATE)
    assert error.value.kind == "update_gap"
    receive(stream, sent(planner, frames, snapshot=True), SNAPSHOT)
    restarted = UpdatePlanner("e2")  # the robot's mapper started a new map
    sent(restarted, frames[:1])
    with pytest.raises(InputError, match="stream e1"):
        stream.apply(sent(restarted, frames[:2]), UPDATE)
    # Its snapshot is taken whatever its number: another stream.
    receive(stream, sent(restarted, frames[:2], snapshot=True), SNAPSHOT)
    assert (stream.epoch, stream.seq) == ("e2", 3)


def test_an_update_whose_count_disagrees_is_refused() -> None:
    frames = keyframes(4)
    planner, stream = UpdatePlanner("e1"), MapStream()
    receive(stream, sent(planner, frames[:2]), SNAPSHOT)
    publication = planner.plan(frames[:3], snapshot=False)
    assert publication is not None
    bad = dataclasses.replace(publication, tag=dataclasses.replace(publication.tag, keyframes=7))
    with pytest.raises(InputError) as error:
        stream.apply(message(bad), UPDATE)
    assert error.value.kind == "update_mismatch"
    assert stream.seq == 1


def test_a_whole_map_without_a_tag_is_taken_as_it_is() -> None:
    stream = MapStream()
    array = partial_map_markers(keyframes(3), stamp_from_seconds(1e9), FRAME, 0.03)
    receive(stream, array, SNAPSHOT)
    assert (stream.epoch, len(stream.markers)) == (None, 3)
    with pytest.raises(InputError) as error:
        stream.apply(array, UPDATE)
    assert error.value.kind == "unsequenced_update"


def test_a_message_on_the_wrong_topic_is_refused() -> None:
    planner, stream = UpdatePlanner("e1"), MapStream()
    with pytest.raises(InputError) as error:
        stream.apply(sent(planner, keyframes()), UPDATE)
    assert error.value.kind == "wrong_kind"
    assert math.isclose(stream.seq, 0)
