"""The layering rule: core never imports rclpy, ROS messages, io, ros or cli; and inside core,
no two parts (subpackages, top-level modules) import each other, even through a third."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

CORE = Path(__file__).resolve().parents[2] / "multi_robot_mapper" / "core"
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


def core_part(module: str) -> str | None:
    """The part of core ``module`` belongs to (``merging`` for
    ``multi_robot_mapper.core.merging.joint``, ``se2`` for ``...core.se2``); None outside core
    and for core itself."""
    prefix = "multi_robot_mapper.core."
    if not module.startswith(prefix):
        return None
    part = module.removeprefix(prefix).split(".")[0]
    return part if (CORE / part).is_dir() or (CORE / f"{part}.py").is_file() else None


def core_import_graph() -> dict[str, set[str]]:
    """Which parts of core each part imports, read statically from the sources."""
    graph: dict[str, set[str]] = {}
    for path in CORE.rglob("*.py"):
        relative = path.relative_to(CORE)
        if relative == Path("__init__.py"):
            continue
        source = relative.parts[0].removesuffix(".py")
        package = ["multi_robot_mapper", "core", *relative.parts[:-1]]
        for node in ast.walk(ast.parse(path.read_text())):
            modules: list[str] = []
            if isinstance(node, ast.Import):
                modules = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = package[: len(package) - node.level + 1] if node.level else []
                module = ".".join([*base, *([node.module] if node.module else [])])
                # ``from multi_robot_mapper.core import se2`` imports the module se2
                modules = [module, *(f"{module}.{a.name}" for a in node.names)]
            targets = {core_part(m) for m in modules} - {None, source}
            graph.setdefault(source, set()).update(t for t in targets if t is not None)
    return graph


def a_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` (its nodes in order, the first repeated at the end), or None."""
    done: set[str] = set()

    def walk(node: str, path: list[str]) -> list[str] | None:
        if node in path:
            return [*path[path.index(node) :], node]
        if node in done:
            return None
        for successor in sorted(graph.get(node, ())):
            cycle = walk(successor, [*path, node])
            if cycle:
                return cycle
        done.add(node)
        return None

    return next((c for n in sorted(graph) if (c := walk(n, [])) is not None), None)


def test_the_parts_of_core_import_each_other_in_one_direction_only() -> None:
    graph = core_import_graph()
    # The parser must see core's real imports: merging is built on the others.
    assert {"local_mapping", "matching"} <= graph["merging"]
    cycle = a_cycle(graph)
    assert cycle is None, f"core imports in a cycle: {' -> '.join(cycle or [])}"


def test_the_cycle_check_finds_a_cycle_through_a_third_part() -> None:
    assert a_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert a_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None
