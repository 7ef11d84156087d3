"""The evidence of a loop closure in local mapping: the robot's own approach left out of the
target."""

from __future__ import annotations

import numpy as np


def test_a_closure_is_weighed_without_the_robot_s_own_approach() -> None:
    """A robot drives out along y = 0 (keyframes 0-10, 3 m apart), turns round at 30 m and
    comes back 2.5 m a keyframe: keyframe 20 (at 5 m) closes on the way out. Its approach
    (keyframes 15-17, within APPROACH_RADIUS = 14 m and mapped with the drift the closure
    corrects) leaves the target; the way out, however near, and the far end stay."""
    from multi_robot_mapper.core.local_mapping.evidence import APPROACH_RADIUS, without_approach

    assert APPROACH_RADIUS == 14.0
    out = [(float(x), 0.0, 0.0) for x in range(0, 31, 3)]  # keyframes 0-10
    back = [(30.0 - 2.5 * k, 0.0, np.pi) for k in range(1, 11)]  # keyframes 11-20
    poses = np.array(out + back)
    older = np.arange(0, 18)  # before the recent stretch (keyframes 18-20)
    target = without_approach(poses, older, first_stretch_end=5, mine=20)
    assert target.tolist() == list(range(15))
    # Nothing up to the end of the stretch the closure returns to is ever taken.
    target = without_approach(poses, older, first_stretch_end=16, mine=20)
    assert target.tolist() == list(range(17))
