"""Configuration of a robot's mapper: everything ``robot_mapper`` and ``mrm`` read."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import LocalMapperConfig
from multi_robot_mapper.core.scan_stream import ScanStreamConfig

# The stream rules' defaults are defined beside the rules (core/scan_stream.py), which the
# offline pipeline applies without this node config; the node's parameters start from them.
_STREAM = ScanStreamConfig()


@dataclasses.dataclass(frozen=True)
class RobotMapperConfig:
    """Per-robot mapper. ROS parameter names are the dotted field names (``extraction.*``,
    ``local_mapping.*``, ``local_mapping.integrate.*``)."""

    extraction: ExtractionConfig = dataclasses.field(default_factory=ExtractionConfig)
    local_mapping: LocalMapperConfig = dataclasses.field(default_factory=LocalMapperConfig)
    warning_period: float = param(
        10.0,
        unit="s",
        doc="the same kind of bad-scan warning is logged at most once per this period",
        minimum=0.0,
        maximum=3600.0,
        tune="shorter while you chase bad input, longer for quieter logs",
    )
    segment_marker_width: float = param(
        0.03,
        unit="m",
        doc="line width of the segment markers (visualisation only)",
        minimum=0.001,
        maximum=10.0,
        tune="the map looks too thin or too thick in RViz at your zoom",
    )
    partial_map_period: float = param(
        1.0,
        unit="s",
        doc="the partial map goes out at most once per this period, when it changed (only what "
        "changed, between snapshots)",
        minimum=0.05,
        maximum=3600.0,
        tune="longer on a thin radio link (the map goes out less often); shorter to see the map "
        "sooner",
    )
    snapshot_period: float = param(
        120.0,
        unit="s",
        doc="the whole partial map goes out on partial_map (transient local: what a late or "
        "restarted merger and a viewer get first) at most once per this period, and when a "
        "receiver asks on partial_map_request; between snapshots, partial_map_updates carries "
        "only what changed (io/map_updates.py). A fixed constant: snapshots are most of the "
        "bytes (docs/network.md) and a merger that misses an update asks for one at once",
        minimum=0.05,
        maximum=3600.0,
    )
    scan_max_queue_delay: float = param(
        0.5,
        unit="s",
        doc="a scan that waited longer than this in the subscription's queue is dropped "
        "(counted) so that the newest scans are mapped: the latency stays bounded when scans "
        "come faster than they can be mapped",
        minimum=0.01,
        maximum=60.0,
        tune="longer on a slow computer that maps in bursts (more scans mapped, more latency); "
        "shorter keeps the pose fresher",
    )
    stamp_reset_jump: float = param(
        _STREAM.reset_jump,
        unit="s",
        doc="a scan stamped further back than this from the last one (a bag played again, a "
        "clock reset) starts the robot's map over; a smaller step back is a stale scan, "
        "dropped, and a repeated stamp a duplicate, dropped",
        minimum=0.01,
        maximum=1e6,
    )
    max_stamp_lead: float = param(
        _STREAM.max_lead,
        unit="s",
        doc="a scan stamped further ahead of this node's clock is dropped (a robot clock far "
        "off, a corrupt stamp); not checked while a simulated clock has not started",
        minimum=0.0,
        maximum=1e6,
        tune="raise it to the clock offset of robots whose clocks are not synchronised with this "
        "computer's (no NTP or chrony)",
    )
    stamp_gap_periods: float = param(
        _STREAM.gap_periods,
        unit="intervals",
        doc="a scan stamped further ahead of the last mapped one than this many of the "
        "stream's scan intervals (their recent median) is held until stamp_confirm_scans scans "
        "confirm the new time, and refused (stamp_jump_ahead) when the next scan continues the "
        "old one: one stamp far ahead must not make every later scan look stale",
        minimum=1.0,
        maximum=1e6,
    )
    stamp_confirm_scans: int = param(
        _STREAM.confirm_scans,
        unit="scans",
        doc="scans in a row that must continue a new time (a jump ahead of the cadence, or "
        "back beyond stamp_reset_jump) before it is believed: then they are mapped (a jump "
        "back first starts the map over); a corrupt stamp is one scan, a clock that jumped "
        "stays there",
        minimum=1,
        maximum=1000,
    )
    geometry_change_scans: int = param(
        _STREAM.geometry_scans,
        unit="scans",
        doc="a scan whose angle_min, angle_max, angle_increment or beam count differ from the "
        "laser's (its first scan's) is refused (angle_fields), unless this many scans in a row "
        "have the new geometry: the laser was reconfigured, its new geometry is used from then "
        "on (with a warning)",
        minimum=1,
        maximum=100000,
    )
    copy_window: int = param(
        _STREAM.copy_window,
        unit="scans",
        doc="a scan whose ranges are an exact copy of one of the last this many mapped scans' "
        "is refused (copied_ranges): no laser reads the same twice; 0: not checked",
        minimum=0,
        maximum=1000000,
        tune="a simulated laser without noise (it reads the same ranges twice while the robot "
        "stands): 0",
    )
    map_frame: str = param(
        "",
        unit="",
        doc="frame of partial_map and pose; empty means '<namespace>/map' ('map' at the root)",
        tune="your robot's map frame has another name",
    )
    max_scan_rate: float = param(
        0.0,
        unit="Hz",
        doc="map at most this many scans per second (by their stamps), skipping the rest before "
        "any work, counted; 0: every scan. A 40 Hz laser mapped at 10 Hz costs a quarter of the "
        "CPU: set it when many robots share one computer (slam_toolbox's throttle_scans)",
        minimum=0.0,
        maximum=1000.0,
        tune="many robots on one computer: 10 maps a quarter of a 40 Hz laser's scans",
    )
    backend_process: bool = param(
        True,
        unit="",
        doc="run the local mapper's back end (loop closures, the pose graph) in a worker "
        "process: on a thread of this process it would take Python's interpreter lock from "
        "the scan callback for hundreds of milliseconds per keyframe; false: on a thread. "
        "Read when the node starts (and when its map starts over)",
        tune="a computer with one core or little memory (false: no second process per robot), or "
        "to debug the back end in one process",
    )
    diagnostics_period: float = param(
        1.0,
        unit="s",
        doc="how often the robot's status (scan rate, scans rejected and set aside by reason) "
        "goes out on /diagnostics",
        minimum=0.01,
        maximum=3600.0,
        tune="your diagnostics aggregator or monitor expects another rate",
    )
    stale_timeout: float = param(
        5.0,
        unit="s",
        doc="the status turns STALE when no scan arrived for this long (node clock: sim time "
        "when use_sim_time is set)",
        minimum=0.01,
        maximum=86400.0,
        tune="longer for a laser slower than 1 Hz or scans that pause (a bag played in pieces)",
    )

    def __post_init__(self) -> None:
        validate(self)

    def stream_config(self) -> ScanStreamConfig:
        """The rules every scan of the robot's stream is checked by before it is mapped."""
        return ScanStreamConfig(
            reset_jump=self.stamp_reset_jump,
            max_lead=self.max_stamp_lead,
            gap_periods=self.stamp_gap_periods,
            confirm_scans=self.stamp_confirm_scans,
            geometry_scans=self.geometry_change_scans,
            copy_window=self.copy_window,
        )
