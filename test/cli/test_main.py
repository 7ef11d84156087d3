"""The first hour of a new user: ``mrm``'s help, its messages for the usual mistakes, Ctrl-C.
``mrm replay`` and ``--record``: `test_replay.py`; ``mrm evaluate``: `test_evaluate.py`."""

from __future__ import annotations

import argparse
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from multi_robot_mapper.cli.main import build_parser, main


def mrm(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def parsers() -> dict[str, argparse.ArgumentParser]:
    top = build_parser()
    found = {"mrm": top}
    for action in top._actions:
        if isinstance(action, argparse._SubParsersAction):
            found.update({f"mrm {n}": p for n, p in action.choices.items()})
    return found


def test_every_option_has_help_that_says_its_default() -> None:
    for name, parser in parsers().items():
        formatter = parser._get_formatter()
        for action in parser._actions:
            if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            what = f"{name} {'/'.join(action.option_strings) or action.dest}"
            assert action.help, f"{what} has no help"
            text = formatter._expand_help(action) if action.help else ""
            flag = action.nargs == 0  # store_true: off unless given
            if action.option_strings and not action.required and not flag:
                assert "default" in text, f"{what}: the help does not say the default: {text!r}"


def test_help_has_no_restructuredtext_and_lists_each_command_once(capsys) -> None:
    for name, parser in parsers().items():
        text = parser.format_help()
        assert "``" not in text and ":func:" not in text and ":mod:" not in text, name
    text = parsers()["mrm"].format_help()
    for command in ("demo", "replay", "evaluate", "simulate", "import-bag", "run"):
        lines = [line for line in text.splitlines() if line.strip().startswith(command + " ")]
        assert len(lines) == 1, (command, lines)
    assert "{demo," not in text  # the choices' braces are not a second list


def test_a_missing_input_has_one_wording(capsys, tmp_path: Path) -> None:
    missing = tmp_path / "nope"
    cases = {
        "bag": ("replay", missing, "--out", tmp_path / "o"),
        "log file": ("import-carmen", missing, "--robots", 2, "--out", tmp_path / "b"),
        "params file": ("run", "--robots", "r1", "--params-file", missing),
    }
    for kind, args in cases.items():
        code, _, err = mrm(capsys, *args)
        assert code == 2 and err.strip().endswith(f"error: no such {kind}: {missing}"), err


def two_robot_bag(capsys, folder: Path, duration: float = 8.0) -> Path:
    bag = folder / "sim"
    args = ("--robots", 2, "--out", bag, "--duration", duration, "--rate", 10, "--seed", 3)
    assert mrm(capsys, "simulate", *args)[0] == 0
    return bag


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / 100.0  # utime + stime, in clock ticks


@pytest.mark.parametrize("moment", ["importing", "mapping"])
def test_ctrl_c_at_any_moment_is_one_line_and_exit_130(tmp_path: Path, moment: str, capsys) -> None:
    bag = two_robot_bag(capsys, tmp_path, duration=20.0)
    command = [sys.executable, "-m", "multi_robot_mapper.cli.main", "replay", str(bag)]
    command += ["--out", str(tmp_path / "out")]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-c", "import multi_robot_mapper.cli.replay"], check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    importing = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    # Judged by the CPU time the process has used, not by the clock (a busy machine): a
    # quarter of the imports in, or well past them.
    threshold = 0.25 * importing if moment == "importing" else 2.0 * importing + 1.0
    process = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 300.0
    while _cpu_seconds(process.pid) < threshold:
        assert process.poll() is None and time.monotonic() < deadline, process.returncode
        time.sleep(0.01)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert err.strip().splitlines()[-1] == "mrm replay: interrupted; nothing half-written was left"
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert not (tmp_path / "out").exists()
