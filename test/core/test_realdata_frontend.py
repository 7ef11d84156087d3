"""The front end on real SICK scans from ../shared/data (skipped when the data is absent)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CARMEN_LOGS, carmen_log

from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.geometry import point_segment_distance, ranges_index
from multi_robot_mapper.io.carmen import carmen_scan_data, read_carmen

pytestmark = pytest.mark.realdata
DEFAULT = ExtractionConfig()


@pytest.mark.parametrize("name", CARMEN_LOGS)
def test_every_covered_point_lies_within_kappa_plus_1cm_of_its_segment(name: str) -> None:
    scans = list(read_carmen(carmen_log(name)))
    assert len(scans) > 300
    worst = 0.0
    segment_counts = []
    for scan in scans:
        result, valid = extract_scan(carmen_scan_data(scan), DEFAULT)
        segment_counts.append(len(result))
        if len(result) == 0:
            assert result.dropped_points == len(valid.points)
            continue
        first, last = result.point_span.T
        # All segments' covered points at once: each segment repeated over its point range.
        index, owner, _ = ranges_index(first, last + 1)
        seg = result.segments[owner]
        q = result.points[index]
        worst = max(worst, float(point_segment_distance(q[:, 0], q[:, 1], *seg.T).max()))
        # Every valid point is either covered by a segment or dropped with its small cluster.
        assert np.unique(index).size + result.dropped_points == len(valid.points)
    assert worst <= DEFAULT.split_tolerance + 0.01, f"{name}: a covered point is {worst:.4f} m away"
    assert np.median(segment_counts) >= 5, "real indoor scans have walls"


def test_intel_has_910_scans_with_180_beams() -> None:
    scans = list(read_carmen(carmen_log("intel")))
    assert len(scans) == 910
    assert {s.ranges.size for s in scans} == {180}
