"""Typed configs as ROS parameters: declared with descriptors, validated on load and on set.

Only a config's user parameters (the fields with ``tune``, at most 30 per node) are ROS
parameters; every other field is a fixed constant at its default, or at the value of the config
a node is built with in Python (tests, experiments). Each parameter's descriptor carries the
range declared in its config field (the same table ``mrm --set`` and ``--config`` are checked
against), so ROS tools show it and ROS refuses a value outside it. A params-file key the node
does not know is refused as the CLI refuses it; one naming a fixed constant is refused saying
so.
"""

from __future__ import annotations

from collections.abc import Callable
from types import MappingProxyType
from typing import TypeVar

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from multi_robot_mapper.core.config import (
    ConfigError,
    FieldSpec,
    config_from_flat,
    config_to_flat,
    fixed_message,
    unknown_message,
    user_specs,
)

C = TypeVar("C")

_PARAMETER_TYPES = MappingProxyType(
    {
        float: Parameter.Type.DOUBLE,
        int: Parameter.Type.INTEGER,
        bool: Parameter.Type.BOOL,
        str: Parameter.Type.STRING,
    }
)


def declare_config(node: Node, cls: type[C], base: C | None = None) -> C:
    """Declare the user parameters of ``cls`` on ``node`` and return the validated config.

    Values from ``--params-file`` or ``parameter_overrides`` apply at declaration; an invalid
    value, a fixed constant or a parameter the node does not know raises :class:`ConfigError`
    naming it. ``base`` (default: the dataclass defaults) gives the fixed constants and the
    defaults of the user parameters.
    """
    values = config_to_flat(cls() if base is None else base)
    for spec in user_specs(cls):
        try:
            param = node.declare_parameter(spec.name, values[spec.name], descriptor(spec))
        except Exception as exc:  # rclpy raises several types for a wrongly typed override
            raise ConfigError(f"parameter '{spec.name}': {_one_line(exc)}") from exc
        values[spec.name] = param.value
    undeclared = unknown_overrides(node)
    fixed = [name for name in undeclared if name in values]
    unknown = [name for name in undeclared if name not in values]
    if fixed:
        message = fixed_message(fixed, node.get_name())
        raise ConfigError(f"{node.get_name()}: {message} (from --params-file or -p)")
    if unknown:
        message = unknown_message(unknown, [spec.name for spec in user_specs(cls)])
        raise ConfigError(f"{node.get_name()}: {message} (from --params-file or -p)")
    return config_from_flat(cls, values)


def descriptor(spec: FieldSpec) -> ParameterDescriptor:
    """The ROS descriptor of a config field: type, description and the declared range."""
    result = ParameterDescriptor(
        name=spec.name, type=_PARAMETER_TYPES[spec.kind], description=spec.describe()
    )
    if spec.kind in (int, float) and spec.minimum is not None and spec.maximum is not None:
        if spec.kind is int:
            result.integer_range = [
                IntegerRange(from_value=int(spec.minimum), to_value=int(spec.maximum), step=1)
            ]
        else:
            result.floating_point_range = [
                FloatingPointRange(
                    from_value=float(spec.minimum), to_value=float(spec.maximum), step=0.0
                )
            ]
    return result


def unknown_overrides(node: Node) -> list[str]:
    """Parameters a params file or ``-p`` gave this node that it never declared: a typo there
    would otherwise be ignored without a word."""
    # rclpy keeps the overrides meant for this node (its own sections and /**) here.
    overrides = getattr(node, "_parameter_overrides", {})
    return sorted(
        name
        for name in overrides
        if not node.has_parameter(name) and not name.startswith("qos_overrides.")
    )


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def on_config_change(node: Node, current: Callable[[], C], apply: Callable[[C], None]) -> None:
    """Validate ``ros2 param set`` changes as a whole config (the ``current`` one with the
    changes); apply it or refuse with the reason. ``apply`` may raise :class:`ConfigError`
    to refuse a config the fields' ranges allow."""

    def callback(params: list[Parameter]) -> SetParametersResult:
        config = current()
        values = config_to_flat(config)
        values.update({p.name: p.value for p in params})
        try:
            new = config_from_flat(type(config), values)
            apply(new)
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        except Exception as exc:  # a failed apply must not escape into the executor
            return SetParametersResult(successful=False, reason=f"not applied: {_one_line(exc)}")
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(callback)
