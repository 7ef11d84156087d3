"""Bringup without launch (``mrm run``), the params file applied to every node, and the launch
file. How -p is shared out: test/cli/test_run.py; the params file as generated:
test/ros/test_params_files.py."""

from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from test_link_graph import SIMULATED_WORLD_JOIN_PROBABILITY

from multi_robot_mapper.core.config import ConfigError
from multi_robot_mapper.core.simulation import LaserModel, simulate_robots
from multi_robot_mapper.io.bags import recording_of
from multi_robot_mapper.ros.bringup import build_system, robot_names
from multi_robot_mapper.ros.live import Observer, ScanPlayer, timeline
from multi_robot_mapper.ros.params_files import SYSTEM_PARAMS_FILE
from multi_robot_mapper.ros.testing import default_domain_id, isolated_context, spin_until

REPO = Path(__file__).resolve().parents[2]
PARAMS = REPO / "config" / SYSTEM_PARAMS_FILE
LAUNCH = REPO / "launch" / "multi_robot_mapper.launch.py"


def test_robot_names_are_namespaces() -> None:
    assert robot_names("robot1, /robot2/,robot1,,team_a/r3") == ["robot1", "robot2", "team_a/r3"]
    for bad in ("", " , ", "1robot", "robot-1", "a//b"):
        with pytest.raises(ConfigError):
            robot_names(bad)


@pytest.mark.ros
def test_build_system_applies_the_params_file_to_every_robot_and_the_merger(
    tmp_path: Path,
) -> None:
    # The shipped file, with two values changed, given as --ros-args as ros2 run would.
    text = PARAMS.read_text(encoding="utf-8")
    text = text.replace("partial_map_period: 1.0\n", "partial_map_period: 0.7\n", 1)
    text = text.replace("merge_period: 1.0\n", "merge_period: 0.3\n", 1)
    changed = tmp_path / "p.yaml"
    changed.write_text(text, encoding="utf-8")
    context = Context()
    rclpy.init(
        args=["test", "--ros-args", "--params-file", str(changed)],
        context=context,
        domain_id=default_domain_id(),
    )
    try:
        system = build_system(["robot1", "robot2"], method="pivot", context=context)
        try:
            assert sorted(system.mappers) == ["robot1", "robot2"]
            for name, mapper in system.mappers.items():
                assert mapper.get_namespace() == f"/{name}"
                assert mapper.config.partial_map_period == 0.7
            assert system.merger.config.merge_period == 0.3
            assert system.merger.config.robot_names() == ["robot1", "robot2"]
            assert sorted(system.merger.robots) == ["robot1", "robot2"]
        finally:
            system.destroy()
        with pytest.raises(ConfigError, match="icp"):
            build_system(["robot1"], method="icp", context=context)
        system = build_system(["robot1"], method="ffs", context=context)
        try:
            assert system.merger.config.method == "ffs"
        finally:
            system.destroy()
    finally:
        context.try_shutdown()


def test_mrm_run_refuses_unknown_methods_and_missing_params_files_with_exit_2(
    mrm, capsys, tmp_path
) -> None:
    os.environ.setdefault("ROS_DOMAIN_ID", str(default_domain_id()))
    with pytest.raises(SystemExit) as exited:  # argparse's choices
        mrm(["run", "--robots", "robot1", "--method", "icp"])
    assert exited.value.code == 2 and "icp" in capsys.readouterr().err
    assert mrm(["run", "--robots", "robot1", "--params-file", str(tmp_path / "no.yaml")]) == 2
    assert "no such params file" in capsys.readouterr().err
    assert mrm(["run", "--robots", "9lives"]) == 2
    assert mrm(["run", "--robots", "robot1", "-p", "no_such_parameter:=1"]) == 2
    assert "neither robot_mapper nor map_merger" in capsys.readouterr().err


def _communicate_or_dump(process: subprocess.Popen[bytes], timeout: float) -> tuple[bytes, bytes]:
    """The process's output once it exits; if it does not within ``timeout``, its threads'
    stacks (SIGUSR1, faulthandler: run_nodes registers it) in the failure message."""
    try:
        return process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGUSR1)
        time.sleep(2.0)
        process.kill()
        _, err = process.communicate()
        raise AssertionError(f"no exit {timeout} s after the signal:\n{err.decode()}") from None


