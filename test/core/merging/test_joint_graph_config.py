"""The joint graph's settings (core/merging/joint_graph_config.py): every declared range is
enforced at construction, naming the parameter, its value and its range with its unit; the ends
of each range are accepted."""

from __future__ import annotations

import pytest

from multi_robot_mapper.core.config import ConfigError, field_specs
from multi_robot_mapper.core.merging.joint_graph_config import JointGraphConfig

NUMBERS = [s for s in field_specs(JointGraphConfig) if s.kind in (int, float)]


def test_every_range_is_refused_just_outside_and_accepted_at_its_ends() -> None:
    assert NUMBERS and all(s.minimum is not None and s.maximum is not None for s in NUMBERS)
    for spec in NUMBERS:
        step = 1e-6 * max(1.0, abs(spec.maximum))  # type: ignore[arg-type]
        for outside in (spec.minimum - step, spec.maximum + step):  # type: ignore[operator]
            with pytest.raises(ConfigError, match=rf"'{spec.name}' = .* outside its range"):
                JointGraphConfig(**{spec.name: outside})
        ends = [spec.maximum] if spec.exclusive_minimum else [spec.minimum, spec.maximum]
        for end in ends:
            assert getattr(JointGraphConfig(**{spec.name: end}), spec.name) == end


def test_a_sigma_below_its_floor_is_refused_with_its_unit() -> None:
    # A zero standard deviation would make an edge infinitely stiff (a singular information).
    with pytest.raises(
        ConfigError, match=r"'sigma' = 0\.0 m is outside its range \[0\.0001, 10\] m"
    ):
        JointGraphConfig(sigma=0.0)
    with pytest.raises(ConfigError, match=r"'link_angle_sigma' = -1\.0 rad is outside"):
        JointGraphConfig(link_angle_sigma=-1.0)
    with pytest.raises(ConfigError, match=r"'drift' must be float, got True"):
        JointGraphConfig(drift=True)
