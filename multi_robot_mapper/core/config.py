"""Typed configuration as data.

Every component has one frozen dataclass whose fields carry their default, unit, meaning and
bounds. The same functions load it from a flat ``{"section.name": value}`` mapping, whatever
that mapping came from: ROS parameters, a YAML file in ``config/`` or ``mrm --set`` options.
Values are validated on load and errors name the parameter, the value and the rule broken.

A field given ``tune`` (when a user changes it) is a *user parameter*: a ROS parameter of its
node and a key of ``config/<node>.yaml``. Every other field is a *fixed constant*: its default
holds in the nodes, and only ``mrm --set`` / ``--config`` (experiments offline) or a config
built in Python change it.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import typing
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, TypeVar

C = TypeVar("C")

_SCALAR_TYPES: Mapping[str, type] = MappingProxyType(
    {"float": float, "int": int, "bool": bool, "str": str}
)


class ConfigError(ValueError):
    """A configuration value is unknown, of the wrong type or out of bounds."""


def param(
    default: Any,
    *,
    unit: str,
    doc: str,
    minimum: float | None = None,
    maximum: float | None = None,
    exclusive_minimum: bool = False,
    choices: tuple[str, ...] | None = None,
    tune: str = "",
) -> Any:
    """A documented configuration field (use as a dataclass field default); ``tune`` says when
    a user changes it and makes it a user parameter (at most 30 per node)."""
    metadata = {
        "unit": unit,
        "doc": doc,
        "minimum": minimum,
        "maximum": maximum,
        "exclusive_minimum": exclusive_minimum,
        "choices": choices,
        "tune": tune,
    }
    return dataclasses.field(default=default, metadata=metadata)


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """Everything known about one scalar configuration field, by its dotted name."""

    name: str
    kind: type
    default: Any
    unit: str
    doc: str
    minimum: float | None
    maximum: float | None
    exclusive_minimum: bool
    choices: tuple[str, ...] | None
    tune: str = ""  # when a user changes it; empty: a fixed constant

    @property
    def user(self) -> bool:
        """A user parameter (a ROS parameter of its node), not a fixed constant."""
        return bool(self.tune)

    def within(self, value: float) -> bool:
        """Whether a number lies in this field's declared range."""
        low = self.minimum
        if low is not None and (value < low or (self.exclusive_minimum and value == low)):
            return False
        return self.maximum is None or value <= self.maximum

    def range_text(self) -> str:
        """The declared range, e.g. ``[0.005, 10] m``."""
        low = "(" if self.exclusive_minimum else "["
        lo = "-inf" if self.minimum is None else f"{self.minimum:g}"
        hi = "inf" if self.maximum is None else f"{self.maximum:g}"
        return f"{low}{lo}, {hi}]{' ' + self.unit if self.unit else ''}"

    def describe(self) -> str:
        """One line for ROS parameter descriptors and ``--help``."""
        bounds = ""
        if self.choices:
            bounds = f" One of: {', '.join(self.choices)}."
        elif self.minimum is not None or self.maximum is not None:
            low = "(" if self.exclusive_minimum else "["
            lo = "-inf" if self.minimum is None else f"{self.minimum:g}"
            hi = "inf" if self.maximum is None else f"{self.maximum:g}"
            bounds = f" Range {low}{lo}, {hi}]."
        unit = f" [{self.unit}]" if self.unit else ""
        return f"{self.doc}{unit}.{bounds}"


def field_specs(cls: type, prefix: str = "") -> list[FieldSpec]:
    """The scalar fields of a (possibly nested) config dataclass, with dotted names."""
    return list(_field_specs(cls, prefix))


@functools.cache  # every validate() needs them; resolving the type hints is the slow part
def _field_specs(cls: type, prefix: str) -> tuple[FieldSpec, ...]:
    specs: list[FieldSpec] = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        kind = hints[f.name]
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(kind):
            specs.extend(field_specs(typing.cast(type, kind), prefix=f"{name}."))
            continue
        if kind not in _SCALAR_TYPES.values():
            raise TypeError(f"config field {name} has unsupported type {kind!r}")
        md = f.metadata
        specs.append(
            FieldSpec(
                name=name,
                kind=kind,
                default=f.default,
                unit=md.get("unit", ""),
                doc=md.get("doc", ""),
                minimum=md.get("minimum"),
                maximum=md.get("maximum"),
                exclusive_minimum=bool(md.get("exclusive_minimum", False)),
                choices=md.get("choices"),
                tune=md.get("tune", ""),
            )
        )
    return tuple(specs)


def user_specs(cls: type) -> list[FieldSpec]:
    """The user parameters of a node's config class: its ROS parameters, in field order."""
    return [spec for spec in field_specs(cls) if spec.user]


