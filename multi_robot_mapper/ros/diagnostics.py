"""Robot health on ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``), as plain functions.

Both nodes publish on the absolute ``/diagnostics``, the topic ``diagnostic_aggregator``,
``rqt_runtime_monitor`` and Foxglove's diagnostics panel read (as ``diagnostic_updater`` does):

- ``robot_mapper`` one status per robot, named ``<robot>/robot_mapper``: scan rate (from the
  scans' header stamps), scans received / accepted / set aside / rejected, each by reason,
  scans skipped by ``max_scan_rate``, keyframes and map size. OK while scans arrive and are
  used; WARN when scans were rejected since the last report or none of them could be placed;
  STALE when no scan arrived for ``stale_timeout``.
- ``map_merger`` one status per robot, named ``map_merger/<robot>``: OK when merged (placed in
  ``map``), WARN when unmerged, STALE when neither its partial map nor its pose arrived for
  ``stale_timeout`` (its map stays in the global map); the merge score (the value, in metres
  of matching wall, of the link that placed it, and the best pair value it has with any
  robot), placement, pose rate and map size. A restarted robot's earlier map is reported as
  ``map_merger/<robot>_session<k>``.

Every array is stamped with the newest input stamp it reports on, never ``now()``; staleness is
judged on the node's clock (sim time when ``use_sim_time`` is set).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Mapping, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.core.se2 import Pose

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
STALE = DiagnosticStatus.STALE
TOPIC = "/diagnostics"


class RateMeter:
    """Messages per second over the header stamps of the last ``window`` messages."""

    def __init__(self, window: int = 50) -> None:
        self._stamps: deque[float] = deque(maxlen=window)

    def add(self, stamp: float) -> None:
        self._stamps.append(stamp)

    def rate(self) -> float | None:
        """None until two messages with different stamps arrived."""
        if len(self._stamps) < 2:
            return None
        span = self._stamps[-1] - self._stamps[0]
        return (len(self._stamps) - 1) / span if span > 0.0 else None


@dataclasses.dataclass(frozen=True)
class MapperHealth:
    """What ``robot_mapper`` reports about its robot."""

    robot: str
    scan_rate: float | None  # Hz, from the header stamps of the last scans received
    silent_for: float | None  # s since the last scan arrived (None: none yet)
    stale_timeout: float
    scans_received: int
    scans_accepted: int
    rejected: Mapping[str, int]  # scans refused before mapping, by reason
    set_aside: Mapping[str, int]  # scans the local mapper could not place, by reason
    keyframes: int
    map_segments: int
    recent_received: int  # since the last report
    recent_accepted: int
    recent_rejected: int
    skipped: int = 0  # left out by max_scan_rate (on purpose, not a fault)


def mapper_status(health: MapperHealth) -> DiagnosticStatus:
    """The status of one robot's mapper (see the module doc for the levels)."""
    rejected = sum(health.rejected.values())
    set_aside = sum(health.set_aside.values())
    if health.silent_for is None:
        level, message = STALE, "no scan received yet"
    elif health.silent_for > health.stale_timeout:
        level, message = STALE, f"no scan for {health.silent_for:.1f} s"
    elif health.recent_rejected:
        level = WARN
        message = f"{health.recent_rejected} scans rejected since the last report"
    elif health.recent_received and not health.recent_accepted:
        level, message = WARN, f"none of the last {health.recent_received} scans could be placed"
    else:
        level, message = OK, f"mapping at {_number(health.scan_rate, 'Hz')}"
    values = [
        ("scan rate (Hz)", _number(health.scan_rate)),
        ("scans received", str(health.scans_received)),
        ("scans skipped (max_scan_rate)", str(health.skipped)),
        ("scans accepted", str(health.scans_accepted)),
        ("scans rejected", str(rejected)),
        *((f"rejected: {reason}", str(n)) for reason, n in sorted(health.rejected.items())),
        ("scans set aside", str(set_aside)),
        *((f"set aside: {reason}", str(n)) for reason, n in sorted(health.set_aside.items())),
        ("keyframes", str(health.keyframes)),
        ("map segments", str(health.map_segments)),
        ("seconds since last scan", _number(health.silent_for)),
    ]
    return _status(f"{health.robot}/robot_mapper", health.robot, level, message, values)


@dataclasses.dataclass(frozen=True)
class MergerRobotHealth:
    """What ``map_merger`` reports about one robot."""

    robot: str
    placement: Pose | None  # T_map_robot (None: unmerged, or not merged yet)
    reference: bool  # its map frame is `map`
    link_value: float | None  # m, value of the tree link that placed it (None: none)
    best_value: float  # m, best pair value it has with any robot (0: none)
    pose_rate: float | None  # Hz of its pose messages (accepted scans)
    maps_received: int
    keyframes: int
    segments: int
    silent_for: float | None  # s since its last partial map or pose (None: none yet)
    stale_timeout: float
    session_of: str | None = None  # an earlier session of this robot, kept (not updated)
    why_unmerged: str = ""  # the joint merger's verdict on its best pair ("": none known)
    probability: float | None = None  # that its placement is right (None: not placed)


