"""No module-level mutable state in the package (issue 49): what a mapper or a merger keeps
between calls lives in its own objects, so two of them in one process never share anything.
Tables of constants are read-only (tuples, ``MappingProxyType``); memoised pure functions
(``functools.cache``/``lru_cache``) are allowed, their results depend on the arguments only."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "multi_robot_mapper"

# Calls that build a mutable container.
MUTABLE_CALLS = {
    "list",
    "dict",
    "set",
    "bytearray",
    "defaultdict",
    "OrderedDict",
    "deque",
    "Counter",
}
MUTABLE_DISPLAYS = (ast.List, ast.Dict, ast.Set, ast.ListComp, ast.DictComp, ast.SetComp)


def _called(value: ast.expr) -> str:
    if not isinstance(value, ast.Call):
        return ""
    func = value.func
    return func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")


def mutable_globals(source: str) -> list[str]:
    """The module-level names of ``source`` bound to a mutable container, and the names a
    function rebinds with ``global``."""
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


def test_the_checker_finds_containers_and_global_statements() -> None:
    source = (
        "import collections\nA = {}\nB: list[int] = []\nC = collections.deque()\n"
        "D = (1, 2)\n__all__ = ['D']\ndef f():\n    global D\n"
    )
    assert mutable_globals(source) == [
        "A (line 2)",
        "B (line 3)",
        "C (line 4)",
        "global D (line 8)",
    ]


def test_no_module_of_the_package_keeps_mutable_state() -> None:
    found = {
        str(path.relative_to(PACKAGE)): names
        for path in sorted(PACKAGE.rglob("*.py"))
        if (names := mutable_globals(path.read_text(encoding="utf-8")))
    }
    assert found == {}, f"module-level mutable state: {found}"
