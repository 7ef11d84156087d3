"""The front end's link to the back end (:mod:`.backend`): the keyframes it queues, handed to
the back end in line, on a thread of its own, or in a worker process, and what the back end
changed applied to the front end's copy of the map. :class:`~.mapper.LocalMapper` is one."""

from __future__ import annotations

import threading
from collections import deque

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.local_mapping.backend import (
    Backend,
    BackendThread,
    HostedBackend,
    Runner,
)
from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.joins import LostFrom
from multi_robot_mapper.core.local_mapping.keyframe_map import Keyframe, KeyframeScan
from multi_robot_mapper.core.local_mapping.loop_closer import BackendUpdate, Closure
from multi_robot_mapper.core.pose_graph import Edge
from multi_robot_mapper.core.se2 import Pose


class BackendLink:
    """The state the front end shares with its back end (set by :class:`~.mapper.LocalMapper`)
    and the hand-over itself."""

    config: LocalMapperConfig
    backend: Backend | HostedBackend
    version: int
    backend_seconds: deque[float]
    optimise_seconds: deque[float]
    backend_errors: int
    last_backend_error: str | None
    _queue: deque[tuple[KeyframeScan, Pose, int, Edge | None, LostFrom | None]]
    _poses: dict[int, Pose]
    _pieces: dict[int, int]
    _scans: dict[int, KeyframeScan]
    _lock: threading.Lock
    _worker: BackendThread | None
    _busy: bool
    _keyframes: list[Keyframe]

    def start_worker(self, runner: Runner | None = None) -> None:
        """Run the back end on a thread of its own from now on: :meth:`add_scan` only hands
        keyframes over and never waits for matching or the optimiser (what a node does; a
        replay runs it in line and is deterministic). With ``runner`` (a worker process:
        ``ros.worker_process.WorkerProcess``), the thread only waits while the back end
        works in that process (:mod:`.backend`); only before the first keyframe."""
        if self._worker is not None:
            return
        if runner is not None:
            if self._scans:
                raise ValueError("the back end moves to a worker process before any keyframe")
            self.backend = HostedBackend(self.config, runner)
        self._worker = BackendThread(lambda: bool(self.run_backend(limit=1)), self._failed)

    def stop_worker(self, timeout: float = 120.0) -> None:
        """Stop the back-end thread (the keyframe it is on is finished first: a thread left
        inside gtsam while the interpreter exits can crash the process)."""
        worker, self._worker = self._worker, None
        if worker is not None:
            backend = self.backend
            # no gtsam in a worker's host: the keyframe in flight there is abandoned
            worker.stop(timeout, backend.shutdown if isinstance(backend, HostedBackend) else None)

    def _failed(self, trace: str) -> None:
        """A back-end step on the worker thread failed (a bug; the next keyframe is tried)."""
        self.backend_errors += 1
        self.last_backend_error = trace

    # --- the back end -----------------------------------------------------------------------

    def run_backend(self, limit: int | None = None) -> list[BackendUpdate]:
        """Give the queued keyframes to the back end (at most ``limit``); apply what it
        changed. A node calls this on its own thread; it never holds the front end's lock
        while matching."""
        updates: list[BackendUpdate] = []
        while limit is None or len(updates) < limit:
            with self._lock:
                if not self._queue:
                    break
                scan, pose, piece, edge, lost_from = self._queue.popleft()
                self._busy = True
                # The front end may have moved the keyframe since (earlier closures).
                pose, piece = self._poses[scan.index], self._pieces[scan.index]
            try:
                update, fresh = self.backend.add_keyframe((scan, pose, piece, edge, lost_from))
            except Exception:
                with self._lock:
                    self._busy = False
                raise
            with self._lock:
                for keyframe in fresh:
                    if keyframe.index == len(self._keyframes):
                        self._keyframes.append(keyframe)
                    else:
                        self._keyframes[keyframe.index] = keyframe
                for moved, kept, _ in update.joins:
                    for key, of in self._pieces.items():
                        if of == moved:
                            self._pieces[key] = kept
                for key, moved_pose in update.moved.items():
                    self._poses[key] = moved_pose
                # Keyframes made after this one moved with their anchors.
                self._follow(update, scan.index)
                self.version += 1
                self._busy = False
            self.backend_seconds.append(update.seconds)
            self.optimise_seconds.append(update.optimise_seconds)
            self.backend_errors += len(update.errors)
            if update.errors:
                self.last_backend_error = update.errors[-1]
            updates.append(update)
        return updates

    def _follow(self, update: BackendUpdate, done: int) -> None:
        """Keyframes the back end has not taken yet follow their reference's move."""
        for scan, _, _, edge, _ in self._queue:
            if edge is None or edge.first > done:
                continue
            self._poses[scan.index] = se2.compose(self._poses[edge.first], edge.T_first_second)
            self._pieces[scan.index] = self._pieces[edge.first]

    def keyframes(self) -> list[Keyframe]:
        """Every keyframe the back end has taken, with the map segments it owns, as of its
        last update (safe to call from any thread while the back end works)."""
        with self._lock:
            return list(self._keyframes)

    @property
    def closures(self) -> list[Closure]:
        """The loop closures and joins in the graph (from a worker process: after the
        keyframe it is on)."""
        return self.backend.closures

    @property
    def idle(self) -> bool:
        """No keyframe waits for the back end and none is being worked on."""
        with self._lock:
            return not self._queue and not self._busy
