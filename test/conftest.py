"""Shared fixtures: data paths, and isolated rclpy contexts for node tests.

Every test session runs on its own ROS domain (``ROS_DOMAIN_ID`` if the caller set one, else
one derived from the process id) with discovery limited to this machine, so parallel runs
never see each other's topics.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    import numpy as np

    from multi_robot_mapper.core.scan import LaserScanData

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
# Deprecated since Jazzy and in conflict with the discovery range above: never inherited.
os.environ.pop("ROS_LOCALHOST_ONLY", None)

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "carmen"
CARMEN_LOGS = ("intel", "aces", "fhw", "csail")


def carmen_log(name: str) -> Path:
    """Path of a shared CARMEN log; skips the test with the reason when it is absent."""
    path = DATA / f"{name}.log.gz"
    if not path.is_file():
        pytest.skip(f"real-data log {path} not found (../shared/data is not beside this clone)")
    return path


def spins_ros(item: pytest.Item) -> bool:
    """Whether a test starts ROS nodes: marked ``ros``, asks for ``ros_context``, or its module
    holds rclpy's names (an executor, a node, ``isolated_context``) for its fixtures to use."""
    if item.get_closest_marker("ros") or "ros_context" in getattr(item, "fixturenames", ()):
        return True
    names = vars(getattr(item, "module", None) or object).values()
    return any(
        str(getattr(value, "__module__", "")).startswith(
            ("rclpy", "multi_robot_mapper.ros.testing")
        )
        for value in names
    )


@pytest.hookimpl(tryfirst=True)  # before ``-m`` selects by the markers
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test that starts ROS nodes is marked ``ros``: ``make test`` runs them in one
    pytest (``-m ros``, in order, on this run's domain) and the rest in another beside it."""
    for item in items:
        if spins_ros(item):
            item.add_marker(pytest.mark.ros)


@pytest.fixture
def ros_context() -> Iterator[object]:
    """A fresh rclpy context on this run's isolated domain, shut down after the test."""
    from multi_robot_mapper.ros.testing import isolated_context

    with isolated_context() as context:
        yield context


@pytest.fixture
def mrm() -> object:
    """The real ``mrm`` entry point: ``mrm([...args])`` returns the exit code."""
    from multi_robot_mapper.cli.main import main

    return main


@pytest.fixture(scope="module")
def office_drive() -> tuple[np.ndarray, list[LaserScanData], np.ndarray]:
    """4 s of a simulated UTM-30LX at 40 Hz driving through the office world (stamps, scans,
    T_world_laser), for the local-mapping tests."""
    from multi_robot_mapper.core.simulation import LaserModel, simulate_robots

    run = simulate_robots("office", 1, LaserModel(), seed=1, duration=4.0)[0]
    return run.stamps, run.scans, run.T_world_laser
