"""``partial_map`` in small messages: full snapshots now and then, what changed in between.

A robot's partial map goes out in two kinds of ``visualization_msgs/MarkerArray``, both of
keyframe markers exactly as :func:`multi_robot_mapper.io.messages.keyframe_marker` builds them:

- a **snapshot** (topic ``partial_map``, transient local): every keyframe;
- an **update** (topic ``partial_map_updates``, volatile): only the keyframes that are new,
  whose segments changed (fusion; beyond :data:`SEGMENT_TOLERANCE_M`), whose piece or stamp
  changed, or whose pose moved beyond :data:`POSE_TOLERANCE_M` / :data:`POSE_TOLERANCE_RAD` from
  the pose last sent.

A marker is keyed by ``(ns, id)`` and an ``ADD`` replaces the marker of that key, so an update
is already a correct incremental change for RViz and Foxglove. Each message also carries one
``DELETE`` marker of namespace :data:`SEQUENCE_NAMESPACE` (viewers draw nothing for it) whose
``text`` is its :class:`SequenceTag`: the kind, the robot's stream (``epoch``: new whenever its
mapper starts a map), the message's number in that stream and the number of keyframes the map
holds once it is applied. Snapshots and updates share one numbering: update ``n`` builds on
the map of message ``n - 1``. A receiver (:class:`MapStream`) applies an update only on top of
exactly that map: a gap, a duplicate, an update out of order or of another stream is refused
and the map held is kept until the next snapshot.

Pure: no node; the robot side is :class:`UpdatePlanner`, the merger side :class:`MapStream`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.io.inputs import InputError
from multi_robot_mapper.io.messages import PARTIAL_MAP_NAMESPACE

SEQUENCE_NAMESPACE = "partial_map_sequence"
SNAPSHOT = "snapshot"
UPDATE = "update"
# A keyframe whose pose moved less than this from the pose last sent is not sent again. The
# merger judges links and builds its grid at centimetres (grid.resolution 0.05 m); 2 cm and
# 0.002 rad (2 cm at 10 m) are below what it can see, and the error is bounded: it is always
# measured against the pose last sent, never the previous one, so small moves never add up.
# A loop closure moves most poses by more, and they all go out.
POSE_TOLERANCE_M = 0.02
POSE_TOLERANCE_RAD = 0.002
# Fusion rewrites the segments a keyframe owns whenever a neighbour is fused, most often to the
# same values up to rounding (1e-15 m) or in another order: segments that are the same set to
# within this are not sent again (measured on freiburg-079, first 600 scans: 9 in 10 of the
# keyframes whose segments "changed" were such copies).
SEGMENT_TOLERANCE_M = 0.005


@dataclasses.dataclass(frozen=True)
class SequenceTag:
    """Where a message stands in its robot's stream."""

    kind: str  # SNAPSHOT or UPDATE
    epoch: str  # the stream: new whenever the robot's mapper starts a map (no spaces)
    seq: int  # this message's number in the stream (snapshots and updates alike), from 1
    keyframes: int  # keyframes of the map once this message is applied

    def text(self) -> str:
        return f"{self.kind} {self.epoch} {self.seq} {self.keyframes}"


def sequence_marker(tag: SequenceTag, header: Header) -> Marker:
    """The marker that carries ``tag``: a ``DELETE`` (viewers draw nothing) of
    :data:`SEQUENCE_NAMESPACE`, id 0, the tag in ``text``."""
    marker = Marker()
    marker.header = header
    marker.ns = SEQUENCE_NAMESPACE
    marker.id = 0
    marker.action = Marker.DELETE
    marker.text = tag.text()
    return marker


def sequence_of(array: MarkerArray) -> SequenceTag | None:
    """The tag a message carries (None for a message without one: a whole map from an older
    or another mapper); raises :class:`InputError` for a malformed tag."""
    tags = [m for m in array.markers if m.ns == SEQUENCE_NAMESPACE]
    if not tags:
        return None
    parts = tags[0].text.split()
    try:
        if len(tags) != 1 or len(parts) != 4 or parts[0] not in (SNAPSHOT, UPDATE):
            raise ValueError
        tag = SequenceTag(parts[0], parts[1], int(parts[2]), int(parts[3]))
    except ValueError:
        raise InputError(
            "bad_sequence",
            f"markers[ns={SEQUENCE_NAMESPACE}].text",
            f"{len(tags)} sequence markers, text {tags[0].text[:80]!r}: want one, "
            "'<snapshot|update> <epoch> <seq> <keyframes>'",
        ) from None
    return tag


