"""The local mapper's back end as one object: the keyframe map and the loop closer, given one
keyframe at a time (:class:`Backend`), here or in a worker process (:class:`HostedBackend`).

Why a process: closing loops costs a keyframe hundreds of milliseconds of Python and numpy.
On a thread of the node's process it takes Python's interpreter lock from the scan callback
for as long (measured on freiburg-079: the scan callback's p95 45 ms with the back end on a
thread, README "Live"). In a worker process it runs on the other core, and the node's thread
that waits for it does not hold the lock.

A worker process is replaceable: it hosts one :class:`Backend`, built on the first keyframe.
The :class:`HostedBackend` keeps what it gave the worker (the scans are the front end's own
objects; the rest is a few numbers per keyframe), so a worker that died (killed, out of
memory) is replaced by one given every keyframe again, under the current settings: the graph
comes back as it was, and the keyframe that was in flight is not lost."""

from __future__ import annotations

import threading
import traceback
from collections.abc import Callable
from typing import Any, Protocol, cast

from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import Keyframe, KeyframeMap, KeyframeScan
from multi_robot_mapper.core.local_mapping.loop_closer import (
    BackendUpdate,
    Closure,
    LoopCloser,
    LostFrom,
)
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.pose_graph import Edge
from multi_robot_mapper.core.se2 import Pose

# What the front end gives the back end for one keyframe (LoopCloser.add_keyframe's arguments).
KeyframeJob = tuple[KeyframeScan, Pose, int, Edge | None, LostFrom | None]
# What one keyframe changed, and the keyframes it changed, rebuilt.
Changes = tuple[BackendUpdate, list[Keyframe]]


class Runner(Protocol):
    """Runs a module-level function in a worker process (``ros.worker_process.WorkerProcess``),
    re-raising what it raised; a worker that died raises something else and is replaced on
    the next call."""

    def run(self, function: Any, *args: object) -> Any: ...

    def run_with_state(self, function: Any, *args: object) -> Any:
        """``function(state, *args)``, ``state`` a dict the worker keeps between calls."""
        ...

    def shutdown(self) -> None: ...


class Backend:
    """The keyframe map and the loop closer of one robot."""

    def __init__(self, config: LocalMapperConfig) -> None:
        self.config = config
        self.map = KeyframeMap(
            pair_tolerance(config.integrate), config.fusion_tolerance, config.fusion_radius
        )
        self.closer = LoopCloser(config, self.map)

    def add_keyframe(self, job: KeyframeJob) -> Changes:
        """One keyframe into the graph: what it changed, and the keyframes it changed
        rebuilt, whole, as readers see them."""
        update = self.closer.add_keyframe(*job)
        return update, self.map.keyframes(self.map.take_changed())

    def reconfigure(self, config: LocalMapperConfig) -> None:
        """New settings from the next keyframe on; the graph and the map are kept."""
        self.config = config
        self.closer.config = config
        self.map.pair = pair_tolerance(config.integrate)
        self.map.tolerance, self.map.radius = config.fusion_tolerance, config.fusion_radius

    @property
    def closures(self) -> list[Closure]:
        """The loop closures and joins in the graph."""
        return list(self.closer.accepted.values())


class NotHostedError(RuntimeError):
    """The worker process hosts no back end yet (a new one, or one that replaced a dead one)."""


# The key of the back end a worker process hosts in its state (None in the node's process).
_HOSTED = "backend"


def _hosted_backend(state: dict[str, Any]) -> Backend:
    backend = state.get(_HOSTED)
    if backend is None:
        raise NotHostedError("this worker process hosts no back end")
    return cast(Backend, backend)


def _host(state: dict[str, Any], config: LocalMapperConfig, jobs: list[KeyframeJob]) -> Changes:
    """In the worker: a new back end, given ``jobs`` in order; their updates summed into one
    (a keyframe that fails, a bug, is skipped with its traceback, as on a thread), and every
    keyframe rebuilt."""
    state[_HOSTED] = backend = Backend(config)
    updates, errors = [], []
    for job in jobs:
        try:
            updates.append(backend.closer.add_keyframe(*job))
        except Exception:
            errors.append(traceback.format_exc())
    backend.map.take_changed()
    summed = _summed(updates)
    summed.errors.extend(errors)
    return summed, backend.map.keyframes()


