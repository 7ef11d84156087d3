"""``mrm run --robots robot1,robot2,... [--method pivot|ffs] [--params-file FILE]...
[-p NAME:=VALUE]... [--use-sim-time] [--in-process]``: the whole system without launch files.

One ``robot_mapper`` per robot namespace (``/robot1/scan`` in, ``/robot1/partial_map`` out)
and one ``map_merger`` of exactly those robots (``/global_map``, ``/global_grid``,
``/robot_frames/<robot>``, ``/diagnostics``, the ``/save_map`` and ``/load_map``
services). By default each node is a process of its own on the caller's ``ROS_DOMAIN_ID``
(ros/processes.py), talking over DDS as robots on a network do, so that each robot's scans
are processed on a core of their own rather than under one interpreter lock; their output is
this command's. ``--in-process`` spins them all on one multi-threaded executor in this
process instead, as a component container would. Parameters come from ROS 2 params files
(``config/multi_robot_mapper.yaml`` holds both nodes'), then ``-p`` (each to the nodes that
have that parameter), then ``--method``. Runs until Ctrl-C or SIGTERM (every node process
then gets one SIGINT); exit code 2 for invalid parameters, 1 when a node process ends on its
own or does not stop cleanly.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from multi_robot_mapper.cli.common import CliError, missing_input
from multi_robot_mapper.ros.merger_config import METHODS


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "run",
        help="a robot_mapper process per robot and a map_merger process (no launch files needed)",
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
    parser.add_argument(
        "--in-process",
        action="store_true",
        help="every node in this one process, on one executor (default: a process per node)",
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
    from multi_robot_mapper.ros.bringup import robot_names

    try:
        robots = robot_names(args.robots)
    except ConfigError as exc:
        raise CliError(str(exc)) from exc
    ros_args = ros_arguments(args)
    mapper_parameters, merger_parameters = node_parameters(args.params)
    if args.in_process:
        return _run_in_process(args, robots, ros_args, mapper_parameters, merger_parameters)
    merger_parameters = [*_fixed_merger_parameters(robots, args.method), *merger_parameters]
    commands = node_commands(robots, ros_args[2:], mapper_parameters, merger_parameters)
    return run_processes(commands)


def _run_in_process(
    args: argparse.Namespace,
    robots: list[str],
    ros_args: list[str],
    mapper_parameters: list[Any],
    merger_parameters: list[Any],
) -> int:
    from multi_robot_mapper.ros.bringup import build_system
    from multi_robot_mapper.ros.entry import run_nodes

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

    print(f"mrm run: {', '.join(robots)} and a map_merger in one process; Ctrl-C stops", flush=True)
    return run_nodes("mrm run", make_nodes, ros_args, make_executor)


def _fixed_merger_parameters(robots: list[str], method: str | None) -> list[Any]:
    """The merger's robots (exactly these) and ``--method`` when given: what
    :func:`~multi_robot_mapper.ros.bringup.build_system` sets in-process."""
    from rclpy.parameter import Parameter

    fixed = [Parameter("robots", value=",".join(robots))]
    if method is not None:
        fixed.append(Parameter("method", value=method))
    return fixed


def parameter_arguments(parameters: Sequence[Any]) -> list[str]:
    """rclpy Parameters as ``-p NAME:=VALUE`` arguments that give each its own type back (a
    float stays a float: ``10.0``, not ``10``; a string is quoted, so ``"1"`` stays a
    string)."""
    arguments = []
    for parameter in parameters:
        value = parameter.value
        text = repr(value) if isinstance(value, float) else json.dumps(value)
        arguments += ["-p", f"{parameter.name}:={text}"]
    return arguments


def node_commands(
    robots: list[str],
    shared_args: list[str],
    mapper_parameters: Sequence[Any],
    merger_parameters: Sequence[Any],
) -> dict[str, list[str]]:
    """The command of each node process: ``robots``' mappers, then ``map_merger``.
    ``shared_args`` (params files, ``use_sim_time``) go to every node, then each node's own
    ``-p`` (after them, so that they win, as in-process)."""
    from multi_robot_mapper.ros.processes import map_merger_command, robot_mapper_command

    mapper_args = [*shared_args, *parameter_arguments(mapper_parameters)]
    commands = {robot: robot_mapper_command(robot, mapper_args) for robot in robots}
    commands["map_merger"] = map_merger_command(
        [*shared_args, *parameter_arguments(merger_parameters)]
    )
    return commands


def run_processes(commands: dict[str, list[str]]) -> int:
    """Start the node processes and wait for Ctrl-C or SIGTERM (0 once every node stopped
    cleanly) or for a node to end on its own (the others are stopped; 2 when it refused its
    parameters, else 1)."""
    from multi_robot_mapper.ros.processes import NodeProcesses

    stop = threading.Event()
    with _stop_on_signals(stop):
        nodes = NodeProcesses(commands, None, inherit_output=True)
        try:
            robots = [name for name in commands if name != "map_merger"]
            print(
                f"mrm run: {', '.join(robots)} and a map_merger, a process each; Ctrl-C stops",
                flush=True,
            )
            ended = nodes.first_exit(stop)
        finally:
            codes = nodes.stop()
    if ended is not None:
        code = codes[ended]
        print(f"mrm run: {ended} ended with exit code {code}; stopped the others", file=sys.stderr)
        return 2 if code == 2 else 1
    failed = {name: code for name, code in codes.items() if code != 0}
    if failed:
        print(f"mrm run: not stopped cleanly (exit codes): {failed}", file=sys.stderr)
        return 1
    return 0


@contextmanager
def _stop_on_signals(stop: threading.Event) -> Iterator[None]:
    """SIGINT and SIGTERM set ``stop`` (the node processes are then stopped, each with one
    SIGINT) instead of ending this process at once; the handlers before are restored after.
    Only the main thread can set handlers: elsewhere the signals act as usual."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    signals = (signal.SIGINT, signal.SIGTERM)
    previous = {number: signal.getsignal(number) for number in signals}
    for number in signals:
        signal.signal(number, lambda *_: stop.set())
    try:
        yield
    finally:
        for number, handler in previous.items():
            # None: a handler not set from Python; the default stands for it.
            signal.signal(number, signal.SIG_DFL if handler is None else handler)
