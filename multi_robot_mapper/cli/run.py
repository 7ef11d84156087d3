"""``mrm run --robots robot1,robot2,... [--method pivot|ffs] [--params-file FILE]...
[-p NAME:=VALUE]... [--use-sim-time]``: the whole system in one process, without launch files.

One ``robot_mapper`` per robot namespace (``/robot1/scan`` in, ``/robot1/partial_map`` out)
and one ``map_merger`` of exactly those robots (``/global_map``, ``/global_grid``,
``/robot_frames/<robot>``, ``/diagnostics``, the ``/save_map`` and ``/load_map``
services), spun on one multi-threaded executor, as a component container would. Parameters
come from ROS 2 params files (``config/multi_robot_mapper.yaml`` holds both nodes'), then
from ``--method``. Runs until Ctrl-C or SIGTERM; exit code 2 for invalid parameters.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from multi_robot_mapper.cli.common import CliError
from multi_robot_mapper.core.merger_config import METHODS


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "run",
        help="robot_mappers and a map_merger in one process (no launch files needed)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--robots", required=True, help="comma-separated robot namespaces, e.g. robot1,robot2"
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
        help="ROS 2 params file (repeatable), e.g. config/multi_robot_mapper.yaml",
    )
    parser.add_argument(
        "-p",
        "--param",
        dest="params",
        action="append",
        default=[],
        metavar="NAME:=VALUE",
        help="a parameter for every node that has it (repeatable), e.g. -p max_scan_rate:=10",
    )
    parser.add_argument(
        "--use-sim-time",
        action="store_true",
        help="every node follows /clock (replaying a bag with its clock)",
    )
    parser.set_defaults(func=run)


def ros_arguments(args: argparse.Namespace) -> list[str]:
    """The ``--ros-args`` the options stand for (checked: the params files must exist)."""
    ros_args = ["mrm", "--ros-args"]
    for path in args.params_files:
        if not path.is_file():
            raise CliError(f"no such params file: {path}")
        ros_args += ["--params-file", str(path)]
    for item in args.params:
        if ":=" not in item:
            raise CliError(f"-p {item!r}: write NAME:=VALUE (as ros2 run's -p)")
        ros_args += ["-p", item]
    if args.use_sim_time:
        ros_args += ["-p", "use_sim_time:=true"]
    return ros_args


def run(args: argparse.Namespace) -> int:
    from multi_robot_mapper.core.config import ConfigError
    from multi_robot_mapper.ros.bringup import build_system, robot_names
    from multi_robot_mapper.ros.entry import run_nodes

    try:
        robots = robot_names(args.robots)
    except ConfigError as exc:
        raise CliError(str(exc)) from exc
    ros_args = ros_arguments(args)
    executor_threads = len(robots) + 2

    def make_executor() -> Any:
        from rclpy.executors import MultiThreadedExecutor

        return MultiThreadedExecutor(num_threads=executor_threads)

    print(f"mrm run: {', '.join(robots)} and a map_merger; Ctrl-C stops", flush=True)
    return run_nodes(
        "mrm run",
        lambda: build_system(robots, args.method).nodes,
        ros_args,
        make_executor,
    )
