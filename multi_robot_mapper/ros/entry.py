"""The console entry points' common life cycle: init, build the nodes, spin, shut down."""

from __future__ import annotations

import contextlib
import faulthandler
import io
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor

import rclpy
from rclpy import signals
from rclpy._rclpy_pybind11 import RCLError
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
    if hasattr(signal, "SIGUSR1"):
        # `kill -USR1 <pid>` prints every thread's stack to stderr: where a node that does not
        # answer (or does not stop) is stuck, without stopping it. Not where stderr is no file
        # (called in-process under a test runner's capture).
        with contextlib.suppress(io.UnsupportedOperation, ValueError, AttributeError):
            faulthandler.register(signal.SIGUSR1, all_threads=True)
    with _sigint_as_shutdown() as sigint:
        rclpy.init(args=args)
        sigint.armed = True
        return _spin(program, make_nodes, make_executor)


def run_node(
    program: str,
    make_node: Callable[[], Node],
    args: list[str] | None = None,
    make_executor: Callable[[], Executor] = SingleThreadedExecutor,
) -> int:
    """:func:`run_nodes` for one node (``ros2 run multi_robot_mapper <node>``)."""
    return run_nodes(program, lambda: [make_node()], args, make_executor)


def _spin(
    program: str, make_nodes: Callable[[], Sequence[Node]], make_executor: Callable[[], Executor]
) -> int:
    # Made before the nodes, as soon as the context is: a signal shuts the context down, and an
    # executor made after that fails half-built (and its __del__ prints a traceback).
    spinner = make_executor()
    nodes: list[Node] = []
    try:
        try:
            nodes = list(make_nodes())
        except ConfigError as exc:
            print(f"{program}: invalid parameters: {exc}", file=sys.stderr)
            return 2
        for node in nodes:
            spinner.add_node(node)
        spinner.spin()
    except BaseException as exc:
        # Ctrl-C or SIGTERM, while the nodes spin or while they are still being built (a
        # launcher stopping them early), is a normal shutdown.
        if not _shutdown_requested(exc):
            raise
        _await_signal_shutdown()
    finally:
        spinner.shutdown()
        _finish_callbacks(spinner)
        for node in reversed(nodes):
            node.destroy_node()
        _try_shutdown()
    return 0


def _try_shutdown() -> None:
    """``rclpy.try_shutdown``, from the main thread or the signal's: it checks the context and
    then shuts it down, not at once, so when both threads shut it down together the second
    finds it shut down already (``RCLError: rcl_shutdown already called``, a fresh-clone
    ``mrm run`` test under load): that is the shutdown asked for, no error."""
    try:
        rclpy.try_shutdown()
    except RCLError:
        if rclpy.ok():
            raise


class _SigintAsShutdown:
    """A Python SIGINT handler under rclpy's. rclpy's own handler (installed over it by
    ``rclpy.init``, and calling it after) shuts the context down, which ends the spin as
    SIGTERM does. Python's default handler would also raise KeyboardInterrupt wherever the main
    thread is, even inside a ``__del__`` that the garbage collector runs, where it is printed as
    "Exception ignored ... KeyboardInterrupt" with a traceback (a robot_mapper on SIGINT, a
    fresh-clone test). So once rclpy is up (``armed``) the first Ctrl-C raises nothing and asks
    for the same shutdown rclpy's handler does (from a thread, as rclpy does: the main thread
    may be inside rclpy); before that, and at a second Ctrl-C (a shutdown that hangs), it
    raises as Python's does."""

    def __init__(self) -> None:
        self.armed = False
        self.received = 0

    def __call__(self, signum: int, frame: object) -> None:
        self.received += 1
        if not self.armed or self.received > 1:
            raise KeyboardInterrupt
        threading.Thread(target=_try_shutdown, name="sigint-shutdown", daemon=True).start()


@contextlib.contextmanager
def _sigint_as_shutdown() -> Iterator[_SigintAsShutdown]:
    """:class:`_SigintAsShutdown` as the SIGINT handler while the nodes run (the main thread
    only: signals are set there), the handler before it restored after.

    rclpy's handlers are taken out first and after: ``rclpy.try_shutdown`` leaves them
    installed, and a later ``rclpy.init`` then does not install them again, so a handler set
    from Python in between would replace rclpy's at the OS level, and nothing would wake the
    executor's wait (an earlier ``run_nodes`` in the same process: a test's). Taken out, the
    ``rclpy.init`` inside installs them over this one."""
    handler = _SigintAsShutdown()
    if threading.current_thread() is not threading.main_thread():
        yield handler
        return
    signals.uninstall_signal_handlers()
    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield handler
    finally:
        signals.uninstall_signal_handlers()
        # None: the handler before was not set from Python; Python's default stands for it.
        signal.signal(signal.SIGINT, signal.default_int_handler if previous is None else previous)


def _shutdown_requested(exc: BaseException) -> bool:
    """Whether ``exc`` is how a shutdown request (Ctrl-C, SIGTERM) reached the main thread.

    On SIGINT Python raises KeyboardInterrupt wherever the main thread is. On SIGTERM (and on
    SIGINT too) rclpy's signal thread shuts the context down, so whatever the main thread does
    next with it fails: spin() raises ExternalShutdownException, or, when the signal lands
    while spin() builds its wait set or while a node is still being built, an RCLError
    ("context is invalid"). Any error once the context is no longer valid is that shutdown;
    an error while it is still valid is a real one."""
    if isinstance(exc, (KeyboardInterrupt, ExternalShutdownException)):
        return True
    return isinstance(exc, Exception) and not rclpy.ok()


def _await_signal_shutdown(timeout: float = 2.0) -> None:
    """After Ctrl-C, wait (bounded) for rclpy's signal thread to finish shutting the context down
    before anything is torn down. On SIGINT Python raises KeyboardInterrupt in the main thread at
    once, while rclpy's own handler thread is still shutting the context down and waking the
    executors; tearing the executor and the nodes down under it crashed map_merger once (a
    segfault in a native thread; test_bad_scans_node, SIGINT after a merge, a loaded machine).
    Context.ok() takes the lock its shutdown holds, so once it is False that shutdown is over.
    Without rclpy's handlers (SignalHandlerOptions.NO) nobody shuts the context down: no wait."""
    if signals.get_current_signal_handlers_options() == signals.SignalHandlerOptions.NO:
        return
    deadline = time.monotonic() + timeout
    while rclpy.ok() and time.monotonic() < deadline:
        time.sleep(0.01)


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
