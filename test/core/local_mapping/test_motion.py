"""The robot's recent motion (issue 47 item 5): the last motion predicted again, the velocity
over a window, and how far its predictions miss."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multi_robot_mapper.core.local_mapping.motion import ERRORS_NEEDED, RecentMotion


@settings(max_examples=30, deadline=None)
@given(
    speed=st.floats(0.05, 2.0),
    turn_rate=st.floats(-1.0, 1.0),
    period=st.sampled_from([0.025, 0.1, 0.2, 1.0]),
)
def test_the_last_motion_is_predicted_again_and_a_steady_drive_over_a_window(
    speed: float, turn_rate: float, period: float
) -> None:
    step = (speed * period, 0.0, turn_rate * period)
    alone = RecentMotion()  # the mapper's default: the last placed motion
    straight = RecentMotion(window=0.5)
    for _ in range(30):
        alone.placed(period, step, alone.predict(period), None)
        straight.placed(period, (*step[:2], 0.0), straight.predict(period), None)
    np.testing.assert_allclose(alone.predict(period) or (), step, atol=1e-12)
    np.testing.assert_allclose(straight.predict(period) or (), (*step[:2], 0.0), atol=1e-9)


def test_the_velocity_is_the_mean_over_its_window_not_the_last_jitter() -> None:
    recent = RecentMotion(window=0.5)
    for k in range(10):  # 0.6 m/s with +-5 cm of matching jitter, alternating
        recent.placed(0.1, (0.06 + (0.05 if k % 2 else -0.05), 0.0, 0.0), None, None)
    velocity = recent.velocity()
    assert velocity is not None and velocity[0] == pytest.approx(0.6, abs=0.11)
    recent.window = 0.0  # the last placed motion alone (the mapper's default)
    recent.placed(0.1, (0.11, 0.0, 0.0), None, None)
    velocity = recent.velocity()
    assert velocity is not None and velocity[0] == pytest.approx(1.1)


def test_prediction_errors_come_only_from_placements_the_walls_fix() -> None:
    recent = RecentMotion()
    for _ in range(ERRORS_NEEDED + 5):
        # A corridor's placement (no support) says nothing of the prediction's error.
        recent.placed(0.1, (0.1, 0.0, 0.0), (0.05, 0.0, 0.0), 0.0)
    assert recent.prior_sigma(0.1, 0.1) is None
    for _ in range(ERRORS_NEEDED):
        recent.placed(0.1, (0.1, 0.0, 0.0), (0.09, 0.0, 0.0), 5.0)  # 1 cm missed each time
    sigma = recent.prior_sigma(0.1, 0.1)
    assert sigma is not None and sigma == pytest.approx(0.01 / 2.146, rel=0.01)
    # Twice the time ahead: twice the velocity's error, and twice again for the acceleration.
    assert recent.prior_sigma(0.2, 0.1) == pytest.approx(4.0 * sigma)


def test_a_velocity_carried_on_unobserved_is_worth_less_the_longer_it_is_carried() -> None:
    # Down a bare corridor the velocity is not measured, only carried on: its error moves
    # every scan placed since one way, so the prior's spread grows with that time.
    recent = RecentMotion()
    for _ in range(ERRORS_NEEDED):
        recent.placed(0.1, (0.1, 0.0, 0.0), (0.09, 0.0, 0.0), 5.0)
    observed = recent.prior_sigma(0.1, 0.1)
    for _ in range(4):
        recent.placed(0.1, (0.1, 0.0, 0.0), (0.1, 0.0, 0.0), 0.0)  # 0.4 s unobserved
    assert observed is not None
    assert recent.prior_sigma(0.1, 0.1) == pytest.approx(5.0 * observed)
    recent.placed(0.1, (0.1, 0.0, 0.0), (0.09, 0.0, 0.0), 5.0)  # the walls see it again
    assert recent.prior_sigma(0.1, 0.1) == pytest.approx(observed)
