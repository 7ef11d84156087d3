"""What every ``mrm`` command shares: the user-error type and the configuration options."""

from __future__ import annotations

import argparse
from pathlib import Path

from multi_robot_mapper.core.mapper_config import RobotMapperConfig
from multi_robot_mapper.core.merger_config import MapMergerConfig

MERGER_PREFIX = "merge."  # --set names of the merging parameters (map_merger's merge.*)


class CliError(Exception):
    """A user error: printed as one line on stderr, exit code 2."""


def add_config_options(parser: argparse.ArgumentParser, merging: bool = False) -> None:
    """``--config YAML`` and repeatable ``--set NAME=VALUE`` (same names as ROS parameters);
    with ``merging`` also ``--merger-config YAML``."""
    parser.add_argument("--config", type=Path, help="YAML parameters (config/robot_mapper.yaml)")
    if merging:
        parser.add_argument(
            "--merger-config",
            type=Path,
            help="YAML merging parameters (config/map_merger.yaml; its merge.* section is used)",
        )
    merge_example = " or --set merge.link_min_value=20" if merging else ""
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override one parameter, e.g. --set extraction.split_tolerance=0.03"
        f"{merge_example} (repeatable)",
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
