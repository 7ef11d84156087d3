"""The console entry points' common life cycle: init, build the nodes, spin, shut down."""

from __future__ import annotations

import faulthandler
import sys
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

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
    if not faulthandler.is_enabled():
        faulthandler.enable()  # a crash in native code names the Python threads it met
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
        _finish_callbacks(spinner)
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


def _finish_callbacks(spinner: Executor, timeout: float = 10.0) -> None:
    """Let callbacks still running on a MultiThreadedExecutor's threads end before their nodes
    are destroyed. Jazzy's ``MultiThreadedExecutor.shutdown`` leaves its thread pool running
    (later rclpy joins it there); a callback inside a node being destroyed, or still running as
    the interpreter exits, can crash the process. Bounded: a stuck callback does not hold the
    exit for ever."""
    pool = getattr(spinner, "_executor", None)
    if not isinstance(pool, ThreadPoolExecutor):
        return
    joiner = threading.Thread(target=pool.shutdown, kwargs={"wait": True}, daemon=True)
    joiner.start()
    joiner.join(timeout)
