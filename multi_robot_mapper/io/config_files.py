"""Configuration from YAML files: plain nested mappings or ROS 2 ``--params-file`` files.

A file in ``config/`` is a ROS 2 parameters file (``/**: {ros__parameters: {...}}``), so the
same file serves ``ros2 run ... --params-file`` and ``mrm ... --config``.
"""

from __future__ import annotations

import textwrap
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import yaml

from multi_robot_mapper.core.config import (
    ConfigError,
    FieldSpec,
    check_values,
    config_from_flat,
    field_specs,
    flatten_mapping,
    parse_override,
    user_specs,
)

C = TypeVar("C")


# A parameters file is a few kilobytes; anything far larger is not one (and is not read).
MAX_CONFIG_BYTES = 1_000_000


def parameters_from_yaml(path: str | Path, node_name: str | None = None) -> dict[str, Any]:
    """The flat dotted parameters of a YAML file (ROS params-file layout or a plain mapping).

    In a params file, ``/**`` applies to every node; a section named after ``node_name``
    (with or without namespace) is applied on top of it. Every problem with the file is a
    :class:`ConfigError` of one line naming the file (and the key, when one is at fault).
    """
    path = Path(path)
    try:
        if path.is_dir():
            raise ConfigError(f"configuration file {path} is a directory")
        if path.stat().st_size > MAX_CONFIG_BYTES:
            raise ConfigError(
                f"configuration file {path} is larger than {MAX_CONFIG_BYTES} bytes: "
                "not a parameters file"
            )
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ConfigError(f"configuration file {path} does not exist") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"configuration file {path} is not UTF-8 text (byte {exc.start}: "
            f"{exc.object[exc.start : exc.start + 1]!r})"
        ) from exc
    except OSError as exc:
        raise ConfigError(f"configuration file {path} cannot be read ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        problem = getattr(exc, "problem", None) or type(exc).__name__
        raise ConfigError(f"configuration file {path} is not valid YAML{line}: {problem}") from exc
    except RecursionError as exc:  # deeply nested flow collections
        raise ConfigError(f"configuration file {path} is nested too deeply") from exc
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"configuration file {path} must hold a mapping at top level")
    sections = [v for v in data.values() if isinstance(v, Mapping) and "ros__parameters" in v]
    if not sections:
        return _flat(data, path, "")
    flat: dict[str, Any] = {}
    for key, value in data.items():
        if not (isinstance(value, Mapping) and "ros__parameters" in value):
            continue
        name = str(key).rstrip("/").split("/")[-1]
        if key == "/**" or (node_name is not None and name == node_name):
            parameters = value["ros__parameters"]
            if parameters is None:
                continue
            if not isinstance(parameters, Mapping):
                raise ConfigError(
                    f"configuration file {path}: '{key}: ros__parameters' must be a mapping of "
                    f"parameters, not {parameters!r}"
                )
            flat.update(_flat(parameters, path, f"{key}: ros__parameters: "))
    return flat


def _flat(mapping: Mapping[Any, Any], path: Path, where: str) -> dict[str, Any]:
    """``flatten_mapping`` with every key a string and every value a scalar."""
    flat = flatten_mapping({str(k): v for k, v in mapping.items()})
    for name, value in flat.items():
        if not isinstance(value, (bool, int, float, str)):
            raise ConfigError(
                f"configuration file {path}: {where}'{name}' must be a single value, "
                f"not {type(value).__name__} {value!r}"[:300]
            )
    return flat


def load_config(
    cls: type[C],
    path: str | Path | None = None,
    overrides: Iterable[str] = (),
    node_name: str | None = None,
) -> C:
    """Defaults, then the YAML file, then ``name=value`` overrides; validated on load, every
    error naming where the value came from (the file or ``--set``)."""
    flat: dict[str, Any] = {}
    if path is not None:
        from_file = parameters_from_yaml(path, node_name=node_name)
        try:
            check_values(cls, from_file)
        except ConfigError as exc:
            raise ConfigError(f"configuration file {path}: {exc}") from exc
        flat.update(from_file)
    for text in overrides:
        name, value = parse_override(text)
        try:
            check_values(cls, {name: value})
        except ConfigError as exc:
            raise ConfigError(f"--set {text.strip()}: {exc}") from exc
        flat[name] = value
    return config_from_flat(cls, flat)


