"""What ``map_merger`` knows of each robot, and how robots' sessions and saved maps change it.

Plain data and functions (no node): the node holds a ``dict[str, RobotState]`` under its lock
and calls these.

Sessions: ``robot_mapper`` numbers keyframes from 0 and keyframe 0 carries the stamp of the
scan the map began with. A partial map whose keyframe 0 has another stamp than the map the
merger holds is a new session of that robot (its node restarted, or its bag looped): the map
so far is kept as ``<robot>_session<k>`` (merged like any robot, never updated again, at most
``keep_sessions`` per robot) and the new map starts unmerged, to be merged again. A one-keyframe
map is not a session yet (the mapper restarts a start no second scan confirmed).
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription
from visualization_msgs.msg import MarkerArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping import Keyframe
from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.io.inputs import MapLimits, partial_map_from_msg
from multi_robot_mapper.io.map_updates import UPDATE, Applied, MapStream
from multi_robot_mapper.io.messages import PartialMapContents, partial_map_contents
from multi_robot_mapper.io.saved_map import SavedMap, SavedRobot
from multi_robot_mapper.ros import diagnostics
from multi_robot_mapper.ros.diagnostics import RateMeter
from multi_robot_mapper.ros.markers import stamp_key

FloatArray = np.typing.NDArray[np.float64]
_SESSION_NAME = re.compile(r"(.+)_session(\d+)")


@dataclasses.dataclass
class RobotState:
    """What the merger knows of one robot (or of an earlier session of one)."""

    name: str
    segments: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 4)))
    keyframe_poses: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    # every keyframe of every piece as received (empty for a map loaded from a file, which
    # keeps only the segments and keyframe poses of the main piece)
    all_keyframes: list[Keyframe] = dataclasses.field(default_factory=list)
    map_stamp: Time | None = None  # header stamp of the last partial map
    map_frame: str = ""  # the robot's own map frame (the partial map's frame_id)
    version: int = 0  # partial maps received (or loaded)
    session: float | None = None  # stamp of its keyframe 0
    pose: FloatArray | None = None  # T_robotmap_laser of the newest pose message
    pose_stamp: Time | None = None
    pose_piece: int = 0  # the piece of its map the newest pose is in (its frame's suffix)
    heard_ns: int | None = None  # node clock at its last partial map or pose
    pose_rate: RateMeter = dataclasses.field(default_factory=RateMeter)
    session_of: str | None = None  # set for an earlier session: the robot it belonged to
    subscriptions: list[Subscription] = dataclasses.field(default_factory=list)
    pose_publisher: Publisher | None = None
    # partial_map snapshots and partial_map_updates, applied in order (io/map_updates.py)
    stream: MapStream = dataclasses.field(default_factory=MapStream)
    request_publisher: Publisher | None = None  # asks the robot for a snapshot
    requested_ns: int | None = None  # node clock when a snapshot was last asked for
    loaded: bool = False  # the map held came from a saved file, no newer one since

    @property
    def keyframes(self) -> int:
        return len(self.keyframe_poses)


@dataclasses.dataclass(frozen=True)
class MergeInputs:
    """A consistent copy of what a merge and its publication need (taken under the lock)."""

    maps: dict[str, FloatArray]
    versions: dict[str, int]
    viewpoints: dict[str, FloatArray]
    keyframes: dict[str, list[Keyframe]]
    stamps: dict[str, Time]
    frames: dict[str, str]
    poses: dict[str, tuple[FloatArray, Time]]
    pose_pieces: dict[str, int] = dataclasses.field(default_factory=dict)


def merge_inputs(robots: dict[str, RobotState]) -> MergeInputs:
    """The robots with a map, their maps, viewpoints, stamps, frames and newest poses."""
    with_map = {n: s for n, s in robots.items() if len(s.segments)}
    return MergeInputs(
        maps={n: s.segments for n, s in with_map.items()},
        versions={n: s.version for n, s in with_map.items()},
        viewpoints={n: s.keyframe_poses for n, s in with_map.items()},
        keyframes={
            n: s.all_keyframes or keyframes_of(s.segments, s.keyframe_poses)
            for n, s in with_map.items()
        },
        stamps={n: s.map_stamp for n, s in robots.items() if s.map_stamp is not None},
        frames={n: s.map_frame for n, s in robots.items()},
        poses={
            n: (s.pose, s.pose_stamp)
            for n, s in robots.items()
            if s.pose is not None and s.pose_stamp is not None
        },
        pose_pieces={n: s.pose_piece for n, s in robots.items()},
    )


def keyframes_of(segments: FloatArray, keyframe_poses: FloatArray) -> list[Keyframe]:
    """A map known only by its segments and keyframe poses (a saved map) as keyframes: the
    first owns every segment, the others none (the merger then moves it as one rigid map,
    the keyframes still its viewpoints)."""
    poses = np.asarray(keyframe_poses, dtype=np.float64).reshape(-1, 3)
    if len(poses) == 0:
        poses = np.zeros((1, 3))
    T_first_map = se2.invert(se2.matrix_from_pose(*poses[0]))
    own = se2.transform_segments(T_first_map, np.asarray(segments, dtype=np.float64))
    empty = np.zeros((0, 4))
    return [Keyframe(k, 0.0, pose, own if k == 0 else empty) for k, pose in enumerate(poses)]


def received_map(
    state: RobotState, msg: MarkerArray, kind: str, limits: MapLimits
) -> tuple[Applied, PartialMapContents]:
    """A snapshot or an update (``kind``) checked (bounded, finite), applied to the robot's
    stream and the whole map it gives read; raises ``InputError`` (nothing changed). Commit
    ``state.stream`` with the result once it is stored."""
    partial_map_from_msg(msg, limits)  # checked first: bounded, finite
    applied = state.stream.apply(msg, kind)
    whole = applied.whole_map()
    if kind == UPDATE:  # the whole map it gives, within the limits too
        partial_map_from_msg(whole, limits)
    return applied, partial_map_contents(whole)


def store_partial_map(
    robots: dict[str, RobotState],
    name: str,
    contents: PartialMapContents,
    heard_ns: int,
    keep_sessions: int,
) -> str | None:
    """Put a robot's new partial map in place; returns the name its earlier session was kept
    under when this map starts a new session (None otherwise)."""
    state = robots[name]
    kept = None
    if (
        state.keyframes >= 2
        and contents.session is not None
        and state.session is not None
        and contents.session != state.session
    ):
        kept = keep_session(robots, state, keep_sessions)
        state.pose = None  # the old session's pose means nothing in the new map frame
        state.pose_stamp = None
        state.pose_piece = 0
    state.segments = contents.segments
    state.keyframe_poses = contents.keyframe_poses
    state.all_keyframes = list(contents.keyframes)
    state.session = contents.session
    state.map_stamp = contents.stamp
    state.map_frame = contents.frame_id or state.map_frame
    state.heard_ns = heard_ns
    state.version += 1
    state.loaded = False
    return kept


def older_than_loaded(state: RobotState, contents: PartialMapContents) -> bool:
    """Is ``contents`` a map of the session loaded from a file, but older than the loaded
    one? (A robot's latched snapshot, made before the file was saved: merged, its smaller map
    would withdraw placements the file's map holds.) The loaded map then stays until a newer
    one of the session comes."""
    return (
        state.loaded
        and contents.session is not None
        and contents.session == state.session
        and contents.stamp is not None
        and state.map_stamp is not None
        and stamp_key(contents.stamp) < stamp_key(state.map_stamp)
    )


def keep_session(
    robots: dict[str, RobotState], state: RobotState, keep_sessions: int
) -> str | None:
    """Keep ``state``'s map as ``<robot>_session<k>`` (dropping the oldest beyond
    ``keep_sessions``); returns the new name (None when nothing is kept)."""
    if keep_sessions <= 0 or not len(state.segments):
        return None
    earlier = sessions_of(robots, state.name)
    number = 1 + max((k for k, _ in earlier), default=0)
    kept = f"{state.name}_session{number}"
    robots[kept] = RobotState(
        name=kept,
        segments=state.segments,
        keyframe_poses=state.keyframe_poses,
        all_keyframes=state.all_keyframes,
        map_stamp=state.map_stamp,
        map_frame=f"{state.map_frame or state.name + '/map'}_session{number}",
        version=1,
        session=state.session,
        heard_ns=state.heard_ns,
        session_of=state.name,
    )
    for _, old in sessions_of(robots, state.name)[: max(0, len(earlier) + 1 - keep_sessions)]:
        del robots[old]
    return kept


def after_new_session(result: MergeResult | None, robot: str, kept: str) -> MergeResult | None:
    """The previous merge as the next one should see it once ``robot`` started a new session
    (its old map now ``kept``): no pair result or tree edge of ``robot`` is reused (its map
    frame changed, and a map's signature does not see frames), and when ``robot`` was the
    reference, ``kept`` is: the ``map`` frame stays where it was."""
    if result is None:
        return None
    return dataclasses.replace(
        result,
        reference=kept if result.reference == robot else result.reference,
        pairs={pair: record for pair, record in result.pairs.items() if robot not in pair},
        links=[lk for lk in result.links if robot not in (lk.robot_a, lk.robot_b)],
        refinement=None,  # its keyframes are a new session's: FFS starts afresh
    )


def sessions_of(robots: dict[str, RobotState], robot: str) -> list[tuple[int, str]]:
    """``(k, name)`` of every kept earlier session of ``robot``, oldest first."""
    found = []
    for name, state in robots.items():
        match = _SESSION_NAME.fullmatch(name)
        if state.session_of == robot and match is not None:
            found.append((int(match.group(2)), name))
    return sorted(found)


def saved_map_of(
    robots: dict[str, RobotState], result: MergeResult | None, map_frame: str
) -> SavedMap:
    """Every robot with a map, its placement in the last merge and the global map."""
    with_map = {n: s for n, s in robots.items() if len(s.segments)}
    names = sorted(with_map)
    placements = {} if result is None else result.placements
    saved = {
        name: SavedRobot(
            map_frame=state.map_frame,
            session=state.session,
            map_stamp=None if state.map_stamp is None else stamp_key(state.map_stamp),
            placement=placements.get(name),
            segments=state.segments,
            keyframe_poses=state.keyframe_poses,
            session_of=state.session_of,
            probability=None if result is None else result.probabilities.get(name),
        )
        for name, state in with_map.items()
    }
    segments, owners = np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
    if result is not None and len(result.segments):
        # Re-index the owners into the saved robots (sorted names); drop robots not saved.
        lookup = np.array([names.index(r) if r in with_map else -1 for r in result.robots])
        owners = lookup[result.segment_robot]
        keep = owners >= 0
        segments, owners = result.segments[keep], owners[keep].astype(np.int64)
    reference = None if result is None or result.reference not in with_map else result.reference
    return SavedMap(map_frame, reference, saved, segments, owners)


def restore_saved_map(
    robots: dict[str, RobotState], saved: SavedMap, keep_sessions: int
) -> list[str]:
    """Put a saved map's robots in place; returns the names loaded.

    A robot the merger has no map of gets the saved one. A robot whose live map is of the same
    session keeps the live one (it is at least as new). A robot whose live map is another
    session gets the saved map as an earlier session."""
    loaded = []
    for name, entry in saved.robots.items():
        if not len(entry.segments):
            continue
        state = robots.get(name)
        if state is not None and len(state.segments) and state.session == entry.session:
            continue
        target = name
        if state is not None and len(state.segments):
            holder = RobotState(name=name, map_frame=entry.map_frame)
            _fill(holder, entry)
            target = keep_session(robots, holder, keep_sessions) or ""
            if not target:
                continue
        else:
            if state is None:
                state = robots[name] = RobotState(name=name, session_of=entry.session_of)
            _fill(state, entry)
        loaded.append(target)
    return loaded


def _fill(state: RobotState, entry: SavedRobot) -> None:
    state.segments = np.asarray(entry.segments, dtype=np.float64)
    state.keyframe_poses = np.asarray(entry.keyframe_poses, dtype=np.float64)
    state.all_keyframes = []  # a saved map keeps no keyframes: merged as one rigid map
    state.session = entry.session
    state.map_frame = entry.map_frame
    state.loaded = True
    state.map_stamp = (
        None
        if entry.map_stamp is None
        else Time(sec=entry.map_stamp[0], nanosec=entry.map_stamp[1])
    )
    state.version += 1


def merge_pending(result: MergeResult | None) -> bool:
    """Did the merge update that gave ``result`` leave places unmatched or pairs of maps
    unjudged (its time budget spent)? Then the next update goes on, and its placements are
    not final."""
    if result is None:
        return False
    return result.stats.get("matches_pending", 0) + result.stats.get("verdicts_pending", 0) > 0


def result_of_saved(saved: SavedMap) -> MergeResult:
    """The saved merge as a :class:`MergeResult` (no pair results: each pair is matched again
    at the next merge; the reference is kept while it is in a largest group)."""
    names = sorted(saved.robots)
    return MergeResult(
        robots=names,
        placements={n: saved.robots[n].placement for n in names},
        reference=saved.reference,
        links=[],
        pairs={},
        segments=np.asarray(saved.segments, dtype=np.float64).reshape(-1, 4),
        segment_robot=np.asarray(saved.segment_robot, dtype=np.int64),
        timings={},
        stats={},
        probabilities={n: p for n in names if (p := saved.robots[n].probability) is not None},
    )


def robot_statuses(
    states: list[RobotState], result: MergeResult | None, now_ns: int, stale_timeout: float
) -> list[diagnostics.DiagnosticStatus]:
    """Each robot's /diagnostics status (OK merged, WARN unmerged, STALE silent) from what the
    merger knows of it (``now_ns``: the node clock)."""
    scores = diagnostics.link_scores(result)
    reasons = diagnostics.unmerged_reasons(result)
    statuses = []
    for state in states:
        placement = None if result is None else result.placements.get(state.name)
        link_value, best = scores.get(state.name, (None, 0.0))
        health = diagnostics.MergerRobotHealth(
            robot=state.name,
            placement=placement,
            reference=result is not None and result.reference == state.name,
            link_value=link_value,
            best_value=best,
            pose_rate=state.pose_rate.rate(),
            maps_received=state.version,
            keyframes=state.keyframes,
            segments=len(state.segments),
            silent_for=None if state.heard_ns is None else (now_ns - state.heard_ns) * 1e-9,
            stale_timeout=stale_timeout,
            session_of=state.session_of,
            why_unmerged=reasons.get(state.name, ""),
            probability=None if result is None else result.probabilities.get(state.name),
        )
        statuses.append(diagnostics.merger_status(health))
    return statuses
