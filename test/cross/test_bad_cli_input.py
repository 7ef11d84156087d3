"""Hostile input to ``mrm``: numbers out of range, broken config files, outputs that cannot be
written or would mix runs, interrupted runs. Each ends in one line on stderr and exit 2 (or
130/143 when interrupted) before any work, and never leaves half a result."""

from __future__ import annotations

import json
import math
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from multi_robot_mapper.cli.main import main
from multi_robot_mapper.core.config import field_specs
from multi_robot_mapper.io.outputs import atomic_write_text, staged_folder
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.merger_config import MapMergerConfig

REPO = Path(__file__).resolve().parents[2]


def mrm(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str, command: str) -> None:
    assert err.count("\n") == 1 and err.startswith(f"mrm {command}: error: "), err
    assert "Traceback" not in err


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("bag") / "sim"
    code = main(["simulate", "--robots", "2", "--out", str(bag), "--duration", "1", "--rate", "5"])
    assert code == 0
    return bag


def flaser_log(path: Path) -> Path:
    ranges = " ".join(["2.0"] * 180)
    path.write_text(f"FLASER 180 {ranges} 0 0 0 0 0 0 1.0 h 1.0\n")
    return path


# --- one table of ranges ---------------------------------------------------------------------


@pytest.mark.parametrize("config_class", [RobotMapperConfig, MapMergerConfig])
def test_every_numeric_parameter_has_one_finite_inclusive_range(config_class: type) -> None:
    for spec in field_specs(config_class):
        if spec.kind not in (int, float):
            continue
        assert spec.minimum is not None and spec.maximum is not None, spec.name
        assert math.isfinite(spec.minimum) and math.isfinite(spec.maximum), spec.name
        assert not spec.exclusive_minimum, spec.name  # ROS ranges are inclusive
        assert spec.minimum <= spec.default <= spec.maximum, spec.name


@pytest.mark.parametrize(
    ("override", "words"),
    [
        ("local_mapping.integrate.slide_step=1e-12", "outside its range [0.005, 10] m"),
        ("partial_map_period=1e-9", "outside its range [0.05, 3600] s"),
        ("extraction.split_tolerance=inf", "outside its range [0.001, 1] m"),
        ("extraction.cluster_distance=nan", "is NaN"),
        ("local_mapping.integrate.max_hypotheses=1000000000", "[1, 1e+06]"),
        ("slide_step=0.1", "did you mean 'slide_step' -> 'local_mapping.integrate.slide_step'"),
    ],
)
def test_set_outside_the_declared_range_is_refused_with_the_range(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, override: str, words: str
) -> None:
    code, _, err = mrm(capsys, "frontend", flaser_log(tmp_path / "a.log"), "--set", override)
    assert code == 2
    one_line_error(err, "frontend")
    assert words in err and f"--set {override}" in err


# --- config files ----------------------------------------------------------------------------

CONFIG_FILES = {
    "ros__parameters is a number": ("/**:\n  ros__parameters: 5\n", "must be a mapping"),
    "not UTF-8": (b"extraction:\n  split_tolerance: 0.03 # \xff\xfe\n", "not UTF-8"),
    "a directory": (None, "is a directory"),
    "unknown key": ("/**:\n  ros__parameters:\n    split_tolerence: 0.03\n", "split_tolerence"),
    "a list value": ("extraction:\n  split_tolerance: [1, 2]\n", "must be a single value"),
    "out of range": ("extraction:\n  split_tolerance: 5.0\n", "outside its range"),
    "broken YAML": ("a: [1, 2\n", "not valid YAML"),
}


@pytest.mark.parametrize("case", sorted(CONFIG_FILES))
def test_broken_config_files_give_one_line_naming_file_and_key(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, case: str
) -> None:
    content, words = CONFIG_FILES[case]
    path = tmp_path / "params.yaml"
    if content is None:
        path.mkdir()
    elif isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    code, _, err = mrm(capsys, "frontend", flaser_log(tmp_path / "a.log"), "--config", path)
    assert code == 2
    one_line_error(err, "frontend")
    assert str(path) in err and words in err


