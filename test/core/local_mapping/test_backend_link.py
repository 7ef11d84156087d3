"""The front end's link to its back end (core/local_mapping/backend_link.py): the back end
moves to a worker process only before the first keyframe."""

from __future__ import annotations

import pytest
import test_backend
from test_backend import _map

from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.ros.worker_process import WorkerProcess

drive = test_backend.drive  # the fixture: 60 s of the office tour


def test_the_back_end_moves_to_a_worker_only_before_the_first_keyframe(drive) -> None:  # type: ignore[no-untyped-def]
    stamps, scans = drive
    mapper = LocalMapper()
    _map(mapper, stamps[:3], scans[:3])
    worker = WorkerProcess("test back end")
    with pytest.raises(ValueError, match="before any keyframe"):
        mapper.start_worker(worker)
    worker.shutdown()
