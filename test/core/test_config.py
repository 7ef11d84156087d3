"""Typed configuration (core/config.py): one set of defaults, validated by name and range, and
overrides parsed like YAML. Parameter files: test/io/test_config_files.py; the shipped
robot_mapper.yaml: test/ros/test_mapper_config.py."""

from __future__ import annotations

import pytest

from multi_robot_mapper.core.config import (
    ConfigError,
    config_from_flat,
    parse_override,
)
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"extraction.split_tolerance": -0.1}, "extraction.split_tolerance"),
        ({"extraction.split_tolerance": 0.0}, r"outside its range \[0.001, 1\] m"),
        ({"extraction.min_cluster_points": 2.5}, "must be int"),
        ({"extraction.simplifier": "rdp"}, "not one of split, dce"),
        ({"extraction.cluster_distance": True}, "must be float"),
        ({"extraction.clusterdistance": 0.2}, "unknown parameter"),
    ],
)
def test_invalid_values_are_refused_with_the_parameter_named(values: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        config_from_flat(RobotMapperConfig, values)


def test_ints_are_accepted_for_floats_and_overrides_parse_like_yaml() -> None:
    assert config_from_flat(ExtractionConfig, {"cluster_distance": 1}).cluster_distance == 1.0
    assert parse_override("a.b=0.5") == ("a.b", 0.5)
    assert parse_override("a=true") == ("a", True)
    assert parse_override("a=dce") == ("a", "dce")
    with pytest.raises(ConfigError, match="name=value"):
        parse_override("nonsense")
