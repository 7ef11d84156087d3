"""The robot_mapper's settings: the shipped YAML is exactly the documented defaults, as ``make
config`` writes it."""

from __future__ import annotations

from pathlib import Path

from multi_robot_mapper.core.config import (
    config_to_flat,
    user_specs,
)
from multi_robot_mapper.io.config_files import (
    default_params_file,
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
