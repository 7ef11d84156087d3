"""What ``map_merger`` publishes, built as plain functions (no node): the global map's markers,
the occupancy grid, robot poses and frames in ``map``.

Every message is stamped with a stamp its caller took from the inputs, never ``now()``.
"""

from __future__ import annotations

import array
from collections.abc import Iterable, Mapping, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.core.merging.occupancy import OccupancyGrid
from multi_robot_mapper.io.messages import piece_frame, pose_msg, segments_marker

FloatArray = np.typing.NDArray[np.float64]

# Tableau-like colours, one per robot (by the robot's place in the sorted list of robots).
PALETTE = (
    (0.12, 0.47, 0.71),
    (1.00, 0.50, 0.05),
    (0.17, 0.63, 0.17),
    (0.84, 0.15, 0.16),
    (0.58, 0.40, 0.74),
    (0.55, 0.34, 0.29),
    (0.89, 0.47, 0.76),
    (0.50, 0.50, 0.50),
    (0.74, 0.74, 0.13),
    (0.09, 0.75, 0.81),
)


def robot_color(index: int) -> tuple[float, float, float, float]:
    """The colour of the ``index``-th robot (RGBA)."""
    r, g, b = PALETTE[index % len(PALETTE)]
    return (r, g, b, 1.0)


def stamp_key(stamp: Time) -> tuple[int, int]:
    """A stamp as a sortable ``(sec, nanosec)`` pair."""
    return (int(stamp.sec), int(stamp.nanosec))


def newest(stamps: Sequence[Time]) -> Time:
    """The latest of ``stamps`` (a zero stamp when there are none)."""
    return max(stamps, key=stamp_key) if stamps else Time()


def placed_poses(
    result: MergeResult,
    poses: Mapping[str, tuple[FloatArray, Time]],
    pieces: Mapping[str, int] | None = None,
) -> dict[str, tuple[FloatArray, Time]]:
    """Each merged robot's newest pose ``T_piece_laser`` moved into ``map`` (``T_map_laser``),
    with the stamp of the pose message it came from. ``pieces``: the piece each pose is in
    (its frame ``<robot>/map_<piece>``; default 0, the robot's map frame); a pose in a piece
    the merge did not place is left out."""
    placed: dict[str, tuple[FloatArray, Time]] = {}
    for robot, (pose, stamp) in poses.items():
        T_map_frame = frame_matrix(result, robot, (pieces or {}).get(robot, 0))
        if T_map_frame is None:
            continue
        T_map_laser = T_map_frame @ se2.matrix_from_pose(*pose)
        placed[robot] = (np.array(se2.pose_from_matrix(T_map_laser)), stamp)
    return placed


def frame_matrix(result: MergeResult, robot: str, piece: int) -> FloatArray | None:
    """``T_map_piece`` of a piece of a robot's map (piece 0: the robot's map frame), or None
    when the merge did not place it."""
    if piece == 0:
        return result.matrix(robot)
    pose = result.frames.get(robot, {}).get(piece)
    return None if pose is None else se2.matrix_from_pose(*pose)


MarkerKey = tuple[str, int]  # (namespace, id)
# A keyframe's marker kept for the next publication: its content key and the marker.
MarkerCache = dict[MarkerKey, tuple[bytes, Marker]]
WHOLE_MAP_ID = -1  # a robot merged without keyframes (a saved map): its segments in one marker


GLOBAL_MAP_NAMESPACE = "global_map"


def map_namespace(robot: str) -> str:
    """The namespace of a robot's keyframe markers in ``global_map``."""
    return f"{GLOBAL_MAP_NAMESPACE}/{robot}"


def global_map_markers(
    result: MergeResult,
    map_stamp: Time,
    poses: Mapping[str, tuple[FloatArray, Time]],
    frame: str,
    width: float,
    pieces: Mapping[str, int] | None = None,
    earlier: Iterable[MarkerKey] = (),
    cache: MarkerCache | None = None,
) -> MarkerArray:
    """The global map: one LINE_LIST per merged keyframe (namespace ``global_map/<robot>``,
    ``id`` = keyframe index, coloured per robot), its ``pose`` the keyframe's optimised pose in
    ``map`` and its points the global map segments it owns, in its own frame (a robot merged
    without keyframes: one marker, ``id`` -1, in ``map``); each merged robot's newest pose as
    an ARROW and its name as TEXT_VIEW_FACING; a DELETE for every marker of ``earlier`` (what
    the last publication showed) that is gone. ``poses`` are the robots' newest poses in their
    own frames (``pieces``: the piece each is in); every marker is stamped with the newest of
    ``map_stamp`` and the poses shown. ``cache`` keeps each keyframe's marker: a keyframe whose
    segments did not change is not rebuilt, only moved."""
    shown = placed_poses(result, poses, pieces)
    header = Header(frame_id=frame, stamp=newest([map_stamp, *(s for _, s in shown.values())]))
    markers = _map_markers(result, header, width, cache) + _robot_markers(result, shown, header)
    current = {(m.ns, m.id) for m in markers}
    for namespace, marker_id in sorted(set(earlier) - current):
        markers.append(Marker(header=header, ns=namespace, id=marker_id, action=Marker.DELETE))
    return MarkerArray(markers=markers)


