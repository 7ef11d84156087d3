"""Typed configs as ROS parameters: declared with descriptors, validated on load and on set."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from multi_robot_mapper.core.config import ConfigError, config_from_flat, field_specs

C = TypeVar("C")

_PARAMETER_TYPES = {
    float: Parameter.Type.DOUBLE,
    int: Parameter.Type.INTEGER,
    bool: Parameter.Type.BOOL,
    str: Parameter.Type.STRING,
}


def declare_config(node: Node, cls: type[C]) -> C:
    """Declare every field of ``cls`` as a parameter of ``node`` and return the validated config.

    Values from ``--params-file`` or ``parameter_overrides`` apply at declaration; an invalid
    value raises :class:`ConfigError` naming it.
    """
    values: dict[str, Any] = {}
    for spec in field_specs(cls):
        descriptor = ParameterDescriptor(
            name=spec.name, type=_PARAMETER_TYPES[spec.kind], description=spec.describe()
        )
        try:
            param = node.declare_parameter(spec.name, spec.default, descriptor)
        except Exception as exc:  # rclpy raises several types for a wrongly typed override
            raise ConfigError(f"parameter '{spec.name}': {exc}") from exc
        values[spec.name] = param.value
    return config_from_flat(cls, values)


def on_config_change(node: Node, cls: type[C], apply: Callable[[C], None]) -> None:
    """Validate ``ros2 param set`` changes as a whole config; apply it or refuse with the reason."""

    def callback(params: list[Parameter]) -> SetParametersResult:
        values = {spec.name: node.get_parameter(spec.name).value for spec in field_specs(cls)}
        values.update({p.name: p.value for p in params})
        try:
            config = config_from_flat(cls, values)
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        apply(config)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(callback)
