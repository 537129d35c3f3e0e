"""The house limits on the package's source: classes, functions and signatures.

No class over 600 lines of code, no function over 60, no signature over 12 parameters
(docstrings, comments and blank lines aside; ``self``/``cls`` not counted), no function
above complexity 15 as radon counts it (each boolean operator and comprehension counts,
which ruff's C901 does not: ruff's check let 16 and 20 through). The statement count is
ruff's PLR0915 (pyproject.toml). The SDK core stays under 10,000 lines of code and
``tmmaster.aio`` under 400, counted the same way.

What is over a limit today is listed in ``KNOWN`` with its size: the test fails when
anything else goes over, and when a listed one shrinks back under (take it off the
list) or grows (the list is a ceiling, never a licence).
"""

from __future__ import annotations

import ast
import bisect
import collections
import functools
import io
import tokenize
from pathlib import Path

from source_trees import source

SRC = Path(__file__).resolve().parents[1] / "src" / "tmmaster"

CLASS_LINES = 600
FUNCTION_LINES = 60
PARAMETERS = 12
COMPLEXITY = 15
#: Lines of code (as the class limit counts them) of the SDK core: every module outside
#: the simulator, the TMscript interpreter, the pick & place package and the report
#: command, ``tmmaster.aio`` included; and of ``tmmaster.aio`` alone (derived from the
#: sync API, not copied: docs/architecture.md).
CORE_LINES = 10_000
AIO_LINES = 400
#: The packages that are not the core.
NOT_CORE = ("sim", "tmscript", "pickplace", "report")

#: Over a limit today: (kind, "module:name") -> its size now.
KNOWN: dict[tuple[str, str], int] = {}


#: Where a class or a function can be defined: a ``def`` or ``class`` is a statement,
#: never part of an expression.
_STATEMENTS = ast.stmt | ast.excepthandler | ast.match_case

_NOT_CODE = frozenset(
    {
        tokenize.COMMENT,
        tokenize.NL,
        tokenize.NEWLINE,
        tokenize.INDENT,
        tokenize.DEDENT,
        tokenize.ENDMARKER,
    }
)

Definition = ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef


def _definitions(tree: ast.Module) -> list[Definition]:
    """Every class and function of ``tree``, nested ones too, in ``ast.walk``'s order.

    Only statements are walked (the expressions they hold define nothing).
    """
    found: list[Definition] = []
    todo: collections.deque[ast.AST] = collections.deque([tree])
    while todo:
        node = todo.popleft()
        if isinstance(node, Definition):
            found.append(node)
        todo.extend(child for child in ast.iter_child_nodes(node) if isinstance(child, _STATEMENTS))
    return found


def _docstring_lines(nodes: list[ast.AST]) -> set[int]:
    """The lines of the docstrings of ``nodes`` (a module, its classes and functions)."""
    lines: set[int] = set()
    for node in nodes:
        body = getattr(node, "body", None)
        first = body[0] if body else None
        if (
            isinstance(first, ast.Expr)
            and isinstance(first.value, ast.Constant)
            and isinstance(first.value.value, str)
        ):
            lines.update(range(first.lineno, (first.end_lineno or first.lineno) + 1))
    return lines


def _code_lines(text: str, docstrings: set[int]) -> list[int]:
    """Lines holding code, in order: no docstring, comment or blank line."""
    code: set[int] = set()
    for token in tokenize.generate_tokens(io.StringIO(text).readline):
        if token.type not in _NOT_CODE:
            code.update(range(token.start[0], token.end[0] + 1))
    return sorted(code - docstrings)


def _limit(node: Definition) -> int:
    return CLASS_LINES if isinstance(node, ast.ClassDef) else FUNCTION_LINES


def _sources() -> list[tuple[Path, str, ast.Module]]:
    """Every module of the package: its path, text and syntax tree (parsed once per
    process: every test below, and the import graph's, reads the same trees)."""
    return [(path, *source(path)) for path in sorted(SRC.rglob("*.py"))]


