"""One worker process for a node's long numpy work (the merge, the local mapper's back end), so
that the node's own threads keep Python's interpreter lock while it runs."""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any, TypeVar, cast

R = TypeVar("R")


class WorkerDiedError(RuntimeError):
    """The worker process ended (killed, out of memory) before it answered."""


class WorkerClosedError(WorkerDiedError):
    """The worker was shut down (its node is being destroyed): no job runs any more. A caller
    that would try again, or fall back to other jobs, stops instead."""


def _end_with(parent: int, poll: float = 0.5) -> None:
    """End this process at once when ``parent`` is no longer its parent (it died). A node
    killed (SIGKILL, out of memory) cannot stop its worker, which would otherwise run its job
    to the end, minutes of a merge, beside the node started again in its place (a merger
    restarted mid-run, issue 50), and only then find its pipe closed."""
    while os.getppid() == parent:
        time.sleep(poll)
    os._exit(1)


def _serve(jobs: Connection, parent: int | None = None) -> None:
    """The worker's loop: a job ``(function, args, with_state)`` in, ``(True, result)`` or
    ``(False, exception)`` out, until the pipe closes. ``with_state``: the function gets the
    worker's own state first (a dict it may keep things in between jobs, e.g. the back end
    it hosts), a local of this loop, not a module global. ``parent``: the node's process id;
    the worker ends as soon as that process is gone."""
    # A terminal's Ctrl-C reaches every process of its group, this one too when its node runs
    # in the foreground (mrm run --in-process): it would interrupt the job with a traceback.
    # The node ends its worker itself (shutdown), and a dead node's worker ends below.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent is not None:
        threading.Thread(target=_end_with, args=(parent,), name="parent watch", daemon=True).start()
    state: dict[str, Any] = {}
    while True:
        try:
            function, args, with_state = jobs.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        try:
            result = function(state, *args) if with_state else function(*args)
            answer: tuple[bool, Any] = (True, result)
        except Exception as exc:  # the caller re-raises it
            answer = (False, exc)
        try:
            jobs.send(answer)
        except (OSError, ValueError):
            return


class WorkerProcess:
    """Runs module-level functions in one spawned process, started on first use; a worker that
    died is replaced on the next call. :meth:`shutdown` terminates it at once, for good: later
    calls raise :class:`WorkerClosedError` without starting a process (a node shutting down
    must not start a new interpreter and a new merge while Python waits for its threads).

    A plain process and pipe rather than ``concurrent.futures.ProcessPoolExecutor``: that pool
    cannot be stopped without waiting for the job it runs, and one shut down without waiting
    leaves an exit hook that writes to a closed pipe (``OSError: Bad file descriptor`` as the
    interpreter exits)."""

    def __init__(self, name: str = "worker") -> None:
        self.name = name  # the process's name, and what errors call it
        self._process: BaseProcess | None = None
        self._pipe: Connection | None = None
        self._lock = threading.Lock()  # one job at a time
        # Guards the process, the pipe and closed: a shutdown while a job starts the process
        # either comes first (the job is refused) or stops the process it started.
        self._state_lock = threading.Lock()
        self._closed = False

    def run(self, function: Callable[..., R], *args: object) -> R:
        """``function(*args)`` in the worker; this thread waits without holding the lock.
        Raises what the function raised, or :class:`WorkerDiedError`."""
        return self._call(function, args, False)

    def run_with_state(self, function: Callable[..., R], *args: object) -> R:
        """``function(state, *args)`` in the worker, ``state`` the worker's own dict, kept
        between jobs (empty in a new worker); as :meth:`run` otherwise."""
        return self._call(function, args, True)

    def _call(self, function: Callable[..., R], args: tuple[object, ...], with_state: bool) -> R:
        with self._lock:
            pipe = self._started()
            try:
                pipe.send((function, args, with_state))
                ok, value = pipe.recv()
            except (EOFError, OSError) as exc:
                self._stop()  # a new one next time
                if self._closed:
                    raise WorkerClosedError(f"the {self.name} was shut down mid-job") from exc
                raise WorkerDiedError(f"the {self.name} process ended before it answered") from exc
        if not ok:
            raise cast(BaseException, value)
        return cast(R, value)

    def _started(self) -> Connection:
        with self._state_lock:
            if self._closed:
                raise WorkerClosedError(f"the {self.name} is shut down")
            if self._process is not None and self._pipe is not None and self._process.is_alive():
                return self._pipe
            dead = self._process, self._pipe
            # spawn, not fork: forking a process that runs DDS threads is unsafe.
            context = multiprocessing.get_context("spawn")
            ours, theirs = context.Pipe()
            process = context.Process(
                target=_serve, args=(theirs, os.getpid()), name=self.name, daemon=True
            )
            process.start()
            theirs.close()  # the worker's end lives in the worker: its death closes ours
            self._process, self._pipe = process, ours
        _retire(*dead)
        return ours

    def shutdown(self) -> None:
        """Stop the worker at once and for good (a job it runs is abandoned; its caller, and
        every later one, gets :class:`WorkerClosedError`)."""
        with self._state_lock:
            self._closed = True
        self._stop()

    def _stop(self) -> None:
        with self._state_lock:
            process, pipe = self._process, self._pipe
            self._process = self._pipe = None
        _retire(process, pipe)


def _retire(process: BaseProcess | None, pipe: Connection | None) -> None:
    """End a worker process that is no longer used (terminated, killed if it lingers) and
    close its pipe."""
    if process is not None:
        if process.is_alive():
            process.terminate()
        process.join(5.0)
        if process.is_alive():
            process.kill()
            process.join()
    if pipe is not None:
        pipe.close()