# --- simulate's numbers ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("option", "value", "words"),
    [
        ("--rate", "inf", "--rate must be in [0.1, 1000] Hz"),
        ("--rate", "0", "--rate must be in [0.1, 1000] Hz"),
        ("--duration", "inf", "--duration must be in [0.1, 3600] s"),
        ("--duration", "1e7", "--duration must be in [0.1, 3600] s"),
        ("--noise", "inf", "--noise must be in [0, 1] m"),
        ("--noise", "-0.01", "--noise must be in [0, 1] m"),
        ("--noise", "nan", "--noise must be in [0, 1] m"),
        ("--seed", "-1", "--seed must be in"),
        ("--robots", "100000", "--robots must be in [1, 100]"),
        ("--beams", "1000000", "--beams must be in [2, 100000] beams, got 1e+06"),
        ("--beams", "1", "--beams must be in [2, 100000] beams, got 1"),
    ],
)
def test_simulate_refuses_numbers_outside_their_range(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, option: str, value: str, words: str
) -> None:
    out = tmp_path / "bag"
    args = ["simulate", "--robots", "1", "--out", out, option, value]
    code, _, err = mrm(capsys, *args)
    assert code == 2
    one_line_error(err, "simulate")
    assert words in err
    assert not out.exists()


def _numeric_options() -> list[tuple[str, str, object]]:
    """(command, option dest, default) of every option of every mrm command that takes a
    number."""
    import argparse

    from multi_robot_mapper.cli.main import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return [
        (command, action.dest, action.default)
        for command, parser in commands.choices.items()
        for action in parser._actions
        if action.type in (int, float)
    ]


def test_every_cli_number_has_one_declared_range() -> None:
    from multi_robot_mapper.cli.common import CLI_LIMITS

    options = _numeric_options()
    assert {"speed", "beams", "seed", "duration"} <= {dest for _, dest, _ in options}
    for command, dest, default in options:
        assert dest in CLI_LIMITS, f"mrm {command} --{dest} has no range in CLI_LIMITS"
        low, high, _ = CLI_LIMITS[dest]
        assert default is None or low <= default <= high, (command, dest)  # type: ignore[operator]


@pytest.mark.parametrize("value", ["0", "-1", "0.005", "inf", "nan", "101"])
def test_demo_refuses_a_speed_outside_its_range_before_any_work(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    value: str,
) -> None:
    _forbid(monkeypatch, "multi_robot_mapper.cli.demo.run_demo")
    code, _, err = mrm(capsys, "demo", "--out", tmp_path / "demo", "--speed", value)
    assert code == 2
    one_line_error(err, "demo")
    assert f"--speed must be in [0.01, 100] times real time, got {float(value):g}" in err
    assert not (tmp_path / "demo").exists()