def _hosted_add_keyframe(
    state: dict[str, Any], config: LocalMapperConfig, job: KeyframeJob
) -> Changes:
    backend = _hosted_backend(state)
    if config != backend.config:
        backend.reconfigure(config)
    return backend.add_keyframe(job)


def _hosted_closures(state: dict[str, Any]) -> list[Closure]:
    return _hosted_backend(state).closures


def _summed(updates: list[BackendUpdate]) -> BackendUpdate:
    """One update that changes what ``updates`` changed, applied in order."""
    moved: dict[int, Pose] = {}
    for update in updates:
        moved.update(update.moved)
    return BackendUpdate(
        moved=moved,
        joins=[join for update in updates for join in update.joins],
        closures=[closure for update in updates for closure in update.closures],
        local_edges=updates[-1].local_edges if updates else 0,
        seconds=sum(update.seconds for update in updates),
        optimise_seconds=sum(update.optimise_seconds for update in updates),
        errors=[error for update in updates for error in update.errors],
    )


class HostedBackend:
    """A :class:`Backend` in the worker process ``runner`` runs (module doc). Its methods wait
    for the worker (without the interpreter lock): call them from the back end's thread."""

    def __init__(self, config: LocalMapperConfig, runner: Runner) -> None:
        self.config = config
        self.runner = runner
        self._given: list[KeyframeJob] = []
        self.hosted = 0  # back ends hosted so far (more than one: a worker was replaced)

    def add_keyframe(self, job: KeyframeJob) -> Changes:
        """As :meth:`Backend.add_keyframe`. A new worker is given every keyframe so far."""
        self._given.append(job)
        try:
            return cast(Changes, self.runner.run_with_state(_hosted_add_keyframe, self.config, job))
        except NotHostedError:
            self.hosted += 1
            return cast(Changes, self.runner.run_with_state(_host, self.config, list(self._given)))

    def reconfigure(self, config: LocalMapperConfig) -> None:
        """New settings, sent with the next keyframe (this never waits for the worker)."""
        self.config = config

    @property
    def closures(self) -> list[Closure]:
        """The worker's closures (waits for the keyframe it is on)."""
        try:
            return cast(list[Closure], self.runner.run_with_state(_hosted_closures))
        except NotHostedError:
            return []

    def shutdown(self) -> None:
        """Stop the worker at once (a keyframe it is on is abandoned)."""
        self.runner.shutdown()


class BackendThread:
    """The back end on a thread of its own (what a node runs): ``step`` (the back end's next
    queued keyframe; False when none is queued) runs whenever the thread is woken, until
    none is left. A step that raises is reported to ``failed`` (its traceback) and the next
    keyframe is tried: a bug must not end the thread."""

    def __init__(self, step: Callable[[], bool], failed: Callable[[str], None]) -> None:
        self._step, self._failed = step, failed
        self._wake = threading.Event()  # keyframes queued
        self._stop = threading.Event()
        # daemon: never holds a process open at exit
        self._thread = threading.Thread(
            target=self._work, name="local-mapping-back-end", daemon=True
        )
        self._thread.start()
        self._wake.set()  # keyframes queued before it started

    def wake(self) -> None:
        """Keyframes are queued."""
        self._wake.set()

    def stop(self, timeout: float, interrupt: Callable[[], None] | None = None) -> None:
        """Stop after the step it is on (a thread left inside gtsam while the interpreter
        exits can crash the process); ``interrupt`` ends that step sooner (a worker
        process's back end shut down under it)."""
        self._stop.set()
        self._wake.set()
        if interrupt is not None:
            interrupt()
        self._thread.join(timeout)

    def _work(self) -> None:
        while not self._stop.is_set():
            self._wake.wait()
            self._wake.clear()
            try:
                while not self._stop.is_set() and self._step():
                    pass
            except Exception:
                if self._stop.is_set():
                    return  # a worker process shut down under the keyframe it was on
                self._failed(traceback.format_exc())