def params_file_header(node: str) -> str:
    """The comment heading ``config/<node>.yaml``."""
    mapper = node == "robot_mapper"
    namespace = " -r __ns:=/robot1" if mapper else ""
    option = "--config" if mapper else "replay --merger-config"
    experiment = (
        "`mrm --set NAME=VALUE`"
        if mapper
        else "`mrm replay --merger-config FILE` (merge.*: also --set)"
    )
    text = (
        f"{node}'s user parameters: its only ROS parameters, each with its range, unit, "
        f"meaning and when to change it. ROS 2 params-file layout, also read by `mrm {option}`; "
        "units are SI. Every other field is a fixed constant (docs/parameters.md): a params "
        f"file naming one is refused; {experiment} reaches it for experiments offline. "
        "Generated from the dataclass defaults in multi_robot_mapper/core by `make config` (a "
        "test keeps them equal)."
    )
    lines = [f"# {line}" for line in textwrap.wrap(text, width=97)]
    lines += [
        f"# Use: ros2 run multi_robot_mapper {node} --ros-args{namespace}",
        f"#   --params-file config/{node}.yaml",
    ]
    return "\n".join(lines) + "\n"


def default_params_file(config_class: type, node: str = "robot_mapper") -> str:
    """A ROS 2 params file holding every user parameter of ``config_class`` at its default,
    each with its range, unit, meaning and when to change it as a comment (``config/<node>.yaml``
    is this text)."""
    return params_file_header(node) + "/**:\n" + _parameters_section(config_class)


SYSTEM_PARAMS_FILE = "multi_robot_mapper.yaml"


# (node name, its config class), in the order the files list them; the node configs live in
# ros/ (ros/params_files.py names them), which this layer never imports.
Nodes = Sequence[tuple[str, type]]


def system_params_text(nodes: Nodes) -> str:
    """Every node's parameters in one params file, a section per node name in any namespace
    (``/**/robot_mapper``, ``/**/map_merger``): ``config/multi_robot_mapper.yaml``, for
    ``mrm run``, the launch file and ``ros2 run`` of either node."""
    header = (
        "# The user parameters of every node of multi_robot_mapper (ROS 2 params-file layout),\n"
        "# one section per node name in any namespace; the fixed constants are in\n"
        "# docs/parameters.md. Generated from the dataclass defaults by\n"
        "# `make config` (a test keeps it equal). Use: mrm run --robots robot1,robot2\n"
        f"#   --params-file config/{SYSTEM_PARAMS_FILE}, the launch file, or\n"
        "#   ros2 run multi_robot_mapper <node> --ros-args --params-file <this file>\n"
    )
    return header + "".join(
        f"/**/{node}:\n" + _parameters_section(config_class) for node, config_class in nodes
    )


def _parameters_section(config_class: type) -> str:
    """``  ros__parameters:`` and every user parameter of ``config_class`` at its default, each
    under a comment of its range (or unit), meaning and when to change it."""
    lines = ["  ros__parameters:"]
    opened: set[str] = set()
    for spec in user_specs(config_class):
        parts = spec.name.split(".")
        for depth in range(len(parts) - 1):
            section = ".".join(parts[: depth + 1])
            if section not in opened:
                opened.add(section)
                lines.append(f"{'    ' + '  ' * depth}{parts[depth]}:")
        indent = "    " + "  " * (len(parts) - 1)
        comment = f"{_bounds_text(spec)}{spec.doc}. When to change it: {spec.tune}."
        width = 99 - len(indent) - 2
        lines += [f"{indent}# {line}" for line in textwrap.wrap(comment, width=width)]
        lines.append(f"{indent}{parts[-1]}: {_yaml_scalar(spec.default)}")
    return "\n".join(lines) + "\n"


def _bounds_text(spec: FieldSpec) -> str:
    """``[0.01, 10] m: ``, ``Hz: `` or nothing: what a YAML comment starts with."""
    if spec.minimum is not None or spec.maximum is not None:
        return f"{spec.range_text()}: "
    return f"{spec.unit}: " if spec.unit else ""


