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
        maximum=3600.0,
    )
    segment_marker_width: float = param(
        0.03,
        unit="m",
        doc="line width of the segment markers (visualisation only)",
        minimum=0.001,
        maximum=10.0,
    )
    partial_map_period: float = param(
        1.0,
        unit="s",
        doc="the whole partial map is republished at most once per this period, when it changed",
        minimum=0.05,
        maximum=3600.0,
    )
    map_frame: str = param(
        "",
        unit="",
        doc="frame of partial_map and pose; empty means '<namespace>/map' ('map' at the root)",
    )

    def __post_init__(self) -> None:
        validate(self)
