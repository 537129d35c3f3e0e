"""Every module imports, and the package's import graph has no cycles.

Type-only imports (under ``if TYPE_CHECKING:``) count too: a cycle there is still two
modules that each need the other to be understood. Imports inside functions count as
well (a lazy import is still a dependency).
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

import pytest

import tmmaster

PACKAGE = Path(tmmaster.__file__).parent


def _modules() -> dict[str, Path]:
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


MODULES = _modules()


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    """The absolute module a ``from ...name import`` in ``module`` refers to."""
    if level == 0:
        return name or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join([*base, name] if name else base)


def _imports(module: str, path: Path) -> set[str]:
    """Modules of this package that ``module`` imports, at any depth of its code."""
    tree = ast.parse(path.read_text("utf-8"))
    is_package = path.name == "__init__.py"
    targets: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(module, is_package, node.level, node.module)
            for alias in node.names:
                # ``from . import _x`` imports a submodule; ``from .x import Name`` the module x.
                sub = f"{base}.{alias.name}"
                targets.add(sub if sub in MODULES else base)
    edges = set()
    for target in targets:
        # The nearest module of this package that ``target`` names (a name inside a
        # module resolves to the module).
        while target and target not in MODULES:
            target = target.rpartition(".")[0]
        if target and target != module:
            edges.add(target)
    return edges


def _graph() -> dict[str, set[str]]:
    graph = {module: _imports(module, path) for module, path in MODULES.items()}
    # A package's __init__ is where its lazy names are defined: importing ``tmmaster.x``
    # runs ``tmmaster/__init__.py``, but that is not a dependency of the submodule's code.
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(node: str) -> None:
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for succ in sorted(graph.get(node, ())):
            if succ not in index:
                visit(succ)
                low[node] = min(low[node], low[succ])
            elif succ in on_stack:
                low[node] = min(low[node], index[succ])
        if low[node] == index[node]:
            component = []
            while True:
                item = stack.pop()
                on_stack.discard(item)
                component.append(item)
                if item == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


@pytest.mark.parametrize("module", sorted(MODULES))
def test_every_module_imports(module: str) -> None:
    if module.endswith(".__main__"):
        # Importing a __main__ runs the command: check it resolves, and its imports below.
        assert importlib.util.find_spec(module) is not None
        return
    importlib.import_module(module)


def test_the_import_graph_has_no_cycles() -> None:
    graph = _graph()
    # Packages re-export their modules lazily (tmmaster/__init__.py names every module
    # it serves); the modules never import their package back, so edges *into* a
    # package's __init__ from its own modules would be the cycle to report.
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_type_only_cycle() -> None:
    source = "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .b import B\n"
    tree = ast.parse(source)
    assert any(isinstance(n, ast.ImportFrom) for n in ast.walk(tree))
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []
