"""No module-level mutable state in the package (issue 49): what a mapper or a merger keeps
between calls lives in its own objects, so two of them in one process never share anything.
Tables of constants are read-only (tuples, ``MappingProxyType``); memoised pure functions
(``functools.cache``/``lru_cache``) are allowed, their results depend on the arguments only.
The checker is ``bench/code_counts.py``'s, which counts the rest of issue 49's figures."""

from __future__ import annotations

from bench.code_counts import PACKAGE, mutable_globals


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
