"""Issue 49's counts of the package's interior, as the issue counted them when it was filed.

    .venv/bin/python -m bench.code_counts

Printed: definitions of ``Pose``; ``lines_of(`` calls; bytes-keyed caches (``lru_cache`` and
``tobytes()`` in core); module-level mutable state (:func:`mutable_globals`, which
``test/cross/test_module_state.py`` also asserts empty); core functions taking a whole
``*Config``; config dataclass fields and each node's YAML keys; core functions over 60 lines
and modules over 600; source modules with a ``test_<module>.py`` of their own at the mirrored path.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "multi_robot_mapper"

# Calls that build a mutable container.
MUTABLE_CALLS = {"list", "dict", "set", "bytearray", "defaultdict", "OrderedDict", "deque"}
MUTABLE_CALLS |= {"Counter"}
MUTABLE_DISPLAYS = (ast.List, ast.Dict, ast.Set, ast.ListComp, ast.DictComp, ast.SetComp)


def _called(value: ast.expr) -> str:
    if not isinstance(value, ast.Call):
        return ""
    func = value.func
    return func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")


def mutable_globals(source: str) -> list[str]:
    """The module-level names of ``source`` bound to a mutable container (``__all__`` aside),
    and the names a function rebinds with ``global``."""
    tree = ast.parse(source)
    found = []
    for node in tree.body:
        if isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            targets, value = [node.target], node.value
        else:
            continue
        names = [t.id for t in targets if isinstance(t, ast.Name) and t.id != "__all__"]
        if names and (isinstance(value, MUTABLE_DISPLAYS) or _called(value) in MUTABLE_CALLS):
            found += [f"{name} (line {node.lineno})" for name in names]
    for node in ast.walk(tree):
        if isinstance(node, ast.Global):
            found += [f"global {name} (line {node.lineno})" for name in node.names]
    return found


def _functions(tree: ast.AST) -> list[ast.FunctionDef | ast.AsyncFunctionDef]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]


def _takes_config(function: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    arguments = function.args.args + function.args.kwonlyargs
    annotations = [ast.unparse(a.annotation) for a in arguments if a.annotation is not None]
    return any(re.search(r"\w+Config\b", text) for text in annotations)


def _config_fields(tree: ast.AST) -> int:
    classes = [n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)]
    return sum(
        sum(isinstance(item, ast.AnnAssign) for item in c.body)
        for c in classes
        if c.name.endswith("Config")
    )


def _yaml_keys(path: Path) -> int:
    def count(node: object) -> int:
        if isinstance(node, dict):
            return sum(count(v) for v in node.values())
        return 1

    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    return count(next(iter(data.values()))["ros__parameters"])


def counts() -> dict[str, object]:
    """Every count, by name."""
    modules = sorted(PACKAGE.rglob("*.py"))
    sources = {path: path.read_text(encoding="utf-8") for path in modules}
    trees = {path: ast.parse(text) for path, text in sources.items()}
    core = [p for p in modules if "core" in p.relative_to(PACKAGE).parts]
    # A module's own test file at its mirrored path: core/merging/joint.py's is
    # test/core/merging/test_joint.py (issue 49 item 7).
    own_tests = [
        p
        for p in modules
        if p.name != "__init__.py"
        and (REPO / "test" / p.parent.relative_to(PACKAGE) / f"test_{p.name}").is_file()
    ]
    pose = re.compile(r"^Pose\s*(:\s*\w+\s*)?=", re.MULTILINE)
    return {
        "Pose definitions": sum(len(pose.findall(text)) for text in sources.values()),
        "lines_of( calls": sum(text.count("lines_of(") for text in sources.values()),
        "lru_cache / tobytes() in core": sum(
            sources[p].count("lru_cache") + sources[p].count("tobytes()") for p in core
        ),
        "module-level mutable state": {
            str(p.relative_to(PACKAGE)): found
            for p in modules
            if (found := mutable_globals(sources[p]))
        },
        "core functions taking a whole *Config": sum(
            _takes_config(f) for p in core for f in _functions(trees[p])
        ),
        "config fields": sum(_config_fields(trees[p]) for p in modules),
        "YAML keys per node": {
            p.name: _yaml_keys(p) for p in sorted((REPO / "config").glob("*.yaml"))
        },
        "core functions over 60 lines": [
            f"{p.relative_to(PACKAGE)}:{f.name}"
            for p in core
            for f in _functions(trees[p])
            if (f.end_lineno or f.lineno) - f.lineno + 1 > 60
        ],
        "modules over 600 lines": [
            str(p.relative_to(PACKAGE)) for p in modules if sources[p].count("\n") > 600
        ],
        "source modules with their own test/<path>/test_<module>.py": (
            f"{len(own_tests)} of {sum(p.name != '__init__.py' for p in modules)}"
        ),
    }


def main() -> None:
    for name, value in counts().items():
        print(f"{name}: {value}")


if __name__ == "__main__":
    main()
