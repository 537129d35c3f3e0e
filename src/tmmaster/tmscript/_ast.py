"""The TMscript syntax tree: frozen, typed nodes, each with the line and column it starts at.

Built by :mod:`._parser` from lark's parse tree, in the manner of CPython's :mod:`ast`:
expressions and statements are separate node families, and nothing here evaluates.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "ArrayLiteral",
    "Assign",
    "Binary",
    "Block",
    "Break",
    "Call",
    "Case",
    "Cast",
    "ClassDeclaration",
    "Continue",
    "Declaration",
    "DoWhile",
    "Expr",
    "ExprStatement",
    "For",
    "FunctionDef",
    "If",
    "IncDec",
    "Index",
    "Literal",
    "Logic",
    "MethodCall",
    "Name",
    "Node",
    "Param",
    "Return",
    "Script",
    "Statement",
    "Switch",
    "Ternary",
    "TypeSpec",
    "Unary",
    "While",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class Node:
    """A node of the tree: where it starts in the source (1-based line and column)."""

    line: int
    column: int


@dataclass(frozen=True, slots=True, kw_only=True)
class TypeSpec(Node):
    """A type as written: ``int``, ``float[]``, ``void``..."""

    base: str
    array: bool = False

    def __str__(self) -> str:
        return self.base + ("[]" if self.array else "")


# ---- expressions -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class Expr(Node):
    """Base class of expressions."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Name(Expr):
    """A variable (or, when no variable has that name, a bare word: TMscript 2.24 §2.2)."""

    name: str


@dataclass(frozen=True, slots=True, kw_only=True)
class Literal(Expr):
    """A number, string or boolean constant; ``type`` is the TMscript type it has (§2.2)."""

    value: int | float | bool | str
    type: str
    #: A hexadecimal or binary constant as written (``0xFFFFFFFF``); empty for the others.
    written: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class ArrayLiteral(Expr):
    """``{a, b, c}`` (TMscript 2.24 §2.3)."""

    items: tuple[Expr, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class Unary(Expr):
    """``-x``, ``+x``, ``!x``, ``~x``."""

    op: str
    operand: Expr


@dataclass(frozen=True, slots=True, kw_only=True)
class Binary(Expr):
    """Arithmetic, shift, comparison and bitwise operators."""

    op: str
    left: Expr
    right: Expr


@dataclass(frozen=True, slots=True, kw_only=True)
class Logic(Expr):
    """``&&`` and ``||``: the right side is evaluated only when needed."""

    op: str
    left: Expr
    right: Expr


@dataclass(frozen=True, slots=True, kw_only=True)
class Ternary(Expr):
    """``c ? a : b``."""

    condition: Expr
    then: Expr
    otherwise: Expr


@dataclass(frozen=True, slots=True, kw_only=True)
class Assign(Expr):
    """``target = value`` and the compound assignments (``+=`` ...): an expression (§2.4)."""

    op: str
    target: Expr
    value: Expr


@dataclass(frozen=True, slots=True, kw_only=True)
class IncDec(Expr):
    """``i++``, ``i--``, ``++i``, ``--i``."""

    op: str
    target: Expr
    prefix: bool


@dataclass(frozen=True, slots=True, kw_only=True)
class Index(Expr):
    """``array[i]``."""

    target: Expr
    index: Expr


@dataclass(frozen=True, slots=True, kw_only=True)
class Call(Expr):
    """``Name(args)``: a built-in or customized function."""

    name: str
    args: tuple[Expr, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class MethodCall(Expr):
    """``device.Preset(args)``: a member method of a class variable."""

    target: Expr
    method: str
    args: tuple[Expr, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class Cast(Expr):
    """``(int)x``, ``(float[])ss`` (TMscript 2.24 §2.5)."""

    type: TypeSpec
    operand: Expr


# ---- statements ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class Statement(Node):
    """Base class of statements."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Declaration(Statement):
    """``int i = 0``, ``string[] s``."""

    type: TypeSpec
    name: str
    init: Expr | None


@dataclass(frozen=True, slots=True, kw_only=True)
class ClassDeclaration(Statement):
    """``ModbusTCP dev = "127.0.0.1", 502`` (TMscript 2.24 §16.1)."""

    cls: str
    name: str
    args: tuple[Expr, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class ExprStatement(Statement):
    """An expression evaluated for its effect."""

    expr: Expr


@dataclass(frozen=True, slots=True, kw_only=True)
class Break(Statement):
    """``break`` (§3.11.1)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Continue(Statement):
    """``continue`` (§3.11.2)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Return(Statement):
    """``return [value]`` (§3.11.3)."""

    value: Expr | None


@dataclass(frozen=True, slots=True, kw_only=True)
class Block(Statement):
    """``{ ... }``: a scope for the variables declared in it."""

    statements: tuple[Statement, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class If(Statement):
    """``if (c) a else b`` (§3.9.1)."""

    condition: Expr
    then: Statement
    otherwise: Statement | None


@dataclass(frozen=True, slots=True, kw_only=True)
class Case(Node):
    """One ``case`` of a switch: ``op`` is ``"=="`` or a comparison; ``value`` None is default."""

    op: str
    value: Expr | None
    body: tuple[Statement, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class Switch(Statement):
    """``switch (x) { case ... }`` (§3.9.2)."""

    subject: Expr
    cases: tuple[Case, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class For(Statement):
    """``for (init; condition; step) body`` (§3.10.1)."""

    init: Statement | None
    condition: Expr | None
    step: Expr | None
    body: Statement


@dataclass(frozen=True, slots=True, kw_only=True)
class While(Statement):
    """``while (c) body`` (§3.10.2)."""

    condition: Expr
    body: Statement


@dataclass(frozen=True, slots=True, kw_only=True)
class DoWhile(Statement):
    """``do { ... } while (c)`` (§3.10.3)."""

    body: Statement
    condition: Expr


# ---- the project -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class Param(Node):
    """A typed parameter of a customized function."""

    type: TypeSpec
    name: str


@dataclass(frozen=True, slots=True, kw_only=True)
class FunctionDef(Node):
    """A customized function (§3.5)."""

    return_type: TypeSpec
    name: str
    params: tuple[Param, ...]
    body: Block


@dataclass(frozen=True, slots=True, kw_only=True)
class Script(Node):
    """A Script Project: ``define``, ``main``, ``closestop``, ``errorstop`` and functions."""

    define: tuple[Statement, ...]
    main: Block | None
    closestop: Block | None
    errorstop: Block | None
    functions: tuple[FunctionDef, ...]
