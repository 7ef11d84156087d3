"""The settings of Wolter's shape matching: validated on load."""

from __future__ import annotations

import pytest

from multi_robot_mapper.core.config import ConfigError
from multi_robot_mapper.core.matching.shape_config import ShapeConfig


def test_config_is_validated_on_load() -> None:
    with pytest.raises(ConfigError, match="max_group"):
        ShapeConfig(max_group=0)
    with pytest.raises(ConfigError, match="group_distance"):
        ShapeConfig(group_distance=-1.0)
