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