def _yaml_scalar(value: bool | int | float | str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return yaml.safe_dump(value, default_style='"').strip()
    return repr(value)


PARAMETERS_DOC = "parameters.md"
_PARAMETERS_HEADER = """\
# Parameters

<!-- Generated by `make config` (python -m multi_robot_mapper.ros.params_files config) from the
     config dataclasses, as config/*.yaml is; test/test_docs.py keeps it equal. Do not edit:
     change the field's param(...) in multi_robot_mapper/core or /ros and run `make config`. -->

Every field of both nodes' configs, with its default, its range and its unit (SI), in two kinds:

- **User parameters**, at most 30 per node: the ones a user has a reason to change, each with
  when to change it. They are the node's only ROS parameters (`--params-file`, `-p NAME:=VALUE`,
  `ros2 param set`; `ros2 param describe` shows each range) and the only keys of its
  `config/<node>.yaml`.
- **Fixed constants**: every other field. The nodes use its default; its meaning says why it is
  that value. A params file or `-p` naming one is refused with one line naming it.

For experiments, `mrm ... --set NAME=VALUE` and `mrm ... --config FILE` reach every field of the
robot mapper, user parameter or fixed constant, offline (the merger's: `mrm replay ...
--merger-config FILE`, its `merge.*` also by `--set merge.NAME=VALUE`); code that builds a node in
Python gives it a whole config (`RobotMapper(config=...)`, `MapMerger(config=...)`). A value
outside its range, or an unknown name, is refused with one line naming it (exit code 2; a refused
`ros2 param set` keeps the old value). [architecture.md](architecture.md) says what each stage does
with them.
"""


def parameters_doc(nodes: Nodes) -> str:
    """``docs/parameters.md``: every field of every node, generated like ``config/*.yaml`` from
    the documented dataclass defaults: a table of each node's user parameters (default, range,
    unit, meaning, when to change it), then its fixed constants, a table per section, each
    naming the config class it comes from."""
    parts = [_PARAMETERS_HEADER]
    for node, config_class in nodes:
        users = user_specs(config_class)
        fixed = len(field_specs(config_class)) - len(users)
        parts.append(
            f"\n## {node}\n\n{len(users)} user parameters and {fixed} fixed constants. Its "
            f"params file is `config/{node}.yaml`;\n`config/{SYSTEM_PARAMS_FILE}` holds the "
            f"same as its `/**/{node}` section.\n\n### {node}'s user parameters\n\n"
            "| parameter | default | range | unit | meaning | when to change it |\n"
            "| --- | --- | --- | --- | --- | --- |\n"
            + "".join(_parameter_row(spec, spec.tune) for spec in users)
            + f"\n### {node}'s fixed constants\n"
        )
        for prefix, section_class, specs in _sections(config_class):
            title = f"`{prefix}.*`" if prefix else f"{node}'s own fields"
            parts.append(
                f"\n#### {title}\n\n`{section_class.__name__}` ({_source_of(section_class)})\n\n"
                "| parameter | default | range | unit | meaning |\n"
                "| --- | --- | --- | --- | --- |\n" + "".join(_parameter_row(s) for s in specs)
            )
    return "".join(parts)


def _source_of(config_class: type) -> str:
    """``multi_robot_mapper/core/x.py``: the file that defines ``config_class``."""
    return config_class.__module__.replace(".", "/") + ".py"


def _sections(config_class: type) -> list[tuple[str, type, list[FieldSpec]]]:
    """``(prefix, class, specs)`` per nested config dataclass, in field order; the fixed
    constants of each section only (the nested sections follow as sections of their own)."""
    import dataclasses
    import typing

    sections: list[tuple[str, type, list[FieldSpec]]] = []

    def walk(cls: type, prefix: str) -> None:
        own = [
            spec
            for spec in field_specs(cls, prefix)
            if "." not in spec.name[len(prefix) :] and not spec.user
        ]
        sections.append((prefix.rstrip("."), cls, own))
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            if dataclasses.is_dataclass(hints[f.name]):
                walk(typing.cast(type, hints[f.name]), f"{prefix}{f.name}.")

    walk(config_class, "")
    return [section for section in sections if section[2]]


def default_text(value: bool | int | float | str) -> str:
    """A default as the docs show it: ``true``, ``0.5``, ``"pivot"`` (a string quoted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    return repr(value)


def _parameter_row(spec: FieldSpec, *extra: str) -> str:
    """One table row: name, default, range (or choices), unit, meaning (and ``extra`` cells)."""

    def cell(text: str) -> str:  # a table cell: no column break, no HTML tag ('<namespace>')
        return text.replace("|", "\\|").replace("<", "\\<").replace("\n", " ")

    if spec.choices:
        bounds = "one of " + ", ".join(f"`{choice}`" for choice in spec.choices)
    elif spec.minimum is not None or spec.maximum is not None:
        bounds = spec.range_text().removesuffix(f" {spec.unit}" if spec.unit else "")
    else:
        bounds = ""
    default = default_text(spec.default)
    cells = (
        f"`{spec.name}`",
        f"`{default}`",
        cell(bounds),
        cell(spec.unit),
        cell(spec.doc),
        *(cell(text) for text in extra),
    )
    return "| " + " | ".join(cells) + " |\n"