def test_simulate_refuses_a_run_too_large_to_hold(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    args = ("--robots", 100, "--rate", 1000, "--duration", 3600, "--beams", 1081)
    code, _, err = mrm(capsys, "simulate", "--out", tmp_path / "b", *args)
    assert code == 2 and "readings" in err
    one_line_error(err, "simulate")


# --- outputs ---------------------------------------------------------------------------------


def _forbid(monkeypatch: pytest.MonkeyPatch, target: str) -> None:
    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError(f"{target} ran although the output could not be written")

    monkeypatch.setattr(target, fail)


def test_unwritable_out_is_found_before_any_work(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    small_bag: Path,
) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    # cli.demo imports simulate_robots by name: imported (by forbidding its run_demo) before
    # core's is forbidden, or it would keep the forbidden one after this test.
    _forbid(monkeypatch, "multi_robot_mapper.cli.demo.run_demo")
    _forbid(monkeypatch, "multi_robot_mapper.core.pipeline.run_offline")
    _forbid(monkeypatch, "multi_robot_mapper.core.simulation.simulate_robots")
    _forbid(monkeypatch, "multi_robot_mapper.cli.simulate.simulate_robots")
    cases = {
        "replay": ("replay", small_bag, "--out", blocker / "out", "--method", "reference"),
        "simulate": ("simulate", "--robots", 1, "--out", blocker / "bag"),
        "demo": ("demo", "--out", blocker / "demo"),
    }
    for command, args in cases.items():
        code, _, err = mrm(capsys, *args)
        assert code == 2, (command, err)
        one_line_error(err, command)
        assert "cannot create" in err and str(blocker) in err


def test_evaluate_finds_an_unwritable_metrics_file_before_the_work(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    small_bag: Path,
) -> None:
    out = tmp_path / "ref"
    assert mrm(capsys, "replay", small_bag, "--out", out, "--method", "reference")[0] == 0
    (out / "metrics.json").mkdir()  # something that cannot be replaced by a file
    _forbid(monkeypatch, "multi_robot_mapper.cli.evaluate.evaluate")
    code, _, err = mrm(capsys, "evaluate", out, "--bag", small_bag)
    assert code == 2
    one_line_error(err, "evaluate")
    assert "metrics.json is a folder" in err


def test_replay_never_mixes_two_runs_in_one_folder(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    four, three = tmp_path / "four", tmp_path / "three"
    assert (
        mrm(capsys, "simulate", "--robots", 4, "--out", four, "--duration", 1, "--rate", 5)[0] == 0
    )
    assert (
        mrm(capsys, "simulate", "--robots", 3, "--out", three, "--duration", 1, "--rate", 5)[0] == 0
    )
    out = tmp_path / "out"
    assert mrm(capsys, "replay", four, "--out", out, "--method", "reference")[0] == 0
    assert (out / "trajectories" / "robot4.tum").is_file()
    code, _, err = mrm(capsys, "replay", three, "--out", out, "--method", "reference")
    assert code == 2 and "--overwrite" in err
    one_line_error(err, "replay")
    code, _, err = mrm(
        capsys, "replay", three, "--out", out, "--method", "reference", "--overwrite"
    )
    assert code == 0, err
    assert sorted(p.name for p in (out / "trajectories").iterdir()) == [
        "robot1.tum",
        "robot2.tum",
        "robot3.tum",
    ]
    assert json.loads((out / "map.json").read_text())["robots"] == ["robot1", "robot2", "robot3"]
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_an_interrupted_replay_leaves_the_old_result(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    small_bag: Path,
) -> None:
    out = tmp_path / "out"
    assert mrm(capsys, "replay", small_bag, "--out", out, "--method", "reference")[0] == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt  # Ctrl-C while the pictures are written

    monkeypatch.setattr("multi_robot_mapper.io.pictures.save_figure", interrupted)
    args = ("replay", small_bag, "--out", out, "--method", "reference", "--overwrite")
    code, _, err = mrm(capsys, *args)
    assert code == 130 and "interrupted" in err
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no half-written folder left


def test_an_interrupted_bag_write_leaves_nothing_and_a_rerun_works(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from rosbags.rosbag2 import Writer

    original = Writer.write
    written = []

    def write_then_interrupt(self: Writer, *args: object) -> None:
        original(self, *args)
        written.append(1)
        if len(written) == 20:
            raise KeyboardInterrupt  # SIGINT in the middle of the bag

    monkeypatch.setattr(Writer, "write", write_then_interrupt)
    out = tmp_path / "bag"
    code, _, err = mrm(capsys, "simulate", "--robots", 2, "--out", out, "--duration", 2)
    assert code == 130 and len(written) == 20
    assert list(tmp_path.iterdir()) == []  # neither the bag nor a half of it
    monkeypatch.setattr(Writer, "write", original)
    code, _, err = mrm(capsys, "simulate", "--robots", 2, "--out", out, "--duration", 2)
    assert code == 0, err


def _cpu_seconds(pid: int) -> float:
    """User and system CPU time a running process has used (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_simulate_killed_by_a_signal_exits_cleanly_and_can_run_again(
    tmp_path: Path, signum: int
) -> None:
    out = tmp_path / "bag"
    command = [sys.executable, "-m", "multi_robot_mapper.cli.main", "simulate", "--robots", "3"]
    command += ["--out", str(out), "--duration", "600", "--rate", "40"]
    # The signal must come in the middle of the work, after the imports. Judged by the CPU
    # time the process has used, not by the clock: on a busy machine a wait of twice the
    # imports' wall time let the whole work (about 40 CPU seconds) finish first.
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-c", "import multi_robot_mapper.cli.main"], check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    importing = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    # As from a terminal: a test run started in the background (`make test &`) ignores
    # SIGINT, and its children inherit that (the work then finished: exit 0).
    process = subprocess.Popen(
        command,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 300.0
    while _cpu_seconds(process.pid) < 2.0 * importing + 1.0:
        assert process.poll() is None and time.monotonic() < deadline, process.returncode
        time.sleep(0.05)
    process.send_signal(signum)
    _, err = process.communicate(timeout=60)
    assert process.returncode == (130 if signum == signal.SIGINT else 143), err
    assert "Traceback" not in err and "nothing half-written" in err
    assert list(tmp_path.iterdir()) == []
    rerun = subprocess.run([*command[:-4], "--duration", "1", "--rate", "5"], cwd=tmp_path)
    assert rerun.returncode == 0 and (out / "metadata.yaml").is_file()


def _quick_demo(monkeypatch: pytest.MonkeyPatch) -> None:
    """``mrm demo`` without its expensive parts: 1 s per robot instead of 20, and instead of
    playing live to the nodes, the merger's saved map as a stub and the truth as the result
    (every robot merged). Simulating, writing the bag and the result, scoring and drawing are
    the demo's own."""
    import dataclasses

    import numpy as np

    from multi_robot_mapper.cli import demo
    from multi_robot_mapper.core.worlds import WORLDS
    from multi_robot_mapper.io.results import ReplayResult
    from multi_robot_mapper.ros.live import PlayStats

    recorded: dict[str, object] = {}
    simulate = demo.simulate_scenario

    def short(scenario: demo.DemoScenario) -> object:
        recorded.update(simulate(dataclasses.replace(scenario, duration=1.0, stagger=0.5)))
        return recorded

    def played(
        recordings: dict, scenario: object, saved_map: Path, logs: object, record: Path
    ) -> object:
        atomic_write_text(saved_map, json.dumps({"seed": len(recorded)}))
        atomic_write_text(record, "an MCAP file")
        observer = type("Observer", (), {"diagnostics": {}})()
        sent = {r: len(rec.scans) for r, rec in recordings.items()}
        return demo.LiveOutcome(observer, PlayStats(sent, [], 1.0), 0.0, sent, True, {})

    def truth(observer: object) -> ReplayResult:
        robots = sorted(recorded)
        paths = {}
        for robot in robots:
            poses = recorded[robot].ground_truth  # type: ignore[attr-defined]
            paths[robot] = (np.array([p.stamp for p in poses]), np.array([p.pose for p in poses]))
        walls = WORLDS["office"]()
        owners = np.zeros(len(walls), dtype=np.int64)
        frames = {r: (0.0, 0.0, 0.0) for r in robots}
        return ReplayResult("truth", robots, walls, owners, paths, frames, {})

    def drawn(out_dir: Path, *args: object) -> dict[str, Path]:
        atomic_write_text(out_dir / "global_map.png", "a picture")
        return {"global map": out_dir / "global_map.png"}

    monkeypatch.setattr(demo, "simulate_scenario", short)
    monkeypatch.setattr(demo, "play_live", played)
    monkeypatch.setattr(demo, "live_results", truth)
    monkeypatch.setattr(demo, "draw_demo", drawn)


def _contents(folder: Path) -> dict[Path, bytes]:
    return {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_an_interrupted_demo_leaves_the_old_outputs_and_a_rerun_replaces_them(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from multi_robot_mapper.cli import demo

    _quick_demo(monkeypatch)
    out = tmp_path / "demo"
    out.mkdir()
    (out / "notes.txt").write_text("the user's own file")  # --out is shared: kept
    code, _, err = mrm(capsys, "demo", "--out", out, "--seed", 0)
    assert code == 0, err
    before = _contents(out)
    assert {"bag/metadata.yaml", "result/metrics.json", "saved_map.json"} <= {
        str(p) for p in before
    }

    # Ctrl-C while the nodes map (the new bag, of another seed, already written), and while
    # the pictures are drawn (bag, result, metrics and saved map all new by then): the old
    # outputs stay, byte for byte, and nothing half-made is left beside them.
    def interrupt(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    for stage in ("play_live", "draw_demo"):
        with monkeypatch.context() as patch:
            patch.setattr(demo, stage, interrupt)
            code, _, err = mrm(capsys, "demo", "--out", out, "--seed", 1)
        assert code == 130 and "nothing half-written" in err, (stage, err)
        assert _contents(out) == before, stage
        assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == [], stage
    # Run to the end, the new outputs replace the old ones; the user's file is kept.
    code, _, err = mrm(capsys, "demo", "--out", out, "--seed", 1)
    assert code == 0, err
    after = _contents(out)
    assert set(after) == set(before) and after[Path("notes.txt")] == before[Path("notes.txt")]
    for name in ("bag", "result"):  # another seed: other scans, other paths
        assert {p: b for p, b in after.items() if p.parts[0] == name} != {
            p: b for p, b in before.items() if p.parts[0] == name
        }, name
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []


def test_atomic_outputs_keep_the_old_file_or_folder_when_interrupted(tmp_path: Path) -> None:
    path = tmp_path / "x.json"
    atomic_write_text(path, "old")
    with pytest.raises(KeyboardInterrupt), staged_folder(tmp_path / "folder") as staging:
        (staging / "half").write_text("...")
        raise KeyboardInterrupt
    assert not (tmp_path / "folder").exists()
    from multi_robot_mapper.io.outputs import atomic_file

    with pytest.raises(RuntimeError), atomic_file(path) as stream:
        stream.write("new but cut")
        raise RuntimeError
    assert path.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]
    assert oct(path.stat().st_mode & 0o777) == oct(0o644)
