"""Typed configuration: one set of defaults, loaded the same way from YAML, overrides and ROS."""

from __future__ import annotations

from pathlib import Path

import pytest

from multi_robot_mapper.core.config import (
    ConfigError,
    config_from_flat,
    config_to_flat,
    parse_override,
    user_specs,
)
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.io.config_files import (
    default_params_file,
    load_config,
    parameters_from_yaml,
)
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"


def test_shipped_yaml_equals_the_documented_defaults() -> None:
    from_yaml = parameters_from_yaml(CONFIG_DIR / "robot_mapper.yaml", node_name="robot_mapper")
    users = {spec.name for spec in user_specs(RobotMapperConfig)}  # the file's keys: see
    defaults = config_to_flat(RobotMapperConfig())  # test_user_parameters.py
    assert from_yaml == {name: value for name, value in defaults.items() if name in users}
    # The file is exactly what `make config` writes, comments included.
    shipped = (CONFIG_DIR / "robot_mapper.yaml").read_text(encoding="utf-8")
    assert shipped == default_params_file(RobotMapperConfig), "run `make config`"


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


def test_direct_construction_is_validated_too() -> None:
    with pytest.raises(ConfigError, match="cluster_distance"):
        ExtractionConfig(cluster_distance=-1.0)


def test_ints_are_accepted_for_floats_and_overrides_parse_like_yaml() -> None:
    assert config_from_flat(ExtractionConfig, {"cluster_distance": 1}).cluster_distance == 1.0
    assert parse_override("a.b=0.5") == ("a.b", 0.5)
    assert parse_override("a=true") == ("a", True)
    assert parse_override("a=dce") == ("a", "dce")
    with pytest.raises(ConfigError, match="name=value"):
        parse_override("nonsense")


def test_missing_or_broken_yaml_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(RobotMapperConfig, tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(RobotMapperConfig, bad)
