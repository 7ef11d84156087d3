"""The system params file (ros/params_files.py): generated, and holding both nodes' defaults."""

from __future__ import annotations

from pathlib import Path

from multi_robot_mapper.core.config import config_to_flat, user_specs
from multi_robot_mapper.io.config_files import parameters_from_yaml
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.merger_config import MapMergerConfig
from multi_robot_mapper.ros.params_files import SYSTEM_PARAMS_FILE, system_params_file

PARAMS = Path(__file__).resolve().parents[2] / "config" / SYSTEM_PARAMS_FILE


def test_the_system_params_file_is_generated_and_holds_both_nodes_defaults() -> None:
    assert PARAMS.read_text(encoding="utf-8") == system_params_file(), "run `make config`"
    for node, config_class in (
        ("robot_mapper", RobotMapperConfig),
        ("map_merger", MapMergerConfig),
    ):
        users = {spec.name for spec in user_specs(config_class)}  # its ROS parameters only
        defaults = config_to_flat(config_class())
        expected = {name: value for name, value in defaults.items() if name in users}
        assert parameters_from_yaml(PARAMS, node_name=node) == expected, node