def keyframe_markers(array: MarkerArray) -> list[Marker]:
    """The keyframe markers of a message (``partial_map`` namespace, ``ADD`` line lists)."""
    return [
        m
        for m in array.markers
        if m.ns == PARTIAL_MAP_NAMESPACE and m.type == Marker.LINE_LIST and m.action == Marker.ADD
    ]


# --- robot side --------------------------------------------------------------------------------


def pose_moved(
    sent: Sequence[float],
    now: Sequence[float],
    metres: float = POSE_TOLERANCE_M,
    radians: float = POSE_TOLERANCE_RAD,
) -> bool:
    """Whether pose ``now`` is farther than the tolerance from pose ``sent``."""
    turn = abs(math.remainder(float(now[2]) - float(sent[2]), math.tau))
    return math.hypot(now[0] - sent[0], now[1] - sent[1]) > metres or turn > radians


def _rows_sorted(segments: np.typing.NDArray[np.float64]) -> np.typing.NDArray[np.float64]:
    rounded = np.round(segments / SEGMENT_TOLERANCE_M)
    return segments[np.lexsort(rounded.T[::-1])]


def segments_changed(
    sent: np.typing.NDArray[np.float64], now: np.typing.NDArray[np.float64]
) -> bool:
    """Whether two keyframes' segments differ by more than :data:`SEGMENT_TOLERANCE_M` in any
    end, in whatever order each lists them."""
    if sent.shape != now.shape:
        return True
    if np.array_equal(sent, now):
        return False
    gap = np.abs(_rows_sorted(sent) - _rows_sorted(now))
    return bool(gap.max(initial=0.0) > SEGMENT_TOLERANCE_M)


def keyframe_changed(sent: Keyframe | None, now: Keyframe) -> bool:
    """Whether ``now`` must go out again: new, its segments, piece or stamp changed, or its
    pose moved beyond the tolerance from the pose ``sent``."""
    if sent is None:
        return True
    return (
        sent.piece != now.piece
        or sent.stamp != now.stamp
        or segments_changed(sent.segments, now.segments)
        or pose_moved(sent.T_robotmap_keyframe, now.T_robotmap_keyframe)
    )


def changed_keyframes(
    sent: Mapping[int, Keyframe], keyframes: Sequence[Keyframe]
) -> list[Keyframe]:
    """The keyframes of the map as it is (``keyframes``) that differ from what was sent
    (``sent``, by index): what an update carries."""
    return [kf for kf in keyframes if keyframe_changed(sent.get(kf.index), kf)]


@dataclasses.dataclass(frozen=True)
class Publication:
    """What to publish next: the keyframes to send and the tag to send them with."""

    tag: SequenceTag
    keyframes: list[Keyframe]


class UpdatePlanner:
    """The robot's side of one stream: what was sent, what to send next.

    :meth:`plan` says what to publish (a snapshot when asked, else an update of what changed,
    else nothing); :meth:`commit` records it once it went out."""

    def __init__(self, epoch: str) -> None:
        if not epoch or any(c.isspace() for c in epoch):
            raise ValueError(f"an epoch is one word, not {epoch!r}")
        self.epoch = epoch
        self.seq = 0  # the last message committed
        self.sent: dict[int, Keyframe] = {}  # each keyframe as the receivers hold it

    def plan(self, keyframes: Sequence[Keyframe], snapshot: bool) -> Publication | None:
        """The next message for the map ``keyframes``: every keyframe when ``snapshot`` (or
        nothing was ever sent), else the changed ones; None when nothing changed."""
        if snapshot or not self.sent:
            kind, chosen = SNAPSHOT, list(keyframes)
        else:
            kind, chosen = UPDATE, changed_keyframes(self.sent, keyframes)
        if not chosen:
            return None
        known = set(self.sent) if kind == UPDATE else set()
        count = len(known | {kf.index for kf in chosen})
        return Publication(SequenceTag(kind, self.epoch, self.seq + 1, count), chosen)

    def commit(self, publication: Publication) -> None:
        """``publication`` went out: the receivers now hold its keyframes."""
        if publication.tag.kind == SNAPSHOT:
            self.sent = {}
        self.sent.update({kf.index: kf for kf in publication.keyframes})
        self.seq = publication.tag.seq


