"""Every module imports, the package's import graph has no cycles, and the simulator is a plugin.

Type-only imports (under ``if TYPE_CHECKING:``) count too: a cycle there is still two
modules that each need the other to be understood. Imports inside functions count as
well (a lazy import is still a dependency).

The simulator (``tmmaster.sim``) is a plugin of the core: no module outside it imports it
when it is imported; a function may, where the user asked for the simulator
(``pickplace --sim``, the ``tmmaster sim`` command).
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

import pytest

import tmmaster
from source_trees import source

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


#: Where an import can be: ``import`` is a statement, never part of an expression, so the
#: walks below go through statements only (an expression holds none).
_STATEMENTS = ast.stmt | ast.excepthandler | ast.match_case


def _statements(tree: ast.AST) -> list[ast.AST]:
    """``tree`` and every statement in it, at any depth (in functions and classes too)."""
    found: list[ast.AST] = []
    todo = [tree]
    while todo:
        node = todo.pop()
        found.append(node)
        todo.extend(child for child in ast.iter_child_nodes(node) if isinstance(child, _STATEMENTS))
    return found


def _tree(path: Path) -> ast.Module:
    """The module's syntax tree, parsed once per process (several tests, and the house
    limits', read it)."""
    return source(path)[1]


def _imports(module: str, path: Path, *, at_import: bool = False) -> set[str]:
    """Modules of this package that ``module`` imports, at any depth of its code.

    ``at_import``: only the imports that run when ``module`` is imported (none inside a
    function or under ``if TYPE_CHECKING:``).
    """
    tree = _tree(path)
    is_package = path.name == "__init__.py"
    targets: set[str] = set()
    for node in _executed_at_import(tree) if at_import else _statements(tree):
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


def _is_type_checking(node: ast.AST) -> bool:
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _executed_at_import(tree: ast.AST) -> list[ast.AST]:
    """The statements of ``tree`` run when the module is imported: not inside a function,
    nor under ``if TYPE_CHECKING:`` (its ``else`` runs). Statements only, as in
    :func:`_statements` (a lambda, an expression, holds none)."""
    found: list[ast.AST] = []
    todo = [tree]
    while todo:
        node = todo.pop()
        found.append(node)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        if _is_type_checking(node):
            assert isinstance(node, ast.If)
            todo.extend(node.orelse)
            continue
        todo.extend(child for child in ast.iter_child_nodes(node) if isinstance(child, _STATEMENTS))
    return found


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


def test_no_module_outside_the_simulator_imports_it_when_imported() -> None:
    # The core, the commands and the report run against a real robot without loading the
    # simulator; only a function the user reaches by asking for it imports it.
    reaching = {
        module: sorted(edge for edge in edges if edge.startswith("tmmaster.sim"))
        for module, path in MODULES.items()
        if module != "tmmaster.sim" and not module.startswith("tmmaster.sim.")
        for edges in [_imports(module, path, at_import=True)]
    }
    assert {m: e for m, e in reaching.items() if e} == {}


def test_imports_at_import_time_skip_functions_and_type_only_blocks() -> None:
    tree = ast.parse(
        "import a\n"
        "if TYPE_CHECKING:\n    import b\nelse:\n    import c\n"
        "def f():\n    import d\n"
        "class K:\n    import e\n"
    )
    found = {
        alias.name
        for node in _executed_at_import(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    }
    assert found == {"a", "c", "e"}
    # pickplace's --sim path imports the simulator inside its functions: an edge, not
    # an import at import time.
    path = MODULES["tmmaster.pickplace.__main__"]
    edges = _imports("tmmaster.pickplace.__main__", path)
    at_import = _imports("tmmaster.pickplace.__main__", path, at_import=True)
    assert "tmmaster.sim" in edges
    assert not any(edge.startswith("tmmaster.sim") for edge in at_import)


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
