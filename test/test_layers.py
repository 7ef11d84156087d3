"""The layering rule: core never imports rclpy, ROS messages, io, ros or cli."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

CORE = Path(__file__).resolve().parents[1] / "multi_robot_mapper" / "core"
FORBIDDEN = (
    "rclpy",
    "sensor_msgs",
    "visualization_msgs",
    "geometry_msgs",
    "std_msgs",
    "multi_robot_mapper.io",
    "multi_robot_mapper.ros",
    "multi_robot_mapper.cli",
    "matplotlib",
    "yaml",
    "rosbags",
    "mcap",
    "evo",
    "multi_robot_mapper.evaluation",
)


def test_importing_every_core_module_never_loads_rclpy() -> None:
    modules = [
        "multi_robot_mapper.core."
        + ".".join(p.relative_to(CORE).with_suffix("").parts).removesuffix(".__init__")
        for p in CORE.rglob("*.py")
    ]
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}: importlib.import_module(m)\n"
        f"bad = sorted(k for k in sys.modules if k.split('.')[0] in {FORBIDDEN!r} "
        f"or any(k.startswith(f) for f in {FORBIDDEN!r}))\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"core pulled in: {out.stdout.strip()}"


def test_core_sources_import_only_core_numpy_scipy_and_stdlib() -> None:
    for path in CORE.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for name in names:
                assert not name.startswith(FORBIDDEN), f"{path.name} imports {name}"


def imports_of(package: str) -> set[str]:
    names: set[str] = set()
    for path in (CORE.parent / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module)
    return names


def test_io_and_evaluation_never_import_the_ros_or_cli_layers() -> None:
    for package in ("io", "evaluation"):
        bad = {
            name
            for name in imports_of(package)
            if name.startswith(("rclpy", "multi_robot_mapper.ros", "multi_robot_mapper.cli"))
        }
        assert not bad, f"{package} imports {sorted(bad)}"