@pytest.mark.ros
@pytest.mark.parametrize("in_process", [False, True], ids=["a process per node", "in-process"])
@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_mrm_run_maps_and_merges_live_and_stops_cleanly(
    stop: signal.Signals, in_process: bool
) -> None:
    """``mrm run`` in a process of its own (by default its nodes in processes of their own,
    or with ``--in-process`` all in it): two simulated robots' scans go in on their topics,
    the merged global map comes out; SIGINT and SIGTERM end it, and every node, with exit
    code 0."""
    robots = ["robot1", "robot2"]
    env = dict(os.environ, ROS_DOMAIN_ID=str(default_domain_id()))
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    command = [sys.executable, "-m", "multi_robot_mapper.cli.main", "run"]
    command += ["--robots", ",".join(robots), "--params-file", str(PARAMS)]
    # The simulated office's right join gets P 0.95-0.99 from 30 s of driving: merged at
    # test_link_graph's SIMULATED_WORLD_JOIN_PROBABILITY (-p reaches the merger).
    command += ["-p", f"merge.join_probability:={SIMULATED_WORLD_JOIN_PROBABILITY}"]
    command += ["--in-process"] if in_process else []
    # A session of its own, so that the signal can go to its whole process group, as a
    # terminal's Ctrl-C does: each node process, in a group of its own, gets one SIGINT, from
    # mrm run.
    process = subprocess.Popen(
        command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True
    )
    try:
        with isolated_context() as context:
            observer = Observer(robots, context=context)
            driver = Node("driver", context=context)
            player = ScanPlayer(driver, robots, speed=1.0)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(observer)
            executor.add_node(driver)
            try:
                # Every node up (the mappers take their scans, the merger offers its map)
                # before the signal: a node still starting is not what this test stops.
                assert spin_until(
                    executor,
                    lambda: player.subscribed() and driver.count_publishers("/global_map") > 0,
                    30.0,
                ), process.poll()
                if stop == signal.SIGINT:
                    _drive_two_robots(executor, observer, player, robots)
            finally:
                player.stop()
                executor.shutdown()
                observer.destroy_node()
                driver.destroy_node()
        os.killpg(process.pid, stop)
        out, err = _communicate_or_dump(process, timeout=20.0)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, err.decode()
    assert b"Traceback" not in err, err.decode()
    assert b"robot1, robot2 and a map_merger" in out
    assert (b"in one process" in out) == in_process


def _drive_two_robots(executor, observer: Observer, player: ScanPlayer, robots: list[str]) -> None:
    """The office: two robots, 30 s each sharing 45 % of their stretches (as the demo), every
    4th scan (10 Hz), played live; both robots' frames and a global map holding both come back
    (the frames and the map are two topics: either may arrive first)."""
    runs = simulate_robots("office", 2, LaserModel(), seed=1, duration=30.0, overlap=0.45)
    scans = {r: recording_of(r, run).scans[::4] for r, run in zip(robots, runs, strict=True)}
    player.start(timeline(scans))
    assert spin_until(
        executor,
        lambda: (
            len(observer.merged()) == 2
            and not player.running()
            and bool(observer.global_maps)
            and len(observer.global_maps[-1].segments) == 2
        ),
        90.0,
    ), (observer.merged(), player.stats.published)
    assert spin_until(executor, lambda: observer.grid is not None, 10.0)


@pytest.mark.ros
def test_mrm_run_ends_with_exit_2_when_a_node_process_refuses_its_parameters(mrm, capsys) -> None:
    """A value out of its range passes ``mrm run``'s own checks (names only) and is refused by
    the node that has it: every other node process is stopped and the exit code is 2."""
    os.environ.setdefault("ROS_DOMAIN_ID", str(default_domain_id()))
    assert mrm(["run", "--robots", "robot1", "-p", "max_scan_rate:=-5"]) == 2
    assert "robot1 ended with exit code 2" in capsys.readouterr().err


def test_the_launch_file_parses_and_is_installed() -> None:
    tree = ast.parse(LAUNCH.read_text(encoding="utf-8"))
    functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in functions
    setup = (REPO / "setup.py").read_text(encoding="utf-8")
    assert 'glob("launch/*.launch.py")' in setup
    assert "<exec_depend>launch_ros</exec_depend>" in (REPO / "package.xml").read_text()


def test_the_launch_file_builds_its_description_where_launch_is_installed(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    pytest.importorskip("launch_ros", reason="launch and launch_ros come with apt ROS, not PyPI")
    import importlib.util

    spec = importlib.util.spec_from_file_location("multi_robot_mapper_launch", LAUNCH)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setattr(
        "ament_index_python.packages.get_package_share_directory", lambda _: str(REPO)
    )
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert len(description.entities) == 5
