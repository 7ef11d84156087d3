"""Parameter files: YAML then overrides in order, a node's own section over the wildcard, and a
missing or broken file a config error."""

from __future__ import annotations

from pathlib import Path

import pytest

from multi_robot_mapper.core.config import (
    ConfigError,
)
from multi_robot_mapper.io.config_files import (
    load_config,
)
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig


def test_yaml_then_overrides_apply_in_order(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text("extraction:\n  split_tolerance: 0.04\n  cluster_distance: 0.3\n")
    cfg = load_config(RobotMapperConfig, path, ["extraction.cluster_distance=0.25"])
    assert cfg.extraction.split_tolerance == 0.04
    assert cfg.extraction.cluster_distance == 0.25


def test_params_file_node_section_overrides_wildcard(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(
        "/**:\n  ros__parameters:\n    warning_period: 3.0\n"
        "/robot2/robot_mapper:\n  ros__parameters:\n    warning_period: 7.0\n"
        "other_node:\n  ros__parameters:\n    warning_period: 99.0\n"
    )
    assert load_config(RobotMapperConfig, path, node_name="robot_mapper").warning_period == 7.0
    assert load_config(RobotMapperConfig, path, node_name="x").warning_period == 3.0


def test_missing_or_broken_yaml_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(RobotMapperConfig, tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(RobotMapperConfig, bad)
