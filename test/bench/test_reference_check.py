"""The benches' judge of wrong closures and links (bench/reference_check.py): a reference wrong
at one scan, or over a stretch of up to three, is found by the scans either side, and only there."""

from __future__ import annotations

import dataclasses
import importlib
from types import ModuleType

import numpy as np
import pytest

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.simulation import LaserModel, simulate_robots
from multi_robot_mapper.io.bags import RobotRecording, recording_of

# Every 10th scan of a 40 Hz drive: about 0.2 m apart, as the dense real log.
STRIDE = 10
MIDDLE = 2  # the scan whose reference is made wrong, in units of STRIDE


@pytest.fixture(scope="module")
def reference_check() -> ModuleType:
    return importlib.import_module("bench.reference_check")


@pytest.fixture(scope="module")
def drive() -> RobotRecording:
    run = simulate_robots("office", 1, LaserModel(), seed=3, duration=3.0)[0]
    recording = recording_of("robot1", run)
    recording.scans = recording.scans[::STRIDE]
    recording.ground_truth = recording.ground_truth[::STRIDE]
    return recording


def _turned(recording: RobotRecording, index: int, angle: float) -> RobotRecording:
    """The recording with the reference of scan ``index`` turned by ``angle`` (a glitch)."""
    truth = list(recording.ground_truth)
    x, y, theta = truth[index].pose
    truth[index] = dataclasses.replace(truth[index], pose=(x, y, theta + angle))
    return dataclasses.replace(recording, ground_truth=truth)


def test_the_scans_either_side_find_a_turned_reference_and_where_the_scan_is(
    reference_check: ModuleType, drive: RobotRecording
) -> None:
    trio = tuple(drive.scans[i].scan for i in (MIDDLE - 1, MIDDLE, MIDDLE + 1))
    truth = [drive.ground_truth[i].pose for i in (MIDDLE - 1, MIDDLE, MIDDLE + 1)]
    assert reference_check.pose_by_neighbours(trio, tuple(truth)) is None
    x, y, theta = truth[1]
    glitch = (truth[0], (x, y, theta + np.radians(15.0)), truth[2])
    found = reference_check.pose_by_neighbours(trio, glitch)
    assert found is not None
    dx, dy, dtheta = se2.between(truth[1], found)
    assert np.hypot(dx, dy) < 0.05 and abs(dtheta) < np.radians(1.0)


def test_where_the_reference_is_right_it_is_the_judge(
    reference_check: ModuleType, drive: RobotRecording
) -> None:
    # The reference is wrong at one scan only; between two others it judges alone, with no
    # second look.
    judge = reference_check.ReferenceJudge({"robot1": _turned(drive, MIDDLE, np.radians(15.0))})
    first, after = drive.ground_truth[0], drive.ground_truth[MIDDLE + 2]
    motion = se2.between(first.pose, after.pose)
    assert judge.verdict("robot1", first.stamp, "robot1", after.stamp, motion) == "right"
    turned = (motion[0], motion[1], motion[2] + np.radians(15.0))
    assert judge.verdict("robot1", first.stamp, "robot1", after.stamp, turned) == "wrong"


@pytest.mark.parametrize(("length", "angle"), [(1, 15.0), (2, 12.0), (3, 12.0)])
def test_a_match_wrong_only_by_turned_references_is_told_apart(
    reference_check: ModuleType, drive: RobotRecording, length: int, angle: float
) -> None:
    # The reference of ``length`` consecutive scans turned together (csail: scans 42 and 364
    # alone, robot4 of 4's scans 93-95 together, 11-12 deg): a match right by the scans is
    # wrong by the reference, and the scans either side of the stretch tell it apart; a match
    # wrong by the scans stays wrong.
    stretch = range(MIDDLE, MIDDLE + length)
    turned = drive
    for index in stretch:
        turned = _turned(turned, index, np.radians(angle))
    judge = reference_check.ReferenceJudge({"robot1": turned})
    first = drive.ground_truth[0]
    for index in stretch:
        scan = drive.ground_truth[index]
        true_motion = se2.between(first.pose, scan.pose)
        assert judge.verdict("robot1", first.stamp, "robot1", scan.stamp, true_motion) == (
            "reference"
        )
        x, y, theta = true_motion
        wrong_motion = (x + 0.5, y, theta)
        assert judge.verdict("robot1", first.stamp, "robot1", scan.stamp, wrong_motion) == "wrong"
