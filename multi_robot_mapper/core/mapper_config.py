"""Configuration of a robot's mapper: everything ``robot_mapper`` and ``mrm`` read."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.extraction import ExtractionConfig
from multi_robot_mapper.core.local_mapping import LocalMapperConfig


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
    )
    segment_marker_width: float = param(
        0.03,
        unit="m",
        doc="line width of the segment markers (visualisation only)",
        minimum=0.0,
        exclusive_minimum=True,
    )
    partial_map_period: float = param(
        1.0,
        unit="s",
        doc="the whole partial map is republished at most once per this period, when it changed",
        minimum=0.0,
        maximum=3600.0,
        exclusive_minimum=True,
    )
    map_frame: str = param(
        "",
        unit="",
        doc="frame of partial_map and pose; empty means '<namespace>/map' ('map' at the root)",
    )
    max_scan_rate: float = param(
        0.0,
        unit="Hz",
        doc="map at most this many scans per second (by their stamps), skipping the rest before "
        "any work, counted; 0: every scan. A 40 Hz laser mapped at 10 Hz costs a quarter of the "
        "CPU: set it when many robots share one computer (slam_toolbox's throttle_scans)",
        minimum=0.0,
        maximum=1000.0,
    )
    diagnostics_period: float = param(
        1.0,
        unit="s",
        doc="how often the robot's status (scan rate, scans rejected and set aside by reason) "
        "goes out on /diagnostics",
        minimum=0.0,
        maximum=3600.0,
        exclusive_minimum=True,
    )
    stale_timeout: float = param(
        5.0,
        unit="s",
        doc="the status turns STALE when no scan arrived for this long (node clock: sim time "
        "when use_sim_time is set)",
        minimum=0.0,
        maximum=86400.0,
        exclusive_minimum=True,
    )

    def __post_init__(self) -> None:
        validate(self)
