"""Few knobs (issue 49 item 5): a node's ROS parameters are its user parameters, at most 30,
each documented with its range, unit and when to change it; every other config field is a
fixed constant, refused with a message naming it when a params file or ``-p`` sets it, and
still reached by ``mrm --set`` / ``--config`` (offline) and by a config built in Python."""

from __future__ import annotations

from pathlib import Path

import pytest
import rclpy
from conftest import REPO
from rclpy.context import Context
from rclpy.exceptions import ParameterNotDeclaredException
from rclpy.parameter import Parameter

from multi_robot_mapper.cli.common import CliError
from multi_robot_mapper.core.config import ConfigError, config_from_flat, field_specs, user_specs
from multi_robot_mapper.io.config_files import load_config, parameters_from_yaml
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.merger_config import MapMergerConfig
from multi_robot_mapper.ros.testing import default_domain_id

MAX_USER_PARAMETERS = 30  # per node (issue 49 item 5)
NODES = {"robot_mapper": RobotMapperConfig, "map_merger": MapMergerConfig}
# A fixed constant of each node, for the refusals below.
FIXED = {"robot_mapper": "local_mapping.integrate.slide_step", "map_merger": "merge.link_min_wall"}


def node_class(node: str) -> type:
    from multi_robot_mapper.ros.map_merger import MapMerger
    from multi_robot_mapper.ros.robot_mapper import RobotMapper

    return RobotMapper if node == "robot_mapper" else MapMerger


@pytest.mark.parametrize("node", NODES)
def test_each_node_has_at_most_30_user_parameters_each_documented(node: str) -> None:
    specs = user_specs(NODES[node])
    assert 0 < len(specs) <= MAX_USER_PARAMETERS, f"{node}: {len(specs)} user parameters"
    for spec in specs:
        assert spec.doc and spec.tune, spec.name  # its meaning and when to change it
        if spec.kind in (int, float):  # and its range
            assert spec.minimum is not None and spec.maximum is not None, spec.name
    assert FIXED[node] in {spec.name for spec in field_specs(NODES[node])} - {
        spec.name for spec in specs
    }


@pytest.mark.parametrize("node", NODES)
def test_each_nodes_yaml_holds_its_user_parameters_only(node: str) -> None:
    path = REPO / "config" / f"{node}.yaml"
    keys = parameters_from_yaml(path, node_name=node)
    assert len(keys) <= MAX_USER_PARAMETERS, f"config/{node}.yaml has {len(keys)} keys"
    assert set(keys) == {spec.name for spec in user_specs(NODES[node])}
    lines = path.read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines):  # each key under its comment: ..., when to change it
        if line.strip() and not line.lstrip().startswith("#") and not line.endswith(":"):
            comment = []
            for above in reversed(lines[:i]):
                if not above.lstrip().startswith("#"):
                    break
                comment.insert(0, above.strip("# "))
            assert "When to change it:" in " ".join(comment), line


@pytest.mark.ros
@pytest.mark.parametrize("node", NODES)
def test_every_key_of_the_yaml_is_a_parameter_the_node_declares(node: str) -> None:
    path = REPO / "config" / f"{node}.yaml"
    keys = set(parameters_from_yaml(path, node_name=node))
    context = Context()
    rclpy.init(
        args=["test", "--ros-args", "--params-file", str(path)],
        context=context,
        domain_id=default_domain_id(),
    )
    try:
        instance = node_class(node)(context=context)  # the shipped file is accepted
        try:
            assert all(instance.has_parameter(key) for key in keys)
            fields = {spec.name for spec in field_specs(NODES[node])}
            declared = {name for name in instance._parameters if name in fields}
            assert declared == keys  # no config field is a ROS parameter but these
        finally:
            instance.destroy_node()
    finally:
        context.try_shutdown()


@pytest.mark.parametrize("node", NODES)
def test_a_fixed_constant_in_a_params_file_is_refused_with_its_name(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    node: str,
) -> None:
    from multi_robot_mapper.ros import map_merger, robot_mapper

    path = tmp_path / "params.yaml"
    path.write_text(f"/**:\n  ros__parameters:\n    {FIXED[node]}: 0.5\n")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(default_domain_id()))
    entry = robot_mapper.main if node == "robot_mapper" else map_merger.main
    assert entry([node, "--ros-args", "--params-file", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"'{FIXED[node]}' is a fixed constant of {node}, not a ROS parameter" in err
    assert "mrm replay ... --set NAME=VALUE" in err  # where an experiment changes it
    assert err.count("\n") == 1


@pytest.mark.ros
def test_a_fixed_constant_is_no_ros_parameter_and_a_python_config_sets_it(ros_context) -> None:
    from multi_robot_mapper.ros.robot_mapper import RobotMapper

    with pytest.raises(ConfigError, match=r"'stamp_reset_jump' is a fixed constant"):
        RobotMapper(
            context=ros_context, parameter_overrides=[Parameter("stamp_reset_jump", value=3.0)]
        )
    # Built in Python with a config: its fixed constants hold, its user fields are the ROS
    # parameters' defaults, and ROS overrides and `ros2 param set` change only those.
    config = config_from_flat(
        RobotMapperConfig, {"stamp_reset_jump": 3.0, "partial_map_period": 0.5}
    )
    node = RobotMapper(
        context=ros_context,
        config=config,
        parameter_overrides=[Parameter("max_scan_rate", value=10.0)],
    )
    try:
        assert (node.config.stamp_reset_jump, node.config.max_scan_rate) == (3.0, 10.0)
        assert node.get_parameter("partial_map_period").value == 0.5
        (result,) = node.set_parameters([Parameter("max_scan_rate", value=5.0)])
        assert result.successful and node.config.max_scan_rate == 5.0
        assert node.config.stamp_reset_jump == 3.0
        with pytest.raises(ParameterNotDeclaredException):
            node.set_parameters([Parameter("stamp_reset_jump", value=4.0)])
        assert node.config.stamp_reset_jump == 3.0
    finally:
        node.destroy_node()


def test_mrm_run_refuses_a_fixed_constant_given_with_dash_p() -> None:
    from multi_robot_mapper.cli.run import node_parameters

    with pytest.raises(CliError, match=r"'merge\.link_min_wall' is a fixed constant of map_merger"):
        node_parameters(["merge.link_min_wall:=3.0"])
    with pytest.raises(CliError, match=r"'max_segments_per_map' .*--merger-config FILE"):
        node_parameters(["max_segments_per_map:=10"])
    with pytest.raises(CliError, match="neither robot_mapper nor map_merger"):
        node_parameters(["no_such_parameter:=1"])


def test_set_and_config_files_still_reach_every_field_offline(tmp_path: Path) -> None:
    path = tmp_path / "experiment.yaml"
    path.write_text("local_mapping:\n  integrate:\n    slide_step: 0.2\n")
    config = load_config(RobotMapperConfig, path, ["stamp_reset_jump=3"])
    assert config.local_mapping.integrate.slide_step == 0.2
    assert config.stamp_reset_jump == 3.0
    path.write_text("max_segments_per_map: 10\nmerge:\n  link_min_wall: 2.0\n")
    merger = load_config(MapMergerConfig, path, ["merge.ffs.sigma_end=0.05"])
    assert (merger.max_segments_per_map, merger.merge.link_min_wall) == (10, 2.0)
    assert merger.merge.ffs.sigma_end == 0.05
