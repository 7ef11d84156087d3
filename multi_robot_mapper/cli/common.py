"""What every ``mrm`` command shares: the user-error type and the configuration options."""

from __future__ import annotations

import argparse
from pathlib import Path

from multi_robot_mapper.core.mapper_config import RobotMapperConfig


class CliError(Exception):
    """A user error: printed as one line on stderr, exit code 2."""


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """``--config YAML`` and repeatable ``--set NAME=VALUE`` (same names as ROS parameters)."""
    parser.add_argument("--config", type=Path, help="YAML parameters (config/robot_mapper.yaml)")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override one parameter, e.g. --set extraction.split_tolerance=0.03 (repeatable)",
    )


def load_mapper_config(args: argparse.Namespace) -> RobotMapperConfig:
    """The robot mapper's configuration from the options above (defaults, YAML, overrides)."""
    from multi_robot_mapper.io.config_files import load_config

    return load_config(RobotMapperConfig, args.config, args.overrides, node_name="robot_mapper")
