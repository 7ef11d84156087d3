"""Configuration of a robot's mapper: everything ``robot_mapper`` and ``mrm`` read."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.extraction import ExtractionConfig


@dataclasses.dataclass(frozen=True)
class RobotMapperConfig:
    """Per-robot mapper. ROS parameter names are the dotted field names (``extraction.*``)."""

    extraction: ExtractionConfig = dataclasses.field(default_factory=ExtractionConfig)
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

    def __post_init__(self) -> None:
        validate(self)
