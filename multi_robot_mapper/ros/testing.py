"""Running nodes in-process without launch files: isolated contexts and bounded spinning.

Used by this package's tests and ``mrm demo``, and meant for users' own tests::

    with isolated_context() as context:
        node = RobotMapper(context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        assert spin_until(executor, lambda: received, timeout=5.0)
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor


def default_domain_id() -> int:
    """``ROS_DOMAIN_ID`` if set, else a domain derived from the process id (1..100)."""
    value = os.environ.get("ROS_DOMAIN_ID", "")
    return int(value) if value.isdigit() else 1 + os.getpid() % 100


@contextmanager
def isolated_context(domain_id: int | None = None) -> Iterator[Context]:
    """A fresh, initialised rclpy context on its own DDS domain, shut down on exit."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(context=context, domain_id=default_domain_id() if domain_id is None else domain_id)
    try:
        yield context
    finally:
        context.try_shutdown()


def spin_until(
    executor: Executor, condition: Callable[[], bool], timeout: float, step: float = 0.01
) -> bool:
    """Spin ``executor`` until ``condition()`` holds (True) or ``timeout`` seconds pass (False)."""
    deadline = time.monotonic() + timeout
    while True:
        if condition():
            return True
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            return False
        executor.spin_once(timeout_sec=min(step, remaining))