def _measure_file(
    path: Path, text: str, tree: ast.Module, over: dict[tuple[str, str], int]
) -> None:
    """Add what in ``path`` (its ``text``, parsed: ``tree``) is over a limit to ``over``."""
    where = path.relative_to(SRC).as_posix()
    definitions = _definitions(tree)
    for node in definitions:
        if isinstance(node, ast.ClassDef):
            continue
        args = node.args
        count = len(args.posonlyargs) + len(args.args) + len(args.kwonlyargs)
        if args.args and args.args[0].arg in ("self", "cls"):
            count -= 1
        if count > PARAMETERS:
            over["params", f"{where}:{node.name}"] = count
    docstrings = _docstring_lines([tree, *definitions])

    def span(node: Definition) -> range:
        return range(node.lineno, (node.end_lineno or node.lineno) + 1)

    # Its lines less its docstrings' bound its code lines: only a definition that this
    # bound puts over its limit needs the file's tokens counted.
    candidates = [
        node
        for node in definitions
        if len(span(node)) - sum(1 for line in docstrings if line in span(node)) > _limit(node)
    ]
    if not candidates:
        return
    code = _code_lines(text, docstrings)
    for node in candidates:
        where_span = span(node)
        size = bisect.bisect_right(code, where_span[-1]) - bisect.bisect_left(code, where_span[0])
        if size > _limit(node):
            kind = "class" if isinstance(node, ast.ClassDef) else "lines"
            over[kind, f"{where}:{node.name}"] = size


@functools.cache
def measure() -> dict[tuple[str, str], int]:
    """Every class, function and signature over its limit: (kind, "module:name") -> size.

    Measured once per process: both tests below read the same source.
    """
    over: dict[tuple[str, str], int] = {}
    for path, text, tree in _sources():
        _measure_file(path, text, tree, over)
    return over


def test_nothing_new_goes_over_the_house_limits() -> None:
    over = measure()
    new = {key: size for key, size in over.items() if key not in KNOWN}
    assert not new, f"over the house limits (split it, or group the options): {new}"


def test_the_known_exceptions_only_shrink() -> None:
    over = measure()
    grown = {key: (KNOWN[key], size) for key, size in over.items() if size > KNOWN.get(key, size)}
    assert not grown, f"grew past its listed size (listed, now): {grown}"
    mended = sorted(set(KNOWN) - set(over))
    assert not mended, f"now within the limits: take them off KNOWN: {mended}"


def test_the_sdk_core_and_its_async_front_stay_under_their_sizes() -> None:
    sizes: collections.Counter[str] = collections.Counter()
    for path, text, tree in _sources():
        part = path.relative_to(SRC).parts
        package = part[0] if len(part) > 1 else "core"
        docstrings = _docstring_lines([tree, *_definitions(tree)])
        sizes[package] += len(_code_lines(text, docstrings))
    core = sum(size for package, size in sizes.items() if package not in NOT_CORE)
    assert core < CORE_LINES, f"the SDK core has {core} lines of code (limit {CORE_LINES})"
    assert sizes["aio"] < AIO_LINES, f"tmmaster.aio has {sizes['aio']} lines of code"


def test_no_function_is_more_complex_than_the_house_limit_by_radon() -> None:
    # The test extra's; radon measures the limit. cc_visit(text) is cc_visit_ast of
    # ast.parse(text): the tree already parsed is the same.
    from radon.complexity import cc_visit_ast

    over = {}
    for path, _text, tree in _sources():
        todo = list(cc_visit_ast(tree))
        while todo:
            block = todo.pop()
            todo += getattr(block, "methods", []) + getattr(block, "closures", [])
            if not hasattr(block, "methods") and block.complexity > COMPLEXITY:
                over[f"{path.relative_to(SRC)}:{block.fullname}"] = block.complexity
    assert not over, f"above complexity {COMPLEXITY} (split it): {over}"