def fixed_message(names: list[str], node: str) -> str:
    """One line refusing fixed constants given to a node as ROS parameters, naming them and
    saying how an experiment reaches them instead."""
    which = ", ".join(repr(n) for n in names)
    what = (
        "is a fixed constant of {node}, not a ROS parameter"
        if len(names) == 1
        else "are fixed constants of {node}, not ROS parameters"
    ).format(node=node)
    by_set = node == "robot_mapper" or all(n.startswith("merge.") for n in names)
    option = "--set NAME=VALUE" if by_set else "--merger-config FILE"
    return (
        f"{which} {what} (docs/parameters.md says which is which); for an experiment, "
        f"change it offline: mrm replay ... {option}"
    )


def _coerce(spec: FieldSpec, value: Any) -> Any:
    kind = spec.kind
    ok: bool
    if kind is bool:
        ok = isinstance(value, bool)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    else:
        ok = isinstance(value, str)
    if not ok:
        raise ConfigError(
            f"parameter '{spec.name}' must be {kind.__name__}, "
            f"got {value!r} ({type(value).__name__})"
        )
    value = kind(value)
    if spec.choices is not None and value not in spec.choices:
        raise ConfigError(
            f"parameter '{spec.name}' = {value!r} is not one of {', '.join(spec.choices)}"
        )
    if kind is float and value != value:  # NaN
        raise ConfigError(f"parameter '{spec.name}' is NaN; allowed: {spec.range_text()}")
    if kind in (int, float) and not spec.within(value):
        unit = f" {spec.unit}" if spec.unit else ""
        raise ConfigError(
            f"parameter '{spec.name}' = {value!r}{unit} is outside its range {spec.range_text()}"
        )
    return value


def validate(config: Any) -> None:
    """Check every scalar field of a config instance against its declared type and bounds."""
    for spec in field_specs(type(config)):
        value: Any = config
        for part in spec.name.split("."):
            value = getattr(value, part)
        _coerce(spec, value)


def flatten_mapping(mapping: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}``; dotted keys pass through unchanged."""
    flat: dict[str, Any] = {}
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten_mapping(value, prefix=f"{name}."))
        else:
            flat[name] = value
    return flat


def unknown_message(unknown: list[str], known: list[str]) -> str:
    """One line naming unknown parameters, with the closest known name of each."""
    hints = []
    for name in unknown:
        match = difflib.get_close_matches(name, known, n=1)
        if not match:  # a misplaced section: 'slide_step' for 'local_mapping.integrate.slide_step'
            match = [k for k in known if k.endswith("." + name)][:1]
        if match:
            hints.append(f"'{name}' -> '{match[0]}'")
    close = f"; did you mean {', '.join(hints)}?" if hints else ""
    return f"unknown parameter(s) {', '.join(repr(n) for n in unknown)}{close}"


def config_from_flat(cls: type[C], values: Mapping[str, Any]) -> C:
    """Build a config of type ``cls`` from dotted names; missing names keep their defaults."""
    return _build(cls, check_values(cls, values), prefix="")


def check_values(cls: type, values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` checked field by field against ``cls`` (names, types, declared ranges) and
    coerced; raises :class:`ConfigError` naming the first problem."""
    specs = {s.name: s for s in field_specs(cls)}
    unknown = sorted(set(values) - set(specs))
    if unknown:
        raise ConfigError(unknown_message(unknown, list(specs)))
    return {name: _coerce(specs[name], v) for name, v in values.items()}


def _build(cls: type[C], values: Mapping[str, Any], prefix: str) -> C:
    kwargs: dict[str, Any] = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(typing.cast(Any, cls)):
        kind = hints[f.name]
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(kind):
            kwargs[f.name] = _build(typing.cast(type, kind), values, prefix=f"{name}.")
        elif name in values:
            kwargs[f.name] = values[name]
    return cls(**kwargs)


def config_to_flat(config: Any) -> dict[str, Any]:
    """Dotted names and values of a config instance (the inverse of :func:`config_from_flat`)."""
    flat: dict[str, Any] = {}
    for spec in field_specs(type(config)):
        value: Any = config
        for part in spec.name.split("."):
            value = getattr(value, part)
        flat[spec.name] = value
    return flat


def parse_override(text: str) -> tuple[str, Any]:
    """Parse a ``name=value`` command-line override; the value is read as YAML would read it."""
    if "=" not in text:
        raise ConfigError(f"override {text!r} is not of the form name=value")
    name, raw = text.split("=", 1)
    raw = raw.strip()
    value: Any
    lowered = raw.lower()
    if lowered in ("true", "false"):
        value = lowered == "true"
    else:
        try:
            value = int(raw)
        except ValueError:
            try:
                value = float(raw)
            except ValueError:
                value = raw
    return name.strip(), value