def merger_status(health: MergerRobotHealth) -> DiagnosticStatus:
    """The merger's status of one robot (see the module doc for the levels)."""
    merged = health.placement is not None
    if health.session_of is not None:
        # An earlier session never updates again: STALE would only say that.
        level = OK if merged else WARN
        message = f"earlier session of '{health.session_of}', map kept" + (
            "" if merged else " (unmerged)"
        )
    elif health.silent_for is None or health.silent_for > health.stale_timeout:
        level = STALE
        silent = (
            "nothing received"
            if health.silent_for is None
            else (f"silent for {health.silent_for:.1f} s")
        )
        if not health.segments:
            message = silent
        elif merged:
            message = f"{silent}; its map stays in the global map"
        else:  # not drawn: say why, as for a robot still talking
            message = f"{silent}; unmerged: {health.why_unmerged or 'no valid link yet'}"
    elif health.reference:
        level, message = OK, "merged (reference: its map frame is the global map frame)"
    elif merged:
        level, message = (
            OK,
            (
                f"merged (P right {_probability(health.probability)}, link value "
                f"{_number(health.link_value, 'm')})"
            ),
        )
    else:
        level = WARN
        message = (
            f"unmerged: {health.why_unmerged}"
            if health.why_unmerged
            else (f"unmerged: no valid link yet (best pair value {health.best_value:.1f} m)")
        )
    placement = (
        "unmerged" if health.placement is None else " ".join(f"{v:.3f}" for v in health.placement)
    )
    values = [
        ("merged", "yes" if merged else "no"),
        ("placement x y theta (m m rad)", placement),
        ("placement probability", _probability(health.probability)),
        ("merge score: link value (m)", _number(health.link_value)),
        ("merge score: best pair value (m)", f"{health.best_value:.2f}"),
        ("pose rate (Hz)", _number(health.pose_rate)),
        ("partial maps received", str(health.maps_received)),
        ("keyframes", str(health.keyframes)),
        ("map segments", str(health.segments)),
        ("seconds since last input", _number(health.silent_for)),
    ]
    return _status(f"map_merger/{health.robot}", health.robot, level, message, values)


def merge_status(
    result: MergeResult | None,
    merges: int,
    errors: int,
    last_merge_s: float | None,
    robots: int,
    up_to_date: bool | None = None,
) -> DiagnosticStatus:
    """The merger's own status, named ``map_merger``: OK when every robot is merged, WARN
    when some are not (or the last merge failed), STALE before the first merge.
    ``up_to_date``: every partial map received is in the last merge (None: not known), what
    a watcher in another process waits for before it reads the final map (``mrm demo``)."""
    placed = 0 if result is None else sum(p is not None for p in result.placements.values())
    if result is None:
        level, message = STALE, "no merge yet"
    elif placed < robots:
        level, message = WARN, f"{placed} of {robots} robots merged"
    else:
        level, message = OK, f"all {robots} robots merged"
    values = [
        ("robots merged", str(placed)),
        ("robots", str(robots)),
        ("reference", "-" if result is None or result.reference is None else result.reference),
        ("merges", str(merges)),
        ("merge errors", str(errors)),
        ("last merge (s)", _number(last_merge_s)),
        ("up to date", "-" if up_to_date is None else ("yes" if up_to_date else "no")),
        ("global map segments", "0" if result is None else str(len(result.segments))),
    ]
    return _status("map_merger", "map_merger", level, message, values)


def unmerged_reasons(result: MergeResult | None) -> dict[str, str]:
    """Per unmerged robot, why it is not placed: the joint merger's own reason
    (``MergeResult.unmerged_reasons``), else (a result without them) why its best pair of
    maps (most matched wall) placed it nowhere, as the pair's verdict says."""
    if result is None:
        return {}
    if result.unmerged_reasons:
        return dict(result.unmerged_reasons)
    best: dict[str, tuple[float, str]] = {}
    for pair, verdict in result.verdicts.items():
        robots = {key[0] for key in pair}  # keys are (robot, piece) units
        value = float(sum(c.value for c in getattr(verdict, "links", ())))
        reason = str(getattr(verdict, "reason", "")) or (
            "its pair was accepted but not joined to the reference's group (it breaks a "
            "cycle, or the group is not the largest)"
        )
        for robot in robots if len(robots) == 2 else ():
            if result.placements.get(robot) is None and value > best.get(robot, (-1.0, ""))[0]:
                best[robot] = (value, reason)
    return {robot: reason for robot, (_, reason) in best.items()}


def link_scores(result: MergeResult | None) -> dict[str, tuple[float | None, float]]:
    """Per robot: the value of the spanning-tree link that placed it (None for the reference
    and for unmerged robots) and its best pair value with any robot (valid or not)."""
    if result is None:
        return {}
    scores: dict[str, tuple[float | None, float]] = {}
    for robot in result.robots:
        best = max(
            (rec.link.value for pair, rec in result.pairs.items() if robot in pair), default=0.0
        )
        scores[robot] = (None, float(best))
    # Walk the tree from the reference: each robot's score is the edge it was reached by.
    frontier = [] if result.reference is None else [result.reference]
    reached = set(frontier)
    while frontier:
        robot = frontier.pop()
        for link in result.links:
            if robot not in (link.robot_a, link.robot_b):
                continue
            other = link.robot_b if robot == link.robot_a else link.robot_a
            if other not in reached:
                reached.add(other)
                scores[other] = (float(link.value), scores[other][1])
                frontier.append(other)
    return scores


def diagnostic_array(statuses: Sequence[DiagnosticStatus], stamp: Time) -> DiagnosticArray:
    """The array of ``statuses`` stamped ``stamp``."""
    return DiagnosticArray(header=Header(stamp=stamp), status=list(statuses))


def _status(
    name: str, hardware_id: str, level: bytes, message: str, values: list[tuple[str, str]]
) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=level,
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=k, value=v) for k, v in values],
    )


def _probability(value: float | None) -> str:
    """A probability near 1 with the digits that tell it apart (0.9993, not 1.00)."""
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.4f}" if value < 0.9999 else f"1 - {1.0 - value:.1e}"


def _number(value: float | None, unit: str = "") -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.2f}" + (f" {unit}" if unit else "")
