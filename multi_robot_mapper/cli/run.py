"""``mrm run --robots robot1,robot2,... [--method pivot|ffs] [--params-file FILE]...
[-p NAME:=VALUE]... [--use-sim-time]``: the whole system in one process, without launch files.

One ``robot_mapper`` per robot namespace (``/robot1/scan`` in, ``/robot1/partial_map`` out)
and one ``map_merger`` of exactly those robots (``/global_map``, ``/global_grid``,
``/robot_frames/<robot>``, ``/diagnostics``, the ``/save_map`` and ``/load_map``
services), spun on one multi-threaded executor, as a component container would. Parameters
come from ROS 2 params files (``config/multi_robot_mapper.yaml`` holds both nodes'), then
``-p`` (each to the nodes that have that parameter), then ``--method``. Runs until Ctrl-C or
SIGTERM; exit code 2 for invalid parameters.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from multi_robot_mapper.cli.common import CliError, missing_input
from multi_robot_mapper.ros.merger_config import METHODS


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "run",
        help="robot_mappers and a map_merger in one process (no launch files needed)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--robots",
        required=True,
        metavar="NAME,...",
        help="comma-separated robot namespaces, e.g. robot1,robot2",
    )
    parser.add_argument(
        "--method", choices=METHODS, default=None, help="merging method (default: the params')"
    )
    parser.add_argument(
        "--params-file",
        dest="params_files",
        action="append",
        default=[],
        type=Path,
        metavar="FILE",
        help="ROS 2 params file (repeatable), e.g. config/multi_robot_mapper.yaml (default: none, "
        "the nodes' built-in defaults)",
    )
    parser.add_argument(
        "-p",
        "--param",
        dest="params",
        action="append",
        default=[],
        metavar="NAME:=VALUE",
        help="a parameter, given to the nodes that have it (repeatable), e.g. "
        "-p max_scan_rate:=10 (robot_mapper), -p merge_period:=2.0 (map_merger) (default: none)",
    )
    parser.add_argument(
        "--use-sim-time",
        action="store_true",
        help="every node follows /clock (replaying a bag with its clock; default: the wall clock)",
    )
    parser.set_defaults(func=run)


def ros_arguments(args: argparse.Namespace) -> list[str]:
    """The ``--ros-args`` the options stand for (checked: the params files must exist)."""
    ros_args = ["mrm", "--ros-args"]
    for path in args.params_files:
        if not path.is_file():
            raise missing_input(path, "params file")
        ros_args += ["--params-file", str(path)]
    if args.use_sim_time:
        ros_args += ["-p", "use_sim_time:=true"]
    return ros_args


def node_parameters(items: list[str]) -> tuple[list[Any], list[Any]]:
    """``-p NAME:=VALUE`` options as the robot_mappers' and the merger's parameters: each goes
    to the nodes that have it (a name neither node has is an error, as ``ros2 run`` would
    ignore it without a word; a fixed constant is refused saying so)."""
    from rclpy.parameter import Parameter

    from multi_robot_mapper.core.config import (
        field_specs,
        fixed_message,
        parse_override,
        user_specs,
    )
    from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
    from multi_robot_mapper.ros.merger_config import MapMergerConfig

    kinds = {s.name: s.kind for c in (MapMergerConfig, RobotMapperConfig) for s in field_specs(c)}
    mapper_fields = {spec.name for spec in field_specs(RobotMapperConfig)}
    mapper_names = {spec.name for spec in user_specs(RobotMapperConfig)}
    merger_names = {spec.name for spec in user_specs(MapMergerConfig)} - {"robots", "method"}
    mapper, merger = [], []
    for item in items:
        if ":=" not in item:
            raise CliError(f"-p {item!r}: write NAME:=VALUE (as ros2 run's -p)")
        name, value = parse_override(item.replace(":=", "=", 1))
        if name not in mapper_names | merger_names:
            if name not in kinds or name in ("robots", "method"):
                raise CliError(f"-p {name}: neither robot_mapper nor map_merger has this parameter")
            node = "robot_mapper" if name in mapper_fields else "map_merger"
            raise CliError(f"-p {name}: {fixed_message([name], node)}")
        if kinds[name] is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)  # -p max_scan_rate:=10 means 10.0
        parameter = Parameter(name, value=value)
        if name in mapper_names:
            mapper.append(parameter)
        if name in merger_names:
            merger.append(parameter)
    return mapper, merger


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.core.config import ConfigError
    from multi_robot_mapper.ros.bringup import build_system, robot_names
    from multi_robot_mapper.ros.entry import run_nodes

    try:
        robots = robot_names(args.robots)
    except ConfigError as exc:
        raise CliError(str(exc)) from exc
    ros_args = ros_arguments(args)
    mapper_parameters, merger_parameters = node_parameters(args.params)
    executor_threads = len(robots) + 2

    def make_executor() -> Any:
        from rclpy.executors import MultiThreadedExecutor

        return MultiThreadedExecutor(num_threads=executor_threads)

    def make_nodes() -> Any:
        system = build_system(
            robots,
            args.method,
            mapper_parameters=mapper_parameters,
            merger_parameters=merger_parameters,
        )
        return system.nodes

    print(f"mrm run: {', '.join(robots)} and a map_merger; Ctrl-C stops", flush=True)
    return run_nodes("mrm run", make_nodes, ros_args, make_executor)
