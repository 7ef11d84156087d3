"""``mrm run``'s parameters: each -p goes to the nodes that have it, typed, and each node process
gets its own."""

from __future__ import annotations


def test_dash_p_goes_to_the_nodes_that_have_the_parameter() -> None:
    from multi_robot_mapper.cli.run import node_parameters

    mapper, merger = node_parameters(
        ["max_scan_rate:=10", "merge_period:=2.5", "warning_period:=3", "grid.enabled:=false"]
    )
    assert {p.name: p.value for p in mapper} == {"max_scan_rate": 10.0, "warning_period": 3.0}
    assert all(isinstance(p.value, float) for p in mapper)
    assert {p.name: p.value for p in merger} == {
        "merge_period": 2.5,
        "warning_period": 3,
        "grid.enabled": False,
    }


def test_mrm_run_gives_each_node_process_its_own_parameters_typed() -> None:
    from multi_robot_mapper.cli.run import node_commands, node_parameters

    items = ["max_scan_rate:=10", "merge_period:=2", "map_file:=/tmp/m.json"]
    mapper, merger = node_parameters(items)
    commands = node_commands(["r1", "r2"], ["--params-file", "p.yaml"], mapper, merger)
    assert list(commands) == ["r1", "r2", "map_merger"]
    shared = ["--params-file", "p.yaml"]
    assert commands["r2"][-6:] == ["-r", "__ns:=/r2", *shared, "-p", "max_scan_rate:=10.0"]
    merger_args = commands["map_merger"][commands["map_merger"].index("--ros-args") :]
    own = ["-p", "merge_period:=2.0", "-p", 'map_file:="/tmp/m.json"']
    assert merger_args == ["--ros-args", *shared, *own]
