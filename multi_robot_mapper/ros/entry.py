"""The console entry points' common life cycle: init, build the nodes, spin, shut down."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from multi_robot_mapper.core.config import ConfigError


def run_nodes(
    program: str,
    make_nodes: Callable[[], Sequence[Node]],
    args: list[str] | None = None,
    make_executor: Callable[[], Executor] = SingleThreadedExecutor,
) -> int:
    """Spin the nodes ``make_nodes`` builds, on one executor, until shutdown (Ctrl-C, SIGTERM);
    exit code 2 on invalid parameters. Nodes are destroyed in reverse order of creation."""
    rclpy.init(args=args)
    try:
        nodes = list(make_nodes())
    except ConfigError as exc:
        print(f"{program}: invalid parameters: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    spinner = make_executor()  # after init: an executor belongs to the initialised context
    for node in nodes:
        spinner.add_node(node)
    try:
        spinner.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # A SIGTERM can shut the context down while spin() builds its wait set (an rclpy race);
        # that is a normal shutdown. Anything while the context is still valid is a real error.
        if rclpy.ok():
            raise
    finally:
        spinner.shutdown()
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def run_node(
    program: str,
    make_node: Callable[[], Node],
    args: list[str] | None = None,
    make_executor: Callable[[], Executor] = SingleThreadedExecutor,
) -> int:
    """:func:`run_nodes` for one node (``ros2 run multi_robot_mapper <node>``)."""
    return run_nodes(program, lambda: [make_node()], args, make_executor)
