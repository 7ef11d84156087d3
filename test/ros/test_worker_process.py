"""The merge's worker process: answers, errors, a killed worker and a shutdown mid-job."""

from __future__ import annotations

import math
import os
import signal
import threading
import time

import pytest

from multi_robot_mapper.ros.worker_process import WorkerClosedError, WorkerProcess


def test_the_worker_answers_raises_and_outlives_a_kill() -> None:
    worker = WorkerProcess()
    try:
        assert worker.run(math.hypot, 3.0, 4.0) == 5.0
        with pytest.raises(ValueError):
            worker.run(math.sqrt, -1.0)  # the function's own error, re-raised here
        pid = worker.run(os.getpid)
        assert pid != os.getpid() and worker.run(os.getpid) == pid  # one process, reused
        os.kill(pid, signal.SIGKILL)
        time.sleep(0.2)
        assert worker.run(math.hypot, 6.0, 8.0) == 10.0  # a new worker
        assert worker.run(os.getpid) != pid
    finally:
        worker.shutdown()


def test_a_shutdown_abandons_the_job_and_the_caller_hears_it() -> None:
    worker = WorkerProcess()
    worker.run(os.getpid)  # started
    outcome: list[BaseException] = []

    def wait_long() -> None:
        try:
            worker.run(time.sleep, 60.0)
        except BaseException as exc:
            outcome.append(exc)

    waiter = threading.Thread(target=wait_long)
    waiter.start()
    time.sleep(0.5)
    started = time.monotonic()
    worker.shutdown()
    waiter.join(10.0)
    assert not waiter.is_alive() and time.monotonic() - started < 10.0
    assert len(outcome) == 1 and isinstance(outcome[0], WorkerClosedError)
    # For good: a later job (a merge falling back to another try as its node is destroyed)
    # is refused at once, without starting a new interpreter.
    started = time.monotonic()
    with pytest.raises(WorkerClosedError):
        worker.run(os.getpid)
    assert time.monotonic() - started < 0.5 and worker._process is None


PARENT = """
import os, sys, threading, time
from multi_robot_mapper.ros.worker_process import WorkerProcess
worker = WorkerProcess()
print(worker.run(os.getpid), flush=True)
threading.Thread(target=worker.run, args=(time.sleep, 120.0), daemon=True).start()
time.sleep(120)
"""


@pytest.mark.skipif(not hasattr(os, "getppid"), reason="needs os.getppid")
def test_a_worker_ends_with_its_killed_node_even_mid_job() -> None:
    """A node killed with SIGKILL (a merger restarted mid-run) cannot stop its worker: the
    worker sees its parent gone and ends within a second, not at the end of its job."""
    import subprocess
    import sys

    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True)
    assert parent.stdout is not None
    worker = int(parent.stdout.readline())
    time.sleep(0.5)  # the long job has started
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10.0
    while _alive(worker) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(worker), "the worker outlived its killed node"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return True  # no /proc: kill(0) said it lives
