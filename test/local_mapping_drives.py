"""Simulated drives and fakes shared by the local-mapping tests (test/core/local_mapping:
`test_mapper.py` and `test_attempts.py`, the front end; `test_loop_closer.py`, `test_joins.py`
and `test_windows.py`, the back end)."""

from __future__ import annotations

import dataclasses

import numpy as np

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.local_mapping import LocalMapper, LocalUpdate
from multi_robot_mapper.core.matching import MatchResult, integrate
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.simulation import LaserModel, drive_path, route_section, simulate_scan
from multi_robot_mapper.core.worlds import ROUTES, WORLDS, box

EXTRACTION = ExtractionConfig()


def feed(mapper: LocalMapper, stamp: float, scan: LaserScanData) -> LocalUpdate:
    segments, _ = extract_scan(scan, EXTRACTION)
    return mapper.add_scan(stamp, segments, scan)


def mapped(stamps: np.ndarray, scans: list[LaserScanData]) -> LocalMapper:
    """A LocalMapper (defaults, back end in line) fed every scan of a drive."""
    local = LocalMapper()
    for t, s in zip(stamps, scans, strict=True):
        feed(local, float(t), s)
    return local


def stranger_scan(seed: int = 5) -> LaserScanData:
    """A round room with a pillar, nothing like the office."""
    octagon = np.array(
        [
            [6 * np.cos(a), 6 * np.sin(a), 6 * np.cos(a + np.pi / 4), 6 * np.sin(a + np.pi / 4)]
            for a in np.arange(8) * np.pi / 4 + 0.3
        ]
    )
    return simulate_scan(
        np.vstack((octagon, box(2.0, 1.0, 0.4, 0.4))),
        (0.0, 0.0, 0.0),
        LaserModel(),
        np.random.default_rng(seed),
    )


def fake_match(
    pose: tuple[float, float, float], confidence: float, judged: object = None
) -> MatchResult:
    """A match that places the new scan at ``pose`` with ``confidence`` (for a fake
    INTEGRATE; as the real one, confidence 0 where ``judged`` does not want it)."""
    x, y, theta = pose
    T_1_2 = np.array([theta, x, y])
    if callable(judged) and not judged(T_1_2):
        confidence = 0.0
    return MatchResult(T_1_2, 5.0, 0.9, True, 1, 1, confidence)


def ate(stamps: np.ndarray, poses: np.ndarray, truth: dict[float, np.ndarray]) -> float:
    """RMSE of the positions after the best rigid alignment onto the truth (se2.fit_points)."""
    est = poses[:, :2]
    ref = np.array([truth[float(s)][:2] for s in stamps])
    error = se2.transform_points(se2.fit_points(est, ref), est) - ref
    return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))


def looped_drive(rate: float, laps: float, seed: int) -> tuple[np.ndarray, list, np.ndarray]:
    """The office tour driven ``laps`` times at 0.8 m/s, scanned at ``rate`` Hz (361 beams)."""
    route = np.asarray(ROUTES["office"], dtype=np.float64)
    lap = route_section(route, 0.0, 1e9)
    length = float(np.hypot(*np.diff(lap, axis=0).T).sum())
    waypoints = np.vstack([lap] + [lap[1:]] * (int(np.ceil(laps)) - 1))
    poses = drive_path(waypoints, 0.8, rate, laps * length / 0.8)
    laser = LaserModel(rate=rate, beams=361, range_noise=0.01)
    rng = np.random.default_rng(seed)
    walls = WORLDS["office"]()
    scans = [simulate_scan(walls, tuple(p), laser, rng) for p in poses]
    return 1000.0 + np.arange(len(poses)) / rate, scans, poses


def biased_integrate(*args: object, **kwargs: object) -> MatchResult:
    """INTEGRATE turning 1 degree per metre of motion too far."""
    result = integrate(*args, **kwargs)  # type: ignore[arg-type]
    T = result.T_1_2.copy()
    T[0] += np.radians(1.0) * float(np.hypot(T[1], T[2]))
    return dataclasses.replace(result, T_1_2=T)
