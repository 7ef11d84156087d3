"""The extraction settings are validated when constructed directly, not only when loaded."""

from __future__ import annotations

import pytest

from multi_robot_mapper.core.config import (
    ConfigError,
)
from multi_robot_mapper.core.extraction_config import ExtractionConfig


def test_direct_construction_is_validated_too() -> None:
    with pytest.raises(ConfigError, match="cluster_distance"):
        ExtractionConfig(cluster_distance=-1.0)
