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
    return {module: _imports(module, path) for module, path in MODULES.items()}


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
    cycles = _cycles(_graph())
    assert cycles == [], f"import cycles (type-only imports count): {cycles}"


def test_type_only_and_function_level_imports_are_edges() -> None:
    # _exceptions.py imports Pose only under ``if TYPE_CHECKING:``.
    assert "tmmaster._pose" in _imports("tmmaster._exceptions", MODULES["tmmaster._exceptions"])
    # _simulator.py imports the MuJoCo backend inside a function.
    assert "tmmaster.sim._mujoco" in _imports(
        "tmmaster.sim._simulator", MODULES["tmmaster.sim._simulator"]
    )
    # ``from . import _kinematics`` is the submodule, not the package.
    edges = _imports("tmmaster._robot_models", MODULES["tmmaster._robot_models"])
    assert "tmmaster._kinematics" in edges
    assert "tmmaster" not in edges


def test_the_cycle_finder_finds_cycles() -> None:
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []
