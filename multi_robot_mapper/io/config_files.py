"""Configuration from YAML files: plain nested mappings or ROS 2 ``--params-file`` files.

A file in ``config/`` is a ROS 2 parameters file (``/**: {ros__parameters: {...}}``), so the
same file serves ``ros2 run ... --params-file`` and ``mrm ... --config``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

from multi_robot_mapper.core.config import (
    ConfigError,
    config_from_flat,
    flatten_mapping,
    parse_override,
)

C = TypeVar("C")


def parameters_from_yaml(path: str | Path, node_name: str | None = None) -> dict[str, Any]:
    """The flat dotted parameters of a YAML file (ROS params-file layout or a plain mapping).

    In a params file, ``/**`` applies to every node; a section named after ``node_name``
    (with or without namespace) is applied on top of it.
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ConfigError(f"configuration file {path} does not exist") from exc
    except yaml.YAMLError as exc:
        raise ConfigError(f"configuration file {path} is not valid YAML: {exc}") from exc
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"configuration file {path} must hold a mapping at top level")
    sections = [v for v in data.values() if isinstance(v, Mapping) and "ros__parameters" in v]
    if not sections:
        return flatten_mapping(data)
    flat: dict[str, Any] = {}
    for key, value in data.items():
        if not (isinstance(value, Mapping) and "ros__parameters" in value):
            continue
        name = str(key).rstrip("/").split("/")[-1]
        if key == "/**" or (node_name is not None and name == node_name):
            flat.update(flatten_mapping(value["ros__parameters"]))
    return flat


def load_config(
    cls: type[C],
    path: str | Path | None = None,
    overrides: Iterable[str] = (),
    node_name: str | None = None,
) -> C:
    """Defaults, then the YAML file, then ``name=value`` overrides; validated on load."""
    flat: dict[str, Any] = {}
    if path is not None:
        flat.update(parameters_from_yaml(path, node_name=node_name))
    for text in overrides:
        name, value = parse_override(text)
        flat[name] = value
    return config_from_flat(cls, flat)