# --- receiver side -----------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Applied:
    """A message applied to the map held, not yet committed: the whole map it gives."""

    epoch: str | None
    seq: int
    markers: dict[int, Marker]  # keyframe markers by id
    kind: str

    def whole_map(self) -> MarkerArray:
        """The whole map as one ``partial_map`` MarkerArray (keyframe order, no tag)."""
        array = MarkerArray()
        array.markers = [self.markers[k] for k in sorted(self.markers)]
        return array


class MapStream:
    """The receiver's side of one robot's stream: the whole map as the last applied message
    left it. :meth:`apply` checks a message against it (raising :class:`InputError` for a gap,
    a duplicate, an update out of order or of another stream: the map held stays);
    :meth:`commit` keeps the result once the caller has checked the whole map."""

    def __init__(self) -> None:
        self.epoch: str | None = None  # None: no map, or one without a tag
        self.seq = 0
        self.markers: dict[int, Marker] = {}
        self.snapshots = 0  # committed, by kind
        self.updates = 0

    def apply(self, array: MarkerArray, kind: str) -> Applied:
        """``array`` received as a ``kind`` (SNAPSHOT on ``partial_map``, UPDATE on
        ``partial_map_updates``) applied to the map held."""
        tag = sequence_of(array)
        markers = {int(m.id): m for m in keyframe_markers(array)}
        if tag is not None and tag.kind != kind:
            raise InputError("wrong_kind", "sequence", f"a {tag.kind} came where a {kind} belongs")
        if kind == SNAPSHOT:
            if tag is None:  # a whole map without a stream: taken as it is
                return Applied(None, 0, markers, kind)
            if tag.epoch == self.epoch and tag.seq <= self.seq:
                raise InputError(
                    "old_snapshot",
                    "sequence",
                    f"snapshot {tag.seq} of stream {tag.epoch}, the map held is already at "
                    f"{self.seq}: ignored",
                )
            return self._counted(Applied(tag.epoch, tag.seq, markers, kind), tag)
        if tag is None:
            raise InputError("unsequenced_update", "sequence", "an update without a sequence tag")
        self._check_follows(tag)
        return self._counted(Applied(tag.epoch, tag.seq, {**self.markers, **markers}, kind), tag)

    def _check_follows(self, tag: SequenceTag) -> None:
        """An update applies only on top of the message just before it, in its stream."""
        if self.epoch is None or tag.epoch != self.epoch:
            held = "no map of a stream" if self.epoch is None else f"stream {self.epoch}"
            raise InputError(
                "update_gap",
                "sequence",
                f"update {tag.seq} of stream {tag.epoch}, but the map held is of {held}: "
                "waiting for the next snapshot",
            )
        if tag.seq <= self.seq:
            raise InputError(
                "old_update",
                "sequence",
                f"update {tag.seq} came after {self.seq} (a duplicate or out of order): ignored",
            )
        if tag.seq > self.seq + 1:
            raise InputError(
                "update_gap",
                "sequence",
                f"update {tag.seq} came after {self.seq}: {tag.seq - self.seq - 1} missed; "
                "the map held is kept until the next snapshot",
            )

    @staticmethod
    def _counted(applied: Applied, tag: SequenceTag) -> Applied:
        if len(applied.markers) != tag.keyframes:
            raise InputError(
                "update_mismatch",
                "sequence",
                f"{applied.kind} {tag.seq} gives {len(applied.markers)} keyframes where its "
                f"tag says {tag.keyframes}: ignored, waiting for the next snapshot",
            )
        return applied

    def commit(self, applied: Applied) -> None:
        self.epoch, self.seq, self.markers = applied.epoch, applied.seq, applied.markers
        if applied.kind == SNAPSHOT:
            self.snapshots += 1
        else:
            self.updates += 1