def _map_markers(
    result: MergeResult, header: Header, width: float, cache: MarkerCache | None
) -> list[Marker]:
    """The global map's markers of :func:`global_map_markers`, robot by robot."""
    markers: list[Marker] = []
    for index, robot in enumerate(result.robots):
        color = robot_color(index)
        namespace = map_namespace(robot)
        keyframes = result.keyframe_maps(robot)
        if keyframes:
            for keyframe, pose, segments in keyframes:
                markers.append(
                    _keyframe_marker(
                        namespace, keyframe, pose, segments, header, width, color, cache
                    )
                )
            continue
        own = result.segments[result.segment_robot == index]
        if len(own) and result.placements.get(robot) is not None:
            markers.append(segments_marker(own, header, namespace, width, color, WHOLE_MAP_ID))
    return markers


def _robot_markers(
    result: MergeResult, shown: Mapping[str, tuple[FloatArray, Time]], header: Header
) -> list[Marker]:
    """Each robot's arrow at its newest pose in ``map`` (those in ``shown``) and its name, at
    that pose or, without one, at its map frame's origin (robots neither merged nor shown:
    nothing)."""
    markers: list[Marker] = []
    for index, robot in enumerate(result.robots):
        T_map_robot = result.matrix(robot)
        if T_map_robot is None and robot not in shown:
            continue
        where = (
            shown[robot][0] if robot in shown else np.array(se2.pose_from_matrix(T_map_robot))  # type: ignore[arg-type]
        )
        color = ColorRGBA(**dict(zip("rgba", robot_color(index), strict=True)))
        if robot in shown:
            arrow = Marker(header=header, ns="robot_poses", id=index, type=Marker.ARROW)
            arrow.action = Marker.ADD
            arrow.pose = pose_msg(where.tolist())
            arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.6, 0.12, 0.12
            arrow.color = color
            markers.append(arrow)
        text = Marker(header=header, ns="robot_names", id=index, type=Marker.TEXT_VIEW_FACING)
        text.action = Marker.ADD
        text.pose = pose_msg(where.tolist())
        text.pose.position.z = 0.6
        text.scale.z = 0.4
        text.color = color
        text.text = robot
        markers.append(text)
    return markers


def _keyframe_marker(
    namespace: str,
    keyframe: int,
    pose: FloatArray,
    segments: FloatArray,
    header: Header,
    width: float,
    color: tuple[float, float, float, float],
    cache: MarkerCache | None,
) -> Marker:
    """A keyframe's marker, rebuilt only when its segments (or width, colour) changed."""
    content = (
        np.ascontiguousarray(segments, dtype=np.float64).tobytes()
        + np.array([width, *color]).tobytes()
    )
    key = (namespace, keyframe)
    cached = None if cache is None else cache.get(key)
    if cached is not None and cached[0] == content:
        marker = cached[1]
    else:
        marker = segments_marker(segments, header, namespace, width, color, keyframe)
        if cache is not None:
            cache[key] = (content, marker)
    marker.header = header
    marker.pose = pose_msg(pose)
    return marker


def occupancy_grid_msg(grid: OccupancyGrid, stamp: Time, frame: str) -> OccupancyGridMsg:
    """``nav_msgs/OccupancyGrid`` of a grid: row-major from cell (0, 0), x fastest, cells
    -1 unknown / 0 free / 100 occupied; ``info.map_load_time`` = ``header.stamp`` = ``stamp``."""
    msg = OccupancyGridMsg()
    msg.header = Header(frame_id=frame, stamp=stamp)
    msg.info.map_load_time = stamp
    msg.info.resolution = float(grid.resolution)
    msg.info.width = grid.width
    msg.info.height = grid.height
    msg.info.origin = pose_msg((grid.origin[0], grid.origin[1], 0.0))
    msg.data = array.array("b", np.ascontiguousarray(grid.cells, dtype=np.int8).tobytes())
    return msg


def grid_from_msg(msg: OccupancyGridMsg) -> OccupancyGrid:
    """The grid of an ``nav_msgs/OccupancyGrid`` (inverse of :func:`occupancy_grid_msg`; the
    origin's rotation is assumed zero, as the merger publishes it)."""
    cells = np.frombuffer(msg.data, dtype=np.int8)
    origin = (float(msg.info.origin.position.x), float(msg.info.origin.position.y))
    shape = (int(msg.info.height), int(msg.info.width))
    return OccupancyGrid(origin, float(msg.info.resolution), cells.reshape(shape).copy())


def frame_transform(
    placement: Sequence[float], stamp: Time, map_frame: str, child_frame: str
) -> TransformStamped:
    """TF of a robot's map frame ``child_frame`` in ``map_frame`` (its placement)."""
    transform = TransformStamped()
    transform.header = Header(frame_id=map_frame, stamp=stamp)
    transform.child_frame_id = child_frame
    placed = pose_msg(placement)
    transform.transform.translation.x = placed.position.x
    transform.transform.translation.y = placed.position.y
    transform.transform.rotation = placed.orientation
    return transform


def piece_transforms(
    result: MergeResult, frames: Mapping[str, str], stamp: Time, map_frame: str
) -> dict[str, TransformStamped]:
    """TF of every other piece of a robot's map the merge placed (piece 0, the robot's map
    frame, is the robot's own transform), keyed by the piece's frame; ``frames``: each
    robot's map frame (default ``<robot>/map``)."""
    transforms = {}
    for robot, pieces in result.frames.items():
        base = frames.get(robot) or f"{robot}/map"
        for piece in pieces:
            T = frame_matrix(result, robot, piece)
            if piece and T is not None:
                child = piece_frame(base, piece)
                placement = se2.pose_from_matrix(T)
                transforms[child] = frame_transform(placement, stamp, map_frame, child)
    return transforms
