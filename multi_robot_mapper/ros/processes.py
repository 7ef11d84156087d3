"""Nodes in processes of their own, as ``ros2 run`` starts them (a robot's mapper runs on its
robot): started on one DDS domain, stopped with SIGINT, their CPU time and memory read from
``/proc`` (Linux). ``mrm run``, ``mrm demo`` and ``bench/live_load.py`` run one
``robot_mapper`` process per robot (``mrm run`` the ``map_merger`` in one more) so that the
robots' scans are processed on every core, not under one interpreter lock.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path

_CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _ended_with_parent() -> None:
    """In a child, before its command runs: SIGTERM (a clean shutdown for an rclpy node) when
    the process that started it dies, however it dies. A parent killed with SIGKILL cannot stop
    its children, and a ``robot_mapper`` left running holds its DDS domain. Linux only (prctl);
    elsewhere the children are stopped only by :meth:`NodeProcesses.stop`."""
    import ctypes

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def _new_process_group() -> None:
    """In a child, before its command runs: a process group of its own, so that a terminal's
    Ctrl-C (sent to the whole foreground group) reaches only the parent, which passes exactly
    one SIGINT on. A node that gets a second SIGINT takes it for a shutdown that hangs and
    raises KeyboardInterrupt wherever it is (ros/entry.py), with a traceback."""
    os.setpgid(0, 0)
    _ended_with_parent()


def robot_mapper_command(robot: str, ros_args: Sequence[str] = ()) -> list[str]:
    """The command that runs ``robot_mapper`` in ``/<robot>`` with this interpreter."""
    return [
        sys.executable,
        "-m",
        "multi_robot_mapper.ros.robot_mapper",
        "--ros-args",
        "-r",
        f"__ns:=/{robot}",
        *ros_args,
    ]


def map_merger_command(ros_args: Sequence[str] = ()) -> list[str]:
    """The command that runs ``map_merger`` with this interpreter."""
    return [sys.executable, "-m", "multi_robot_mapper.ros.map_merger", "--ros-args", *ros_args]


class NodeProcesses:
    """Named node processes on one ROS domain (``domain_id``, or the caller's
    ``ROS_DOMAIN_ID`` when None), each in a process group of its own. Their output goes to
    ``log_dir/<name>.log``, to this process's own stdout and stderr with ``inherit_output``,
    else nowhere."""

    def __init__(
        self,
        commands: Mapping[str, Sequence[str]],
        domain_id: int | None,
        log_dir: Path | None = None,
        inherit_output: bool = False,
    ) -> None:
        env = dict(os.environ)
        if domain_id is not None:
            env["ROS_DOMAIN_ID"] = str(domain_id)
        env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated; conflicts with the discovery range
        env["PYTHONUNBUFFERED"] = "1"
        self.logs: dict[str, Path] = {}
        self.processes: dict[str, subprocess.Popen[bytes]] = {}
        try:
            for name, command in commands.items():
                output: int | object | None = None if inherit_output else subprocess.DEVNULL
                if log_dir is not None:
                    log_dir.mkdir(parents=True, exist_ok=True)
                    self.logs[name] = log_dir / f"{name}.log"
                    output = self.logs[name].open("wb")
                self.processes[name] = subprocess.Popen(
                    list(command),
                    env=env,
                    stdout=output,
                    stderr=None if inherit_output and log_dir is None else subprocess.STDOUT,
                    preexec_fn=_new_process_group if sys.platform == "linux" else None,
                )
                if log_dir is not None:
                    output.close()  # type: ignore[attr-defined]  # the child holds its copy
        except BaseException:
            self.stop()
            raise

    @classmethod
    def robot_mappers(
        cls,
        robots: Sequence[str],
        domain_id: int,
        ros_args: Sequence[str] = (),
        log_dir: Path | None = None,
    ) -> NodeProcesses:
        """One ``robot_mapper`` process per robot."""
        return cls(
            {robot: robot_mapper_command(robot, ros_args) for robot in robots}, domain_id, log_dir
        )

    def running(self) -> dict[str, bool]:
        return {name: p.poll() is None for name, p in self.processes.items()}

    def first_exit(self, stop: threading.Event, poll: float = 0.2) -> str | None:
        """Wait until some process exits (its name) or ``stop`` is set (None)."""
        while not stop.wait(poll):
            for name, process in self.processes.items():
                if process.poll() is not None:
                    return name
        return None

    def stop(self, timeout: float = 10.0) -> dict[str, int | None]:
        """SIGINT to every process (a clean shutdown), SIGKILL to those still running after
        ``timeout``; returns the exit codes."""
        for process in self.processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        codes: dict[str, int | None] = {}
        for name, process in self.processes.items():
            try:
                codes[name] = process.wait(timeout)
            except subprocess.TimeoutExpired:
                process.kill()
                codes[name] = process.wait()
        return codes

    def usage(self) -> dict[str, tuple[float, int]]:
        """CPU seconds (user + system) and resident memory (bytes) of each running process."""
        return {
            name: process_usage(p.pid) for name, p in self.processes.items() if p.poll() is None
        }


def process_usage(pid: int) -> tuple[float, int]:
    """CPU seconds (user + system, children included) and resident memory (bytes) of a
    process, from ``/proc/<pid>`` (zeros when it is gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        statm = Path(f"/proc/{pid}/statm").read_text().split()
    except (OSError, IndexError):
        return 0.0, 0
    # Fields after the command: state is [0], utime [11], stime [12], cutime [13], cstime [14].
    ticks = sum(int(v) for v in stat[11:15])
    return ticks / _CLOCK_TICKS, int(statm[1]) * _PAGE
