"""The map merger's configuration: the shipped params file and the robot list."""

from __future__ import annotations

import pytest
from conftest import REPO

from multi_robot_mapper.core.config import ConfigError, config_from_flat
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.io.config_files import default_params_file, load_config
from multi_robot_mapper.ros.merger_config import MapMergerConfig


def test_the_shipped_params_file_holds_the_defaults() -> None:
    shipped = (REPO / "config" / "map_merger.yaml").read_text(encoding="utf-8")
    assert shipped == default_params_file(MapMergerConfig, "map_merger"), "run `make config`"
    assert "map_merger" in shipped.splitlines()[0]
    assert load_config(MapMergerConfig, REPO / "config" / "map_merger.yaml") == MapMergerConfig()


def test_the_merge_section_is_the_merging_config() -> None:
    config = config_from_flat(
        MapMergerConfig, {"merge.pairwise.link_min_value": 3.0, "merge.integrate.seed": 4}
    )
    assert config.merge == MergeConfig(
        pairwise=MergeConfig().pairwise.__class__(link_min_value=3.0),
        integrate=MergeConfig().integrate.__class__(seed=4),
    )


def test_robot_names_are_namespaces_without_slashes_blanks_or_repeats() -> None:
    assert MapMergerConfig().robot_names() == []
    config = MapMergerConfig(robots=" /robot1, robot2/,,fleet/robot3 , robot1")
    assert config.robot_names() == ["robot1", "robot2", "fleet/robot3"]


def test_bad_values_are_refused_by_name() -> None:
    with pytest.raises(ConfigError, match="method"):
        config_from_flat(MapMergerConfig, {"method": "icp"})
    with pytest.raises(ConfigError, match="merge_period"):
        config_from_flat(MapMergerConfig, {"merge_period": 0.0})


def test_both_methods_run_and_ffs_settings_are_validated() -> None:
    for method in ("pivot", "ffs"):
        MapMergerConfig(method=method).require_implemented()
    config = config_from_flat(MapMergerConfig, {"method": "ffs", "merge.ffs.spacing": 0.05})
    assert config.merge.ffs.spacing == 0.05
    with pytest.raises(ConfigError, match="sigma_end"):
        config_from_flat(MapMergerConfig, {"merge.ffs.sigma_end": 0.5})
