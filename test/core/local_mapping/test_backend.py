"""The local mapper's back end in a worker process (core/local_mapping/backend.py): the same
graph as in line, a worker killed mid-drive replaced with nothing lost, and a stop that does
not wait for the keyframe in flight."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.core.local_mapping.backend import HostedBackend
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import LaserModel, simulate_robots
from multi_robot_mapper.ros.worker_process import WorkerProcess

EXTRACTION = ExtractionConfig()


@pytest.fixture(scope="module")
def drive() -> tuple[np.ndarray, list[LaserScanData]]:
    """60 s of the office tour at 5 Hz (361 beams): about 80 keyframes, local edges and loop
    closures."""
    run = simulate_robots("office", 1, LaserModel(rate=5.0, beams=361), seed=3, duration=60.0)[0]
    return run.stamps, run.scans


@pytest.fixture(scope="module")
def inline(drive) -> LocalMapper:  # type: ignore[no-untyped-def]
    """The drive mapped with the back end in line."""
    mapper = LocalMapper()
    _map(mapper, *drive)
    return mapper


def _map(
    mapper: LocalMapper, stamps: np.ndarray, scans: list[LaserScanData], kill_at: int = -1
) -> None:
    """Every scan, each after the back end finished the keyframes before it (deterministic,
    as in line); the worker process is killed before scan ``kill_at``."""
    for k, (stamp, scan) in enumerate(zip(stamps, scans, strict=True)):
        if k == kill_at:
            backend = mapper.backend
            assert isinstance(backend, HostedBackend)
            os.kill(backend.runner.run(os.getpid), signal.SIGKILL)
        mapper.add_scan(float(stamp), extract_scan(scan, EXTRACTION)[0], scan)
        deadline = time.monotonic() + 60.0
        while not mapper.idle and time.monotonic() < deadline:
            time.sleep(0.002)


def _poses(mapper: LocalMapper) -> np.ndarray:
    return np.array([kf.T_robotmap_keyframe for kf in mapper.keyframes()])


def test_the_graph_in_a_worker_process_is_the_graph_in_line(drive, inline) -> None:  # type: ignore[no-untyped-def]
    stamps, scans = drive
    hosted = LocalMapper(backend=False)
    hosted.start_worker(WorkerProcess("test back end"))
    try:
        _map(hosted, stamps, scans)
        assert hosted.backend_errors == 0
        assert len(hosted.keyframes()) == len(inline.keyframes()) > 10
        # The same map: the replacement rebuilds the graph from every keyframe, and where the
        # kill falls decides how ISAM2's updates are batched, which moves poses by float
        # rounding (3.9e-8 m measured once under load); a micrometre is far below any error.
        np.testing.assert_allclose(_poses(hosted), _poses(inline), atol=1e-6)
        assert len(hosted.closures) == len(inline.closures) > 0
        np.testing.assert_allclose(hosted.map_segments, inline.map_segments, atol=1e-9)
    finally:
        hosted.stop_worker()


def test_a_killed_worker_is_replaced_and_given_every_keyframe_again(drive, inline) -> None:  # type: ignore[no-untyped-def]
    stamps, scans = drive
    hosted = LocalMapper(backend=False)
    hosted.start_worker(WorkerProcess("test back end"))
    try:
        _map(hosted, stamps, scans, kill_at=len(scans) // 2)
        backend = hosted.backend
        assert isinstance(backend, HostedBackend) and backend.hosted == 2
        # the keyframe in flight when it died, if any, was lost once and given again
        assert hosted.backend_errors <= 1
        np.testing.assert_allclose(_poses(hosted), _poses(inline), atol=1e-9)
    finally:
        hosted.stop_worker()


def test_a_stop_does_not_wait_for_the_keyframe_in_the_worker(drive) -> None:  # type: ignore[no-untyped-def]
    stamps, scans = drive
    mapper = LocalMapper(backend=False)
    worker = WorkerProcess("test back end")
    mapper.start_worker(worker)
    worker.run(os.getpid)  # started
    for stamp, scan in zip(stamps[:40], scans[:40], strict=True):
        mapper.add_scan(float(stamp), extract_scan(scan, EXTRACTION)[0], scan)
    started = time.monotonic()
    mapper.stop_worker(timeout=30.0)
    assert time.monotonic() - started < 10.0
    assert mapper.backend_errors == 0  # the abandoned keyframe is no error
