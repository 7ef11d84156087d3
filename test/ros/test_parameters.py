"""Config fields as ROS parameters (ros/parameters.py): each descriptor carries the field's
type, its description with unit and range, and the declared range ROS enforces."""

from __future__ import annotations

import dataclasses

from rcl_interfaces.msg import ParameterType

from multi_robot_mapper.core.config import field_specs, param, validate
from multi_robot_mapper.ros.parameters import descriptor


@dataclasses.dataclass(frozen=True)
class Example:
    period: float = param(1.0, unit="s", doc="how often", minimum=0.01, maximum=60.0)
    beams: int = param(100, unit="beams", doc="how many", minimum=2, maximum=10_000)
    kind: str = param("split", unit="", doc="which", choices=("split", "dce"))
    above: float = param(0.5, unit="m", doc="no upper bound", minimum=0.0)
    verbose: bool = param(False, unit="", doc="say more")

    def __post_init__(self) -> None:
        validate(self)


def kind_of(made: object) -> int:
    """The descriptor's type as rcl_interfaces numbers it (rclpy's Parameter.Type or its value)."""
    kind = made.type  # type: ignore[attr-defined]
    return int(getattr(kind, "value", kind))


def test_each_descriptor_has_the_fields_type_description_and_range() -> None:
    made = {spec.name: descriptor(spec) for spec in field_specs(Example)}
    period, beams, kind = made["period"], made["beams"], made["kind"]
    assert kind_of(period) == ParameterType.PARAMETER_DOUBLE
    assert period.description == "how often [s]. Range [0.01, 60]."
    (floats,) = period.floating_point_range
    assert (floats.from_value, floats.to_value, floats.step) == (0.01, 60.0, 0.0)
    assert not period.integer_range
    assert kind_of(beams) == ParameterType.PARAMETER_INTEGER
    (ints,) = beams.integer_range
    assert (ints.from_value, ints.to_value, ints.step) == (2, 10_000, 1)
    assert kind_of(kind) == ParameterType.PARAMETER_STRING
    assert kind.description == "which. One of: split, dce."
    # A range ROS can hold needs both ends: an open one is said, not enforced by ROS.
    assert made["above"].description == "no upper bound [m]. Range [0, inf]."
    assert not made["above"].floating_point_range
    assert kind_of(made["verbose"]) == ParameterType.PARAMETER_BOOL
    assert all(d.name == name for name, d in made.items())
