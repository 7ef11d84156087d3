"""One worker process for a node's long numpy work (the merge), so that the node's own threads
keep Python's interpreter lock while it runs."""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import TypeVar

R = TypeVar("R")


class WorkerProcess:
    """Runs a module-level function in one spawned process, started on first use; a worker
    that died (killed, out of memory) is replaced on the next call."""

    def __init__(self) -> None:
        self._pool: ProcessPoolExecutor | None = None

    def run(self, function: Callable[..., R], *args: object) -> R:
        """``function(*args)`` in the worker; this thread waits without holding the lock."""
        if self._pool is None:
            # spawn, not fork: forking a process that runs DDS threads is unsafe.
            context = multiprocessing.get_context("spawn")
            self._pool = ProcessPoolExecutor(max_workers=1, mp_context=context)
        try:
            return self._pool.submit(function, *args).result()
        except BrokenProcessPool:
            self.shutdown()  # a new one next time
            raise

    def shutdown(self) -> None:
        """Stop the worker (a job it runs is abandoned)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
