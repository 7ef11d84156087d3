"""The robot's recent motion, as tracking uses it: the constant-velocity prediction of the next
scan, how far such predictions have missed, and so what the prediction is worth as a motion
prior along the direction a match cannot observe (:mod:`core.matching.prior`; issue 47 item 5).

The velocity is the robot's motion over its placed scans of the last ``window`` seconds (at
least the last one; the mapper's ``velocity_window``, 0 by default: the last motion alone), per
second, scaled to the time predicted (as the mapper always predicted). The prediction's own
error is measured on the robot's placements where the walls fix every direction
(:data:`MEASURED_SUPPORT`): its spread per second, read from the latest :data:`ERRORS_KEPT`, is
the prior's standard deviation, grown with the time predicted and with the time since the walls
last fixed every direction (the velocity is carried on, not measured, in between: its error
moves every scan placed since one way). Along dense corridors that was still too sure: the
prior is off by default (``motion_prior``; docs/decisions.md, tracking in corridors).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.matching.prior import UNOBSERVED_SUPPORT
from multi_robot_mapper.core.se2 import Pose

FloatArray = NDArray[np.float64]

# Placed motions whose speeds say how fast the robot drives (the latest: a robot's pace changes).
SPEEDS_KEPT = 1_000
# Prediction errors kept (the latest: a robot's pace changes), and how many make a spread.
ERRORS_KEPT = 200
ERRORS_NEEDED = 20
# A placement measures the prediction's error only where its walls fix every direction, the
# weakest too: there the prior is not weighed (core.matching.prior), so no placement both
# uses the prior and measures it.
MEASURED_SUPPORT = UNOBSERVED_SUPPORT
# The spread is read from the errors' 90th percentile, not their median: a prior must not be
# surer than the robot's worse moments (a bump, a stop). The length of a 2-D normal error
# exceeds sqrt(-2 ln 0.1) = 2.146 standard deviations per axis one time in ten.
_QUANTILE = 90.0
_RAYLEIGH_QUANTILE = float(np.sqrt(-2.0 * np.log(1.0 - _QUANTILE / 100.0)))


class RecentMotion:
    """The placed motions of the last ``window`` seconds, the prediction errors, and
    the speeds and periods of the latest :data:`SPEEDS_KEPT` placed motions."""

    def __init__(self, window: float = 0.0) -> None:
        self.window = window  # seconds of placed motions the velocity is taken over
        self._motions: deque[tuple[float, Pose]] = deque()  # (seconds, motion), oldest first
        self._errors: deque[float] = deque(maxlen=ERRORS_KEPT)  # m per second predicted
        # seconds since a placement's walls last fixed every direction (the prediction's
        # error was last measured, and its velocity last corrected, then)
        self._unobserved = 0.0
        # the speeds (m/s) of the latest placed motions (how far a lost robot can drive), and
        self._speeds: deque[float] = deque(maxlen=SPEEDS_KEPT)
        self._periods: deque[float] = deque(maxlen=SPEEDS_KEPT)  # their seconds

    def reset(self) -> None:
        """A new piece: nothing is known of the motion (the errors, speeds and periods, the
        robot's, are kept)."""
        self._motions.clear()

    @property
    def known(self) -> bool:
        return bool(self._motions)

    def velocity(self) -> FloatArray | None:
        """(x, y, theta) per second: the last scan's pose in the frame of the scan the
        window starts at, divided by the window's seconds (applied from the last scan, as the
        constant-velocity prediction; with the last motion alone, exactly that motion again
        over as many seconds). None before any motion."""
        if not self._motions:
            return None
        seconds = sum(dt for dt, _ in self._motions)
        if seconds <= 0.0:
            return None
        T_start_last = self._motions[0][1]
        for _, motion in list(self._motions)[1:]:
            T_start_last = se2.compose(T_start_last, motion)
        return np.asarray(T_start_last) / seconds

    def predict(self, seconds: float) -> Pose | None:
        """The constant-velocity motion over ``seconds`` from the last scan."""
        velocity = self.velocity()
        if velocity is None:
            return None
        vx, vy, vtheta = (float(v) for v in velocity * seconds)
        return (vx, vy, vtheta)

    def placed(
        self,
        seconds: float,
        motion: Pose,
        predicted: Pose | None,
        support: float | None,
    ) -> None:
        """A scan placed ``motion`` from the last one, ``seconds`` later; ``predicted``: the
        prediction it was tracked from (None: none), ``support`` the match's walls across its
        weakest direction (m; None: unknown)."""
        if seconds <= 0.0:
            return
        if support is not None and support >= MEASURED_SUPPORT:
            self._unobserved = 0.0
            if predicted is not None:
                miss = float(np.hypot(motion[0] - predicted[0], motion[1] - predicted[1]))
                self._errors.append(miss / seconds)
        else:
            self._unobserved += seconds
        self._speeds.append(float(np.hypot(motion[0], motion[1])) / seconds)
        self._periods.append(seconds)
        self._motions.append((seconds, motion))
        while len(self._motions) > 1 and sum(dt for dt, _ in self._motions) > self.window:
            self._motions.popleft()

    def top_speed(self) -> float | None:
        """How fast the robot drives at most, by its placed motions: their 95th percentile,
        which one wrong placement (or a motion over a short, jittery interval) cannot move.
        None before there are any."""
        if not self._speeds:
            return None
        return float(np.percentile(np.asarray(self._speeds), 95.0))

    def period(self) -> float | None:
        """The robot's usual seconds between placed scans (their median), None before any."""
        return float(np.median(np.asarray(self._periods))) if self._periods else None

    def prior_sigma(self, seconds: float, period: float | None) -> float | None:
        """The prediction's standard deviation per axis (m) over ``seconds`` (the robot's
        usual scan ``period`` beyond which it grows with the square), or None before
        :data:`ERRORS_NEEDED` errors are measured.

        Its error per second is the velocity's, and where the walls have not fixed every
        direction since the last such placement, the velocity was carried on from there, not
        measured: its error has moved the scans placed since all one way (a bias, not noise),
        so the prediction is as far off as the velocity's error over all that time."""
        if len(self._errors) < ERRORS_NEEDED or seconds <= 0.0:
            return None
        errors = np.asarray(self._errors)
        per_second = float(np.percentile(errors, _QUANTILE)) / _RAYLEIGH_QUANTILE
        growth = max(1.0, seconds / period) if period else 1.0
        return per_second * (self._unobserved + seconds) * growth
