"""The segment grid of culled ray casting: exactly the segments within reach."""

from __future__ import annotations

import numpy as np
from test_buildings import segment_distance

from multi_robot_mapper.core.segment_grid import segment_grid


def test_segment_grid_finds_exactly_the_segments_within_reach() -> None:
    rng = np.random.default_rng(4)
    starts = rng.uniform(-50, 50, (400, 2))
    segments = np.hstack((starts, starts + rng.normal(0, 3, (400, 2))))
    grid = segment_grid(segments, 12.0)
    for x, y in rng.uniform(-70, 70, (50, 2)):
        distance = segment_distance(np.array([[x, y, x, y]]), segments)[0]
        expected = np.flatnonzero(distance <= 12.0)
        assert set(grid.within(float(x), float(y)).tolist()) >= set(expected.tolist())
        assert np.all(distance[grid.within(float(x), float(y))] <= 12.0 + 1e-6)
