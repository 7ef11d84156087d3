"""Ctrl-C at random moments of an ``mrm replay``: how often it does not end with one line and
exit code 130 (issue 48's "Ctrl-C at any moment").

``.venv/bin/python -m bench.ctrl_c_probe --runs 40 --cpu 0.05 1.5``: a simulated two-robot
bag (20 s, seed 3), then RUNS replays, each sent SIGINT once it has used a random CPU time in
the range given (seconds; the imports take about 1 s of CPU): judged by CPU, not by the clock,
so a busy machine moves nothing. Prints each wrong run (exit code, stderr's tail) and the count.
"""

from __future__ import annotations

import argparse
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.harness import REPO


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / 100.0  # utime + stime, in clock ticks


def interrupted_replay(bag: Path, out: Path, cpu: float) -> tuple[int, str]:
    """One replay sent SIGINT after ``cpu`` seconds of CPU: its exit code and stderr."""
    shutil.rmtree(out, ignore_errors=True)
    command = [sys.executable, "-m", "multi_robot_mapper.cli.main", "replay", str(bag)]
    process = subprocess.Popen(
        [*command, "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    while process.poll() is None and cpu_seconds(process.pid) < cpu:
        time.sleep(0.005)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=300)
    return process.returncode, err


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=40, help="replays to interrupt")
    parser.add_argument("--cpu", type=float, nargs=2, default=(0.05, 1.5), help="CPU s range")
    parser.add_argument("--seed", type=int, default=0, help="seed of the moments drawn")
    args = parser.parse_args()
    draw = random.Random(args.seed)
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / "sim"
        simulate = [sys.executable, "-m", "multi_robot_mapper.cli.main", "simulate"]
        simulate += ["--robots", "2", "--out", str(bag), "--duration", "20", "--seed", "3"]
        subprocess.run(simulate, check=True, capture_output=True, cwd=REPO)
        wrong = 0
        for run in range(args.runs):
            cpu = draw.uniform(*args.cpu)
            code, err = interrupted_replay(bag, Path(folder) / "out", cpu)
            last = err.strip().splitlines()[-1:] or [""]
            if code != 130 or "Traceback" in err or "interrupted" not in last[0]:
                wrong += 1
                print(f"run {run} at {cpu:.3f} s CPU: exit {code}\n{err[-1500:]}")
        print(f"{wrong} of {args.runs} interrupted replays did not end with one line and exit 130")
    return 0


if __name__ == "__main__":
    sys.exit(main())
