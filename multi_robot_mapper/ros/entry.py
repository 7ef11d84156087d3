"""The console entry points' common life cycle: init, build the node, spin, shut down."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from multi_robot_mapper.core.config import ConfigError


def run_node(
    program: str,
    make_node: Callable[[], Node],
    args: list[str] | None = None,
    make_executor: Callable[[], Executor] = SingleThreadedExecutor,
) -> int:
    """Spin the node ``make_node`` builds until shutdown; exit code 2 on invalid parameters."""
    rclpy.init(args=args)
    try:
        node = make_node()
    except ConfigError as exc:
        print(f"{program}: invalid parameters: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    spinner = make_executor()  # after init: an executor belongs to the initialised context
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
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
