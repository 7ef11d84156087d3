"""The console entry points' life cycle (``ros/entry.py``): Ctrl-C as a clean shutdown."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest
from rclpy.node import Node

from multi_robot_mapper.core.config import ConfigError
from multi_robot_mapper.ros.entry import run_nodes
from multi_robot_mapper.ros.testing import default_domain_id


@pytest.mark.ros
def test_ctrl_c_ends_the_spin_without_interrupting_the_main_thread(monkeypatch) -> None:
    # rclpy's SIGINT handler shuts the context down, which ends the spin. Python's own handler
    # would also raise KeyboardInterrupt wherever the main thread is: in a callback, or in a
    # __del__ the garbage collector runs (printed as "Exception ignored ... KeyboardInterrupt",
    # a traceback on a node's clean exit). Here the main thread spends most of its time in a
    # callback's sleep: no KeyboardInterrupt may reach it, and Ctrl-C still ends run_nodes with
    # 0 and the SIGINT handler it found.
    monkeypatch.setenv("ROS_DOMAIN_ID", str(default_domain_id()))
    before = signal.getsignal(signal.SIGINT)
    interrupted: list[str] = []

    def busy() -> None:
        try:
            time.sleep(0.05)
        except KeyboardInterrupt:
            interrupted.append("callback")

    def make_nodes() -> list[Node]:
        node = Node("ctrl_c_probe")
        node.create_timer(0.01, busy)
        threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT)).start()
        return [node]

    def invalid() -> list[Node]:
        raise ConfigError("a parameter out of range")

    # A run before it in the same process (as tests do) leaves rclpy's handlers installed.
    assert run_nodes("probe", invalid, ["probe"]) == 2
    # Should this Ctrl-C not end the spin, a second one (Python's way) ends the test.
    watchdog = threading.Timer(9.0, os.kill, (os.getpid(), signal.SIGINT))
    watchdog.start()
    started = time.monotonic()
    try:
        assert run_nodes("probe", make_nodes, ["probe"]) == 0
    finally:
        watchdog.cancel()
    assert time.monotonic() - started < 8.0
    assert interrupted == []
    assert signal.getsignal(signal.SIGINT) is before


def test_a_shutdown_the_other_thread_made_first_is_no_error(monkeypatch) -> None:
    # Ctrl-C: the signal's thread and the main thread (once the spin ends) both shut the
    # context down, and rclpy.try_shutdown checks, then shuts down: the second may find it
    # shut down already (RCLError, a traceback in a fresh-clone `mrm run` test). That is the
    # shutdown asked for; the same error while the context still runs is raised.
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError

    from multi_robot_mapper.ros import entry

    def already_shut(*_: object) -> None:
        raise RCLError("failed to shutdown: rcl_shutdown already called on the given context")

    monkeypatch.setattr(rclpy, "try_shutdown", already_shut)
    monkeypatch.setattr(rclpy, "ok", lambda *_: False)
    entry._try_shutdown()  # no error
    monkeypatch.setattr(rclpy, "ok", lambda *_: True)
    with pytest.raises(RCLError):
        entry._try_shutdown()
