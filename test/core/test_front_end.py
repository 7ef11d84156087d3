"""The offline run's front end (core/front_end.py): every robot's scans to segments, in the
order to map them, with what it refused counted by reason and its progress reported."""

from __future__ import annotations

import dataclasses

import numpy as np

from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.front_end import FrontEnd
from multi_robot_mapper.core.offline import TimedLaserScan
from multi_robot_mapper.core.scan_stream import ScanStreamConfig
from multi_robot_mapper.core.simulation import LaserModel, simulate_robots


def test_the_front_end_yields_usable_scans_and_counts_the_refused_by_reason() -> None:
    run = simulate_robots("office", 1, LaserModel(rate=10.0), seed=0, duration=1.0)[0]
    items = [TimedLaserScan(float(t), s) for t, s in zip(run.stamps, run.scans, strict=True)]
    empty = dataclasses.replace(items[3].scan, ranges=np.zeros(0))
    items[3] = TimedLaserScan(items[3].stamp, empty)  # no beams: extraction refuses it
    progress: list[tuple[str, int, int]] = []
    front_end = FrontEnd(
        ExtractionConfig(), ScanStreamConfig(), lambda *a: progress.append(a), len(items)
    )
    out = list(front_end.scans("robot1", items))
    kept = [item.stamp for item, _, _ in out]
    assert kept == [item.stamp for k, item in enumerate(items) if k != 3]
    assert all(len(segments) > 0 for _, segments, _ in out)
    assert not any(reset for _, _, reset in out)
    counts = front_end.counts()
    assert counts["scans_total"] == len(items)
    assert counts["scans_rejected"] == {"no_beams": 1}
    assert counts["map_resets"] == 0
    assert progress[-1] == ("mapping robot1", len(items), len(items))


def test_a_robot_without_reference_poses_places_nothing_by_reference() -> None:
    run = simulate_robots("office", 1, LaserModel(rate=10.0), seed=0, duration=0.5)[0]
    items = [TimedLaserScan(float(t), s) for t, s in zip(run.stamps, run.scans, strict=True)]
    front_end = FrontEnd(ExtractionConfig(), ScanStreamConfig(), None, len(items))
    assert list(front_end.scans("robot1", items, needs_reference=True)) == []
    assert front_end.done == len(items)
