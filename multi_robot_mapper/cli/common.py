"""What every ``mrm`` command shares: the user-error type and the configuration options."""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.merger_config import MapMergerConfig

MERGER_PREFIX = "merge."  # --set names of the merging parameters (map_merger's merge.*)


class CliError(Exception):
    """A user error: printed as one line on stderr, exit code 2."""


def missing_input(path: str | Path, kind: str) -> CliError:
    """The one wording of an input that is not there: ``no such <kind>: <path>``."""
    return CliError(f"no such {kind}: {path}")


# reStructuredText in the docstrings that describe commands: ``literal`` and :role:`target`.
_LITERAL = re.compile(r"``(.+?)``", re.DOTALL)
_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def plain_text(text: str) -> str:
    """``text`` without reStructuredText markup (``x`` -> x, :func:`a.b` -> a.b)."""
    return _ROLE.sub(r"\1", _LITERAL.sub(r"\1", text))


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions as written (paragraphs kept) but without reStructuredText, and every
    option's default said: an option whose help does not name its default gets
    ``(default: X)``; a flag (store_true) is off unless given, which its help says."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return super()._fill_text(plain_text(text), width, indent)

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = plain_text(action.help or "")
        takes_value = action.nargs != 0
        if (
            action.option_strings
            and takes_value
            and not action.required
            and action.default not in (None, [], argparse.SUPPRESS)
            and "default" not in text
        ):
            text += " (default: %(default)s)"
        return text


def finish_parsers(parser: argparse.ArgumentParser) -> None:
    """Every sub-command parser below ``parser`` formats its help with :class:`HelpFormatter`."""
    parser.formatter_class = HelpFormatter
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                finish_parsers(sub)


# Every number a command-line option takes, with its allowed range: one table, checked before
# any work (the node and config parameters have theirs in the config dataclasses).
CLI_LIMITS: Mapping[str, tuple[float, float, str]] = MappingProxyType(
    {
        "robots": (1, 100, "robots"),
        "seed": (0, 2**32 - 1, ""),
        "rate": (0.1, 1000.0, "Hz"),
        # simulate: no more than the front end takes (larger scans are refused as corrupt)
        "beams": (2, ExtractionConfig().max_beams, "beams"),
        # demo: 100 times slower plays its 38 s of scans in an hour (duration's bound); faster
        # than 100 times, every mapper drops nearly every scan
        "speed": (0.01, 100.0, "times real time"),
        "noise": (0.0, 1.0, "m"),
        "duration": (0.1, 3600.0, "s"),
        # replay --record-period: seconds of bag time between two recorded merges
        "record_period": (0.1, 3600.0, "s"),
        "clutter": (0.0, 2.0, "objects/m^2"),
        # simulate --world generated: a building's largest extent, its walking people, and the
        # driving between kept scans of a sparse run
        "size": (20.0, 200.0, "m"),
        "people": (0, 1000, "people"),
        "sparse": (0.05, 100.0, "m"),
        "overlap_scans": (0, 1_000_000, "scans"),
        "range_max": (0.1, 100_000.0, "m"),
        "max_points": (1, 10_000_000, "points"),
    }
)
# simulate keeps every reading in memory before writing: about 1 GB at this many.
MAX_SIMULATED_READINGS = 100_000_000


def check_limits(args: argparse.Namespace, *names: str) -> None:
    """Refuse (one line, exit 2) any of the options ``names`` outside its range in CLI_LIMITS;
    an option left unset (None) is not checked."""
    for name in names:
        value: Any = getattr(args, name, None)
        if value is None:
            continue
        low, high, unit = CLI_LIMITS[name]
        if not (math.isfinite(value) and low <= value <= high):
            option = "--" + name.replace("_", "-")
            unit_text = f" {unit}" if unit else ""
            raise CliError(f"{option} must be in [{low:g}, {high:g}]{unit_text}, got {value:g}")


def add_overwrite_option(parser: argparse.ArgumentParser) -> None:
    """``--overwrite``: replace an output folder that already holds an earlier result."""
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace --out if it already holds files (as a whole, when the new result is "
        "complete); without it such a folder is refused",
    )


def check_output(path: Path, *, kind: str = "folder", overwrite: bool = False) -> Path:
    """:func:`multi_robot_mapper.io.outputs.check_output` with its error as a CLI error."""
    from multi_robot_mapper.io.outputs import OutputError
    from multi_robot_mapper.io.outputs import check_output as check

    try:
        return check(path, kind=kind, overwrite=overwrite)
    except OutputError as exc:
        raise CliError(str(exc)) from exc


def add_config_options(parser: argparse.ArgumentParser, merging: bool = False) -> None:
    """``--config YAML`` and repeatable ``--set NAME=VALUE`` (same names as ROS parameters);
    with ``merging`` also ``--merger-config YAML``."""
    parser.add_argument(
        "--config",
        type=Path,
        metavar="YAML",
        help="the robot mapper's parameters, as config/robot_mapper.yaml (default: the "
        "built-in defaults, which that file holds)",
    )
    if merging:
        parser.add_argument(
            "--merger-config",
            type=Path,
            metavar="YAML",
            help="the merging parameters, as config/map_merger.yaml; its merge.* section is used "
            "(default: the built-in defaults, which that file holds)",
        )
    merge_example = " or --set merge.pairwise.link_min_value=20" if merging else ""
    add_set_option(
        parser,
        "override one parameter, e.g. --set extraction.split_tolerance=0.03"
        f"{merge_example} (repeatable)",
    )


def add_set_option(parser: argparse.ArgumentParser, help_text: str) -> None:
    """``--set NAME=VALUE`` (repeatable), collected in ``args.overrides`` (read them with
    :func:`~multi_robot_mapper.core.config.parse_override`); the CLI and the benches share it."""
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help=help_text + " (default: none)",
    )


def load_mapper_config(args: argparse.Namespace) -> RobotMapperConfig:
    """The robot mapper's configuration from the options above (defaults, YAML, overrides)."""
    from multi_robot_mapper.io.config_files import load_config

    overrides = [o for o in args.overrides if not o.strip().startswith(MERGER_PREFIX)]
    return load_config(RobotMapperConfig, args.config, overrides, node_name="robot_mapper")


def load_merger_config(args: argparse.Namespace) -> MapMergerConfig:
    """The map merger's configuration (``--merger-config`` and the ``--set merge.*``
    overrides); ``.merge`` is what ``mrm replay --method pivot`` merges with."""
    from multi_robot_mapper.io.config_files import load_config

    overrides = [o for o in args.overrides if o.strip().startswith(MERGER_PREFIX)]
    path = getattr(args, "merger_config", None)
    return load_config(MapMergerConfig, path, overrides, node_name="map_merger")
