"""Check a Script Project and run it one bounded step at a time.

The syntax tree is compiled once into closures (:class:`Program`): a variable is a slot in a
list, a type is known before the script runs. Statements run as generators so that an
:class:`Execution` can stop anywhere, a statement budget or a blocking call (``Sleep``,
``WaitFor``, ``WaitQueueTag``, ``Pause``) yielding, and go on at the next :meth:`step`.
Expressions are plain closures unless they call a blocking built-in or a customized
function; only those become generators (the common statement costs one call).
"""

from __future__ import annotations

import dataclasses
import enum
import math
import operator
import time
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import Any, TypeAlias, cast

from .._exceptions import TMMasterError, TMScriptRuntimeError, TMScriptSyntaxError
from . import _ast as a
from ._builtins import (
    BUILTINS,
    UNSUPPORTED,
    Builtin,
    ExitRequest,
    Impl,
    ModbusConfig,
    Runtime,
    int16_array,
    link_device,
    read_registers,
)
from ._host import Host, HostError
from ._parser import parse_script
from ._types import (
    INTEGRAL,
    NUMERIC,
    STRING_MAX,
    ConversionError,
    Value,
    convert,
    default_value,
    display_text,
    element_type,
    fits_f32,
    is_array,
    to_f32,
    truthy,
    wrap32,
)

__all__ = [
    "ExecState",
    "Execution",
    "Program",
    "ScriptWarning",
    "Status",
    "compile_program",
    "parse",
]

#: Longest a closestop or errorstop section runs (TMscript 2.24 §3.3, p. 30).
STOP_SECTION_LIMIT_S = 12.0
#: With a time budget (:meth:`Execution.step`'s ``max_seconds``), the clock is read every
#: this many statements...
CLOCK_EVERY = 8
#: ...and after every statement once a slice of them took this long (wall seconds).
SLOW_SLICE_S = 0.001
#: :meth:`Execution.run_to_end` checks its timeout at least this often (wall seconds,
#: plus the statement running then).
RUN_SLICE_S = 0.05
#: After the timeout, closestop gets this long (wall seconds) before run_to_end raises.
TIMEOUT_CLOSESTOP_S = 0.5

_BUDGET = "budget"
_BLOCKED = "blocked"
_PAUSED = "paused"


class ExecState(enum.StrEnum):
    """Where an :class:`Execution` stands after a :meth:`Execution.step` (compares to str)."""

    RUNNING = "running"  #: the budget ran out; step again
    BLOCKED = "blocked"  #: waiting on the host's clock or state; step again later
    PAUSED = "paused"  #: Pause() was called: :meth:`Execution.resume` continues it
    ENDED = "ended"  #: the project stopped (after closestop, or errorstop for Exit(-1))
    ERROR = "error"  #: the project stopped by an error (:attr:`Execution.error`)


@dataclass(frozen=True)
class Status:
    """What :meth:`Execution.step` reports: the state, and the error that ended the project."""

    #: Where the execution stands.
    state: ExecState
    #: The error that stopped the project (state ERROR), else None.
    error: TMScriptRuntimeError | None = None
    #: The code given to ``Exit()``, if it was called.
    exit_code: int | None = None


class _Frame:
    __slots__ = ("g", "l", "rt")

    def __init__(self, g: list[Value], size: int, rt: _Run) -> None:
        self.g = g
        self.l: list[Value] = [None] * size  # type: ignore[list-item]
        self.rt = rt


class _Run(Runtime):
    """The runtime state one execution shares with every closure.

    The budget of a step: ``budget`` counts down the statements of the current slice;
    when it runs out, :meth:`spent` says whether the step's budget is (statements or
    time) or hands out the next slice. With a time budget a slice is
    :data:`CLOCK_EVERY` statements, one after a slice that took :data:`SLOW_SLICE_S`
    or more: the clock is read often enough that a slow statement overshoots it by
    itself only.
    """

    def __init__(self, host: Host) -> None:
        super().__init__(host)
        #: Threads ThreadRun started, in the order they run (main is not among them).
        self.threads: list[_Thread] = []
        self.budget = 0
        #: The clock of the time budget: wall seconds by default (time.monotonic).
        self.clock: Callable[[], float] = time.monotonic
        self._left = 0  # statements of the step not yet handed out in a slice
        self._deadline = math.inf  # clock() at which the step yields
        self._sliced = 0.0  # clock() when the current slice began

    def start(self, max_statements: int, max_seconds: float | None) -> None:
        """Budget a step: at most ``max_statements`` statements and ``max_seconds``."""
        self.budget = 0
        self._left = max(1, max_statements)
        if max_seconds is None:
            self._deadline = math.inf
        else:
            self._sliced = self.clock()
            self._deadline = self._sliced + max(0.0, max_seconds)

    def spent(self) -> bool:
        """The slice ran out: True when the step's budget is spent, else a new slice."""
        left = self._left
        if left <= 0:
            return True
        size = left
        if self._deadline != math.inf:
            now = self.clock()
            if now >= self._deadline:
                return True
            # min(left, 1 if slow else CLOCK_EVERY), left >= 1, without the call
            if now - self._sliced >= SLOW_SLICE_S:
                size = 1
            elif left > CLOCK_EVERY:
                size = CLOCK_EVERY
            self._sliced = now
        self._left = left - size
        self.budget = size - 1  # the statement that asked is the slice's first
        return False


class _Return:
    __slots__ = ("value",)

    def __init__(self, value: Value) -> None:
        self.value = value


@dataclass
class _Thread:
    """A thread ThreadRun started (TMscript 2.24 §3.12, p. 47)."""

    #: Its ID (main is 1).
    ident: int
    #: The statement it runs.
    gen: Generator[str, None, Any]
    #: It goes on while the project is paused (ThreadRun's bool, §3.12.1).
    nonpause: bool


_BREAK = "break"
_CONTINUE = "continue"
#: The kinds of compiled statement (see :meth:`_Compiler.statement`).
_SIMPLE = "simple"
_EXPR = "expr"
_STATEMENT = "statement"
Control: TypeAlias = str | _Return | None
Gen: TypeAlias = Generator[str, None, Any]
PureFn: TypeAlias = Callable[[_Frame], Value]
GenFn: TypeAlias = Callable[[_Frame], Gen]
StmtFn: TypeAlias = Callable[[_Frame], Generator[str, None, Control]]


@dataclass(frozen=True)
class ScriptWarning:
    """A compile warning: a bare word taken as a string, an integer constant over 32 bits
    taken as a double, a single quote in a string constant (all §2.7, p. 27), an element
    of an expression's result (§2.4)."""

    #: The line, 1-based.
    line: int
    #: The column, 1-based.
    column: int
    #: What was found.
    message: str


@dataclass
class _CExpr:
    fn: Callable[[_Frame], Any]
    type: str
    gen: bool  # fn returns a generator
    #: ``(value,)`` for a constant (what ``fn`` always returns, immutable), else None.
    const: tuple[Any] | None = None
    #: ``modbus_read(device, slave, type, address, count)`` with plain arguments: the
    #: call and its argument values (a ``Byte_ToInt16Array`` of it reads in one step).
    read: tuple[a.Call, Callable[[_Frame], list[Value]]] | None = None
    #: ``fn`` makes a new array at each call, which no variable holds: an assignment
    #: need not copy it.
    fresh: bool = False


def _mapped(ce: _CExpr, fn: Callable[[Any], Any], typ: str) -> _CExpr:
    """``ce`` with ``fn`` applied to its value, of type ``typ`` (pure stays pure)."""
    if not ce.gen:
        pure = cast(PureFn, ce.fn)
        return _CExpr(lambda fr: fn(pure(fr)), typ, False)
    gen = cast(GenFn, ce.fn)

    def mapped_gen(fr: _Frame) -> Gen:
        return fn((yield from gen(fr)))

    return _CExpr(mapped_gen, typ, True)


def _run_statements(steps: tuple[tuple[str, Callable[[_Frame], Any]], ...]) -> StmtFn:
    """The statements ``steps`` (each ``(kind, fn)`` of :meth:`_Compiler.statement`) in turn."""

    def run(fr: _Frame) -> Generator[str, None, Control]:
        rt = fr.rt
        for kind, fn in steps:
            rt.budget -= 1
            if rt.budget < 0 and rt.spent():
                yield _BUDGET
            if kind is _SIMPLE:
                fn(fr)
            elif kind is _EXPR:
                yield from fn(fr)  # a call that may wait: its value is dropped
            else:
                ctl = yield from fn(fr)
                if ctl is not None:
                    return ctl  # type: ignore[no-any-return]
        return None

    return run


def _syntax(node: a.Node, message: str) -> TMScriptSyntaxError:
    return TMScriptSyntaxError(message, line=node.line, column=node.column)


def _byte_range(value: a.Expr, typ: str) -> None:
    """A constant out of its type's range given to a byte, an int or a float is an error
    (TMscript 2.24 §2.2, p. 15: ``byte b = -100`` "mismatches with the value range of
    byte"; TMflow 2.24 appendix J, 0x0004821A-C "Invalid byte / int / float range", "The
    operand in the expression is assigned a number out of range", pp. 482-483), each
    element of an array constant too; a calculation keeps 8 or 32 bits."""
    if isinstance(value, a.ArrayLiteral) and is_array(typ):
        for item in value.items:
            _byte_range(item, element_type(typ))
        return
    if not isinstance(value, a.Literal) or value.type not in ("int", "float", "double"):
        return
    if typ in ("int", "int32") and value.written and int(value.value) < 2**32:
        return  # 0xFFFFFFFF: 32 bits, an int -1 with a warning (_ExprCompiler.literal)
    message = _out_of_range(value.value, typ)
    if message is not None:
        raise _syntax(value, message)


def _no_duplicate_case(node: a.Switch) -> list[ScriptWarning]:
    """Two cases of one switch with the same constant condition (the same comparison, a
    constant of the same type and value) or two defaults are refused: TMflow 2.24 appendix
    J, 0x0004810D "Duplicated switch case condition", "Please remove duplicated switch case
    condition" (p. 365). Constants of two types are two conditions, as .NET's Equals has
    them (``case 1``, ``case true``; ``case 1``, ``case 1.0``): a number equal to an
    earlier case's is a warning, as the earlier case matches first."""
    seen: set[tuple[str, str, Any]] = set()
    numbers: dict[tuple[str, Any], a.Case] = {}
    found: list[ScriptWarning] = []
    for case in node.cases:
        lit = case.value
        if lit is not None and not isinstance(lit, a.Literal):
            continue
        key = ("default", "", None) if lit is None else (case.op, lit.type, lit.value)
        if key in seen:
            raise _syntax(case, "a duplicated switch case condition (TMflow 0x0004810D)")
        seen.add(key)
        if lit is not None and lit.type in _RANK:
            first = numbers.setdefault((case.op, lit.value), case)
            if first is not case:
                cond = lit.value if case.op == "==" else f"{case.op} {lit.value}"
                message = (
                    f"case {cond} is the condition of the case on line {first.line}, "
                    "which matches first: this one never matches"
                )
                found.append(ScriptWarning(case.line, case.column, message))
    return found


def _out_of_range(number: Any, typ: str) -> str | None:
    """Why the constant ``number`` does not fit a ``typ`` (see :func:`_byte_range`), or None."""
    if typ == "float":
        return None if fits_f32(number) else f"{number} is out of a float's range"
    bounds = _INT_RANGE.get({"int32": "int"}.get(typ, typ))
    if bounds is None or not isinstance(number, int) or bounds[0] <= number <= bounds[1]:
        return None
    if typ == "byte":
        return (
            f"{number} is out of a byte's range 0..255 "
            "(§2.2, p. 15: a byte constant must fit; a calculation such as 0 - 100 keeps 8 bits)"
        )
    return (
        f"{number} is out of an {typ}'s range {bounds[0]}..{bounds[1]} "
        "(TMflow 0x0004821B Invalid int range; a calculation keeps 32 bits)"
    )


#: Words a variable may not be named: the Boolean values and the reserved characters
#: (TMscript 2.24 §2.2, pp. 14-16: a name "cannot be a numeric value, a string, or a
#: Boolean value"; empty, newline and NewLine are "reserved characters").
_RESERVED = frozenset({"true", "True", "false", "False", "empty", "newline", "NewLine"})


def _check_name(node: a.Node, name: str) -> None:
    if name in _RESERVED:
        raise _syntax(node, f"{name} is a reserved word, not a variable name (§2.2, pp. 14-16)")


def _lossy(value: a.Expr, source: str, target: str) -> str | None:
    """What TMflow warns of when a value is assigned (TMscript 2.24 §2.7, p. 27), else None:
    a variable's digits lost to a narrower number type (the manual's ``i = f``, ``b = i``,
    ``f = d``; a calculation such as ``0 - 100`` into a byte is not flagged, §2.2 p. 15),
    or a string turned into a number or back."""
    if source in _RANK and target in _RANK:
        if isinstance(value, (a.Name, a.Index)) and _RANK[target] < _RANK[source]:
            return f"{source} to {target}: digits may be lost (§2.7, p. 27)"
    elif "string" in (source, target) and (source in _RANK or target in _RANK):
        return f"{source} to {target}: converted (§2.7, p. 27)"
    return None


#: The integer types' ranges: an integer constant that fits is the type it is returned as.
_INT_RANGE = {"byte": (0, 255), "int16": (-(2**15), 2**15 - 1), "int": (-(2**31), 2**31 - 1)}


def _returned_constant(node: a.Return, ce: _CExpr, target: str) -> Any:
    """The constant ``return`` gives, a 32-bit hexadecimal or binary one to an int as its
    32 bits (0xFFFFFFFF is -1, as in an assignment: see :func:`_byte_range`); else None."""
    lit = node.value
    if isinstance(lit, a.Literal) and lit.written and target == "int" and int(lit.value) < 2**32:
        return wrap32(int(lit.value))
    return ce.const[0] if ce.const is not None else None


def _check_return(node: a.Return, name: str, ce: _CExpr, want: str) -> None:
    """A value of another type than the function's returned: refused where it would
    narrow or change kind ("If the function defines the return type, it must return with
    the same type", TMscript 2.24 §3.5, p. 32; TMflow 2.24 appendix J, 0x00048193 and
    0x0004860C "Please check if return data type and function definition type matched").
    A wider number type (an int returned as a float) and an integer constant that fits
    pass, as in an assignment (0x00048607: "Correct: double = int, float = int, double
    = float")."""
    source, target = ce.type, want
    if "?" in (source, target) or "*" in (source, target) or source == target:
        return
    if is_array(source) and is_array(target):
        source, target = element_type(source), element_type(target)
    if source in _RANK and target in _RANK:
        if _RANK[target] >= _RANK[source]:
            return
        value = _returned_constant(node, ce, target)
        bounds = _INT_RANGE.get({"int32": "int"}.get(target, target))
        if isinstance(value, int) and bounds is not None and bounds[0] <= value <= bounds[1]:
            return
    elif source == target:
        return
    raise _syntax(
        node,
        f"{name}() returns a {want}, not a {ce.type}: a function must return the type it"
        " defines (§3.5, p. 32)",
    )


def _runtime(node: a.Node, message: str) -> TMScriptRuntimeError:
    return TMScriptRuntimeError(message, line=node.line, column=node.column)


def _too_long(node: a.Node, length: int) -> TMScriptRuntimeError:
    """A string over :data:`~._types.STRING_MAX` characters (tmmaster's bound)."""
    return _runtime(node, f"a string holds at most {STRING_MAX} characters, not {length}")


def _capped(node: a.Node, result: Value) -> Value:
    """A built-in's ``result``, refused when it is a string over the cap."""
    if isinstance(result, str) and len(result) > STRING_MAX:
        raise _too_long(node, len(result))
    return result


def _type_name(spec: a.TypeSpec) -> str:
    base = {"int32": "int"}.get(spec.base, spec.base)
    return base + ("[]" if spec.array else "")


def _promote(left: str, right: str) -> str:
    if left in INTEGRAL and right in INTEGRAL:
        return "int"
    if "double" in (left, right):
        return "double"
    return "float"


_NOT_CONSTANT: Any = object()


def _converted_literal(node: a.Expr, conv: Callable[[Value], Value]) -> Any:
    """``conv`` of a literal's value, computed once when the script is compiled.

    ``_NOT_CONSTANT`` for any other expression, and for a literal whose conversion fails:
    that error is the script's at run time, where it reaches the literal.
    """
    if not isinstance(node, a.Literal):
        return _NOT_CONSTANT
    try:
        return conv(node.value)
    except Exception:
        return _NOT_CONSTANT


def _element_type(node: a.ArrayLiteral, types: set[str]) -> str:
    """The element type of an array literal whose elements have ``types``."""
    if not types:
        elem = "?"
    elif types <= NUMERIC:
        elem = "byte" if types == {"byte"} else "int"
        if types & {"float", "double"}:
            elem = "double" if "double" in types else "float"
        elif types - {"byte"}:
            elem = "int"
    elif len(types) == 1:
        elem = next(iter(types))
    else:
        raise _syntax(node, "the elements of an array have one type")
    if any(is_array(t) for t in types):
        raise _syntax(node, "only one-dimensional arrays exist (§2.3)")
    return elem


def _lift(ce: _CExpr) -> GenFn:
    """The expression as a generator function (pure ones are wrapped)."""
    if ce.gen:
        return cast(GenFn, ce.fn)
    fn = cast(PureFn, ce.fn)

    def gen(fr: _Frame) -> Gen:
        return fn(fr)
        yield  # pragma: no cover - makes this a generator

    return gen


def _pure_or_gen(ce: _CExpr) -> tuple[PureFn | None, GenFn]:
    """A loop's condition: (the plain closure, or None) and the generator function."""
    if ce.gen:
        return None, cast(GenFn, ce.fn)
    return cast(PureFn, ce.fn), _lift(ce)


@dataclass
class _Function:
    node: a.FunctionDef
    returns: str
    params: tuple[str, ...]
    size: int = 0
    body: StmtFn | None = None


@dataclass
class _Scope:
    names: list[dict[str, tuple[int, str]]] = field(default_factory=lambda: [{}])
    size: int = 0
    is_global: bool = False


class _ExprCompiler:
    """Names and expressions: each expression becomes a closure of a known type.

    Calls go to :class:`_CallCompiler`; :class:`_Compiler` adds the statements.
    """

    def __init__(self, script: a.Script) -> None:
        self.script = script
        self.globals: dict[str, tuple[int, str]] = {}
        self.devices: set[str] = set()
        #: Where each device was declared: None in define, else the id of its function's
        #: or section's scope (local devices of two functions are independent, §3.7 p. 35).
        self.device_owners: dict[str, set[int | None]] = {}
        self.functions: dict[str, _Function] = {}
        self.warnings: list[ScriptWarning] = []
        self.scope = _Scope(is_global=True)
        self.function: _Function | None = None
        self.section = ""
        self.calls = _CallCompiler(self)

    # ---- names ----

    def declare(self, node: a.Node, name: str, typ: str) -> tuple[bool, int]:
        _check_name(node, name)
        scope = self.scope
        if any(name in s for s in scope.names) or (not scope.is_global and name in self.globals):
            raise _syntax(node, f"variable {name} is declared twice")
        if scope.is_global:
            slot = len(self.globals)
            self.globals[name] = (slot, typ)
            scope.names[-1][name] = (slot, typ)
            return True, slot
        slot = scope.size
        scope.size += 1
        scope.names[-1][name] = (slot, typ)
        return False, slot

    def lookup(self, name: str) -> tuple[bool, int, str] | None:
        for names in reversed(self.scope.names):
            if name in names:
                slot, typ = names[name]
                return self.scope.is_global, slot, typ
        if name in self.globals:
            slot, typ = self.globals[name]
            return True, slot, typ
        return None

    # ---- expressions ----

    def pure(self, node: a.Expr, where: str) -> _CExpr:
        ce = self.expr(node)
        if ce.gen:
            raise _syntax(node, f"{where}: a waiting call or a function call is not allowed here")
        return ce

    def to_type(self, ce: _CExpr, want: str, node: a.Node) -> PureFn:
        conv = self.converter(ce.type, want, node)
        fn = cast(PureFn, ce.fn)
        if conv is None:
            return fn
        return lambda fr: conv(fn(fr))

    def converter(self, source: str, target: str, node: a.Node) -> Callable[[Value], Value] | None:
        """The implicit conversion of an assignment (TMscript 2.24 §2.7), None if none needed."""
        if source == target and target not in ("float",):
            if is_array(target):
                return _copy  # arrays are values: an assignment copies
            return None
        if target == "?" or target == "*":
            return None
        if source not in ("?", "void") and is_array(source) != is_array(target):
            raise _syntax(node, f"a {source} cannot be assigned to a {target}")
        if source == "void":
            raise _syntax(node, "the function returns no value")

        def conv(value: Value) -> Value:
            try:
                return convert(value, source, target)
            except ConversionError as exc:
                raise _runtime(node, str(exc)) from None

        return conv

    def converted(self, node: a.Expr, want: str, at: a.Node, *, warn: bool = False) -> _CExpr:
        ce = self.expr(node)
        if warn:
            self.warn_lossy(node, ce, want)
        return self.converted_ce(node, ce, want, at)

    def converted_ce(self, node: a.Expr, ce: _CExpr, want: str, at: a.Node) -> _CExpr:
        """``ce``, the compiled ``node``, as a value of type ``want`` (see :meth:`converted`)."""
        conv = self.converter(ce.type, want, at)
        if conv is _copy and ce.fresh:
            conv = None  # a new array: nobody holds the value a copy would protect
        if conv is None:
            return _CExpr(ce.fn, want, ce.gen, ce.const)
        constant = _converted_literal(node, conv)
        if constant is not _NOT_CONSTANT:
            return _CExpr(lambda fr: constant, want, False, (constant,))
        return _mapped(ce, conv, want)

    def warn_lossy(self, node: a.Expr, ce: _CExpr, target: str) -> None:
        message = _lossy(node, ce.type, target)
        if message is not None:
            self.warnings.append(ScriptWarning(node.line, node.column, message))

    def expr(self, node: a.Expr) -> _CExpr:
        if isinstance(node, a.Literal):
            return self.literal(node)
        if isinstance(node, a.Name):
            return self.name(node)
        if isinstance(node, a.ArrayLiteral):
            return self.array(node)
        if isinstance(node, a.Binary):
            return self.binary(node)
        if isinstance(node, a.Logic):
            return self.logic(node)
        if isinstance(node, a.Unary):
            return self.unary(node)
        if isinstance(node, a.Ternary):
            return self.ternary(node)
        if isinstance(node, a.Assign):
            return self.assign(node)
        if isinstance(node, a.IncDec):
            return self.incdec(node)
        if isinstance(node, a.Index):
            return self.index(node)
        if isinstance(node, a.Cast):
            return self.cast(node)
        if isinstance(node, a.Call):
            return self.calls.call(node)
        if isinstance(node, a.MethodCall):
            return self.calls.method_call(node)
        raise _syntax(node, f"unsupported expression {type(node).__name__}")

    def literal(self, node: a.Literal) -> _CExpr:
        value = node.value
        if isinstance(value, int) and not isinstance(value, bool) and node.type == "double":
            # An integer constant over 32 bits is no int (§2.7, p. 27): a double here,
            # held as one (Length() 8, GetBytes() its 8 bytes: §4.42 p. 133, §4.34).
            message = f"{value} is not an int (over 32 bits, §2.7 p. 27): taken as a double"
            if node.written and value < 2**32:  # the manual does not say (docs/tmscript.md)
                message = (
                    f"{node.written} is over an int's range (§2.2 p. 14): taken as a double, "
                    f"{value}; an int takes its 32 bits, {wrap32(value)}"
                )
            self.warnings.append(ScriptWarning(node.line, node.column, message))
            value = float(value)
        if isinstance(value, str) and "'" in value:
            # TMflow warns of a single quote in a string constant: it reads 'x' as the
            # variable x (§2.2 p. 16, §2.7 p. 27).
            self.warnings.append(
                ScriptWarning(
                    node.line,
                    node.column,
                    "a single quote in a string constant (§2.7 p. 27): TMflow warns and "
                    "may read 'name' as a variable",
                )
            )
        return _CExpr(lambda fr: value, node.type, False, (value,))

    def name(self, node: a.Name) -> _CExpr:
        found = self.lookup(node.name)
        if found is None:
            if node.name in self.devices:
                device = node.name
                return _CExpr(lambda fr: device, "string", False)
            # A bare word that is no variable is a string, with a warning (§2.2, p. 16).
            self.warnings.append(
                ScriptWarning(
                    node.line, node.column, f"{node.name} is not a variable: taken as a string"
                )
            )
            text = node.name
            return _CExpr(lambda fr: text, "string", False)
        is_global, slot, typ = found
        if is_global:
            return _CExpr(lambda fr: fr.g[slot], typ, False)
        return _CExpr(lambda fr: fr.l[slot], typ, False)

    def array(self, node: a.ArrayLiteral) -> _CExpr:
        items = [self.expr(item) for item in node.items]
        types = {ce.type for ce in items}
        elem = _element_type(node, types)
        if any(ce.gen for ce in items):
            gens = [_lift(ce) for ce in items]

            def make_gen(fr: _Frame) -> Gen:
                out = []
                for g in gens:
                    out.append((yield from g(fr)))
                return out

            return _CExpr(make_gen, elem + "[]", True)
        fns = [cast(PureFn, ce.fn) for ce in items]
        return _CExpr(lambda fr: [fn(fr) for fn in fns], elem + "[]", False)

    def arith(self, node: a.Node, op: str, lt: str, rt_: str) -> tuple[Callable[..., Value], str]:
        """The function of a binary operator on two values, and the result type."""
        if op == "+" and ("string" in (lt, rt_)):
            if is_array(lt) or is_array(rt_):
                raise _syntax(node, "an array cannot be added to a string")

            def concat(x: Value, y: Value) -> str:
                left, right = display_text(x, lt), display_text(y, rt_)
                if len(left) + len(right) > STRING_MAX:
                    raise _too_long(node, len(left) + len(right))
                return left + right

            return concat, "string"
        if op in ("==", "!=", "<", "<=", ">", ">="):
            return self.comparison(node, op, lt, rt_), "bool"
        if lt not in NUMERIC or rt_ not in NUMERIC:
            raise _syntax(node, f"operator {op} does not apply to {lt} and {rt_}")
        typ = _promote(lt, rt_)
        if op in ("%", "<<", ">>", "&", "|", "^") and typ != "int":
            raise _syntax(node, f"operator {op} takes integers, not {lt} and {rt_}")
        return _ARITH[(op, typ)](node), typ

    def comparison(self, node: a.Node, op: str, lt: str, rt_: str) -> Callable[[Any, Any], bool]:
        kinds = {("n" if t in NUMERIC else t) for t in (lt, rt_)}
        if len(kinds) != 1 or any(is_array(t) for t in (lt, rt_)):
            raise _syntax(node, f"a {lt} cannot be compared with a {rt_}")
        if "bool" in kinds and op not in ("==", "!="):
            raise _syntax(node, f"operator {op} does not apply to bool")
        compare = _COMPARE[op]
        if kinds == {"n"} and _promote(lt, rt_) == "float":
            # Compared as floats, as they are added (§2.4, p. 19): a float constant is a
            # float (§2.2, p. 14), so float f = 0.1 equals 0.1, as it equals 0.1 + 0.
            return lambda x, y: compare(to_f32(x), to_f32(y))
        return compare

    def binary(self, node: a.Binary) -> _CExpr:
        left, right = self.expr(node.left), self.expr(node.right)
        fn, typ = self.arith(node, node.op, left.type, right.type)
        if not left.gen and isinstance(node.right, a.Literal):
            k = node.right.value
            inlined = (
                _int_with_constant(node.op, k, self.place(node.left), left)
                if typ == "int"
                else None
            )
            if inlined is not None:
                return _CExpr(inlined, typ, False)
            return _CExpr(self.with_constant(node.left, left, fn, k), typ, False)
        if not left.gen and not right.gen:
            lf, rf = cast(PureFn, left.fn), cast(PureFn, right.fn)
            return _CExpr(lambda fr: fn(lf(fr), rf(fr)), typ, False)
        lg, rg = _lift(left), _lift(right)

        def binary_gen(fr: _Frame) -> Gen:
            x = yield from lg(fr)
            y = yield from rg(fr)
            return fn(x, y)

        return _CExpr(binary_gen, typ, True)

    def with_constant(
        self, node: a.Expr, left: _CExpr, fn: Callable[[Any, Any], Value], k: Value
    ) -> PureFn:
        """``fn(left, k)`` for a constant ``k`` (a literal: what its closure returns), a
        variable ``left`` read inlined: the common ``i + 1``, ``n == 0``, ``(a + 1) % m``."""
        place = self.place(node)
        if place is not None and place[0]:
            slot = place[1]
            return lambda fr: fn(fr.g[slot], k)
        if place is not None:
            slot = place[1]
            return lambda fr: fn(fr.l[slot], k)
        lf = cast(PureFn, left.fn)
        return lambda fr: fn(lf(fr), k)

    def logic(self, node: a.Logic) -> _CExpr:
        left, right = self.expr(node.left), self.expr(node.right)
        is_and = node.op == "&&"
        if not left.gen and not right.gen:
            lf, rf = cast(PureFn, left.fn), cast(PureFn, right.fn)
            # truthy() of a bool is the bool itself: tested first, without the call.

            def and_(fr: _Frame) -> bool:
                x = lf(fr)
                if not (x is True or (x is not False and truthy(x))):
                    return False
                y = rf(fr)
                return y is True or (y is not False and truthy(y))

            def or_(fr: _Frame) -> bool:
                x = lf(fr)
                if x is True or (x is not False and truthy(x)):
                    return True
                y = rf(fr)
                return y is True or (y is not False and truthy(y))

            return _CExpr(and_ if is_and else or_, "bool", False)
        lg, rg = _lift(left), _lift(right)

        def logic_gen(fr: _Frame) -> Gen:
            # truthy() of a bool is the bool itself: tested first, without the call.
            x = yield from lg(fr)
            first = x if x is True or x is False else truthy(x)
            if first != is_and:
                return first
            y = yield from rg(fr)
            return y if y is True or y is False else truthy(y)

        return _CExpr(logic_gen, "bool", True)

    def unary(self, node: a.Unary) -> _CExpr:
        operand = self.expr(node.operand)
        typ = operand.type
        fn: Callable[[Any], Value]
        if node.op == "!":
            if typ not in ("bool", "?"):
                # "The item following the symbol "!" ... is supposed to be a Boolean type
                # object (or variable)" (TMflow 2.24 appendix J, 0x00048214, p. 481).
                raise _syntax(node, f"operator ! takes a bool, not {typ}")
            if not operand.gen:
                pf = cast(PureFn, operand.fn)

                def not_(fr: _Frame) -> bool:
                    v = pf(fr)
                    return False if v is True else True if v is False else not truthy(v)

                return _CExpr(not_, "bool", False)
            fn, typ = (lambda v: not truthy(v)), "bool"
        elif typ not in NUMERIC:
            raise _syntax(node, f"operator {node.op} does not apply to {typ}")
        elif node.op == "~":
            if typ not in INTEGRAL:
                raise _syntax(node, "operator ~ takes an integer")
            fn, typ = (lambda v: wrap32(~v)), "int"
        elif node.op == "-":
            if typ in INTEGRAL:
                fn, typ = (lambda v: wrap32(-v)), "int"
            else:
                fn = lambda v: -v  # noqa: E731
        else:
            fn = lambda v: v  # noqa: E731
            typ = "int" if typ in INTEGRAL else typ
        return _mapped(operand, fn, typ)

    def ternary(self, node: a.Ternary) -> _CExpr:
        cond, then, other = (self.expr(n) for n in (node.condition, node.then, node.otherwise))
        typ = then.type
        if then.type != other.type:
            if then.type in NUMERIC and other.type in NUMERIC:
                typ = _promote(then.type, other.type)
            else:
                raise _syntax(node, f"the two results are {then.type} and {other.type}")
        if not (cond.gen or then.gen or other.gen):
            cf, tf, of = (cast(PureFn, c.fn) for c in (cond, then, other))
            return _CExpr(lambda fr: tf(fr) if truthy(cf(fr)) else of(fr), typ, False)
        cg, tg, og = _lift(cond), _lift(then), _lift(other)

        def ternary_gen(fr: _Frame) -> Gen:
            if truthy((yield from cg(fr))):
                return (yield from tg(fr))
            return (yield from og(fr))

        return _CExpr(ternary_gen, typ, True)

    def target(self, node: a.Expr) -> tuple[str, Callable[[_Frame, Value], None], _CExpr]:
        """An assignable place: its type, a store function and its read expression."""
        if isinstance(node, a.Name):
            found = self.lookup(node.name)
            if found is None:
                raise _syntax(node, f"variable {node.name} is not declared")
            is_global, slot, typ = found

            def store(fr: _Frame, value: Value) -> None:
                (fr.g if is_global else fr.l)[slot] = value

            return typ, store, self.name(node)
        if isinstance(node, a.Index):
            base = self.expr(node.target)
            if not is_array(base.type) or base.gen:
                raise _syntax(node, "only an array variable's element can be assigned")
            index = self.pure(node.index, "an index")
            bf, xf = cast(PureFn, base.fn), self.to_type(index, "int", node.index)

            def store_elem(fr: _Frame, value: Value) -> None:
                # Plain annotations, no cast(): this runs for every store.
                items: list[Value] = bf(fr)  # type: ignore[assignment]
                i: int = xf(fr)  # type: ignore[assignment]
                if not 0 <= i < len(items):
                    raise _runtime(node, f"index {i} is out of the array (length {len(items)})")
                items[i] = value

            # The read compiles the array and the index again: their warnings once only.
            mark = len(self.warnings)
            read = self.index(node)
            earlier = self.warnings[:mark]
            self.warnings[mark:] = [w for w in self.warnings[mark:] if w not in earlier]
            return element_type(base.type), store_elem, read
        raise _syntax(node, "only a variable or an array element can be assigned")

    def assign(self, node: a.Assign) -> _CExpr:
        typ, store, current = self.target(node.target)
        if node.op == "=":
            _byte_range(node.value, typ)
        value = self.expr(node.value)
        if node.op == "=":
            self.warn_lossy(node.value, value, typ)
        combine: Callable[[Any, Any], Value] | None = None
        vtype = value.type
        if node.op != "=":
            combine, vtype = self.arith(node, node.op[:-1], typ, value.type)
        conv = self.converter(vtype, typ, node)
        if conv is _copy and value.fresh and combine is None:
            conv = None  # a new array: nobody holds the value a copy would protect
        cur_fn = cast(PureFn, current.fn)
        if not value.gen:
            vf = cast(PureFn, value.fn)
            place = self.place(node.target) if combine is None and conv is None else None
            if place is not None:  # the common ``x = expression``: stored inlined
                return _CExpr(_assign_plain(vf, *place), typ, False)

            def assign_pure(fr: _Frame) -> Value:
                result = vf(fr)
                if combine is not None:
                    result = combine(cur_fn(fr), result)
                if conv is not None:
                    result = conv(result)
                store(fr, result)
                return result

            return _CExpr(assign_pure, typ, False)
        vg = cast(GenFn, value.fn)

        def assign_gen(fr: _Frame) -> Gen:
            result = yield from vg(fr)
            if combine is not None:
                result = combine(cur_fn(fr), result)
            if conv is not None:
                result = conv(result)
            store(fr, result)
            return result

        return _CExpr(assign_gen, typ, True)

    def incdec(self, node: a.IncDec) -> _CExpr:
        typ, store, current = self.target(node.target)
        if typ not in INTEGRAL:
            # "The operands ++, -- are only used by integer variable" (TMflow 2.24 appendix
            # J, 0x00048213, p. 481; TMscript 2.24 §2.4, p. 19: "Integer variable").
            raise _syntax(node, f"{node.op} takes an integer variable, not {typ}")
        delta = 1 if node.op == "++" else -1
        conv = self.converter("int" if typ in INTEGRAL else typ, typ, node)
        cur = cast(PureFn, current.fn)
        prefix = node.prefix
        is_int = typ in INTEGRAL

        def step(fr: _Frame) -> Value:
            old: float = cur(fr)  # type: ignore[assignment]
            new: Value = wrap32(int(old) + delta) if is_int else old + delta
            if conv is not None:
                new = conv(new)
            store(fr, new)
            return new if prefix else old

        return _CExpr(step, typ, False)

    def index(self, node: a.Index) -> _CExpr:
        if not isinstance(node.target, a.Name):
            # [] takes an array variable (the operator table, §2.4, p. 19): an element of a
            # function's result is read, with a warning (user projects index modbus_read's).
            self.warnings.append(
                ScriptWarning(
                    node.line,
                    node.column,
                    "[] takes an array variable (§2.4, p. 19): indexing an expression's "
                    "result is not in the manual",
                )
            )
        base = self.expr(node.target)
        if not is_array(base.type):
            raise _syntax(node, f"a {base.type} has no elements")
        index = self.expr(node.index)
        if index.type in ("float", "double", "bool"):
            # TMflow 2.24 appendix J, 0x0004820E "Array Index is not an integer number"
            # (p. 480: "a non-integral value"); the index counts elements from 0 (TMscript
            # 2.24 §2.3, p. 18). A string is converted, as any string given for a number.
            raise _syntax(node.index, f"an array index is an integer, not a {index.type}")
        elem = element_type(base.type)
        conv = self.converter(index.type, "int", node.index)
        constant = _NOT_CONSTANT if conv is None else _converted_literal(node.index, conv)
        if constant is not _NOT_CONSTANT:
            index, conv = _CExpr(lambda fr: constant, "int", False), None
        elif conv is None and isinstance(node.index, a.Literal):
            constant = node.index.value  # an int constant: what its closure returns

        def get(items: list[Value], i: Value) -> Value:
            if conv is not None:
                i = conv(i)
            n: int = i  # type: ignore[assignment]
            if not 0 <= n < len(items):
                raise _runtime(node, f"index {n} is out of the array (length {len(items)})")
            return items[n]

        if not base.gen and constant is not _NOT_CONSTANT:
            return _CExpr(self.element_at(node, base, constant), elem, False)
        if not base.gen and not index.gen:
            bf, xf = cast(PureFn, base.fn), cast(PureFn, index.fn)
            return _CExpr(lambda fr: get(bf(fr), xf(fr)), elem, False)  # type: ignore[arg-type]
        bg, xg = _lift(base), _lift(index)

        def index_gen(fr: _Frame) -> Gen:
            items = yield from bg(fr)
            i = yield from xg(fr)
            return get(items, i)

        return _CExpr(index_gen, elem, True)

    def element_at(self, node: a.Index, base: _CExpr, n: int) -> PureFn:
        """``base[n]`` for a constant ``n``: one closure (an array variable's read inlined)."""
        place = self.place(node.target)
        bf = cast(PureFn, base.fn)

        def out_of(items: list[Value]) -> TMScriptRuntimeError:
            return _runtime(node, f"index {n} is out of the array (length {len(items)})")

        if place is not None and place[0]:
            slot = place[1]

            def global_at(fr: _Frame) -> Value:
                items: list[Value] = fr.g[slot]  # type: ignore[assignment]
                if not 0 <= n < len(items):
                    raise out_of(items)
                return items[n]

            return global_at
        if place is not None:
            slot = place[1]

            def local_at(fr: _Frame) -> Value:
                items: list[Value] = fr.l[slot]  # type: ignore[assignment]
                if not 0 <= n < len(items):
                    raise out_of(items)
                return items[n]

            return local_at

        def element(fr: _Frame) -> Value:
            items: list[Value] = bf(fr)  # type: ignore[assignment]
            if not 0 <= n < len(items):
                raise out_of(items)
            return items[n]

        return element

    def place(self, node: a.Expr) -> tuple[bool, int] | None:
        """(global, slot) of a variable read by name; None for any other expression."""
        if not isinstance(node, a.Name):
            return None
        found = self.lookup(node.name)
        return None if found is None else (found[0], found[1])

    def cast(self, node: a.Cast) -> _CExpr:
        operand = self.expr(node.operand)
        target = _type_name(node.type)
        if is_array(operand.type) != is_array(target) and operand.type != "?":
            raise _syntax(node, f"a {operand.type} cannot be converted to {target} (§2.5)")
        source = operand.type

        def conv(value: Value) -> Value:
            try:
                return convert(value, source, target)
            except ConversionError as exc:
                raise _runtime(node, str(exc)) from None

        return _mapped(operand, conv, target)


class _Compiler(_ExprCompiler):
    """Statements and the project's sections, over the expressions of its base."""

    # ---- the project ----

    def compile(self) -> Program:
        script = self.script
        for fn in script.functions:
            if fn.name in self.functions:  # a customized function may shadow a built-in (§3.10.1)
                raise _syntax(fn, f"function {fn.name} is defined twice")
            params = tuple(_type_name(p.type) for p in fn.params)
            self.functions[fn.name] = _Function(fn, _type_name(fn.return_type), params)
        define = self.statements(script.define, local=False)
        sections: dict[str, tuple[StmtFn, int]] = {}
        for kind, block in (
            ("main", script.main),
            ("closestop", script.closestop),
            ("errorstop", script.errorstop),
        ):
            if block is not None:
                self.section = kind
                self.scope = _Scope()
                body = self.block(block, new_scope=False)
                sections[kind] = (body, self.scope.size)
        for fn_info in self.functions.values():
            self.section = "function"
            self.scope = _Scope()
            self.function = fn_info
            for param, typ in zip(fn_info.node.params, fn_info.params, strict=True):
                self.declare(param, param.name, typ)
            fn_info.body = self.block(fn_info.node.body, new_scope=False)
            fn_info.size = self.scope.size
            self.function = None
        return Program(
            script=script,
            define=define,
            globals_size=len(self.globals),
            sections=sections,
            warnings=tuple(self.warnings),
        )

    # ---- statements ----

    def block(self, node: a.Block, *, new_scope: bool = True) -> StmtFn:
        if new_scope:
            self.scope.names.append({})
        try:
            return self.statements(node.statements)
        finally:
            if new_scope:
                self.scope.names.pop()

    def statements(self, nodes: tuple[a.Statement, ...], *, local: bool = True) -> StmtFn:
        steps = tuple(self.statement(node) for node in nodes)
        run = _run_statements(steps)
        devices = tuple(n.name for n in nodes if isinstance(n, a.ClassDeclaration))
        if not local or not devices:
            return run

        def scoped(fr: _Frame) -> Generator[str, None, Control]:
            # A device declared in a function or a block is closed when it ends: "For
            # variables declared by the class, such as SerialPort, Socket, and Modbus,
            # the variables will close the devices" (TMscript 2.24 §3.7, p. 35).
            held = fr.rt.devices
            saved = {name: held.get(name) for name in devices}  # an outer scope's, if any
            try:
                return (yield from run(fr))
            finally:
                for name, device in saved.items():
                    if device is None:
                        held.pop(name, None)
                    else:
                        held[name] = device

        return scoped

    def as_gen(self, node: a.Statement) -> StmtFn:
        kind, fn = self.statement(node)
        if kind is _STATEMENT:
            return cast(StmtFn, fn)
        if kind is _EXPR:
            gen = cast(GenFn, fn)

            def run_expr(fr: _Frame) -> Generator[str, None, Control]:
                yield from gen(fr)
                return None

            return run_expr
        pure = fn

        def run(fr: _Frame) -> Generator[str, None, Control]:
            rt = fr.rt
            rt.budget -= 1
            if rt.budget < 0 and rt.spent():
                yield _BUDGET
            pure(fr)
            return None

        return run

    def statement(self, node: a.Statement) -> tuple[str, Callable[[_Frame], Any]]:
        """(kind, fn): a _SIMPLE statement is a plain call; an _EXPR one a generator whose
        value is dropped; a _STATEMENT one a generator returning a control."""
        if isinstance(node, a.Declaration):
            return self.declaration(node)
        if isinstance(node, a.ClassDeclaration):
            return _SIMPLE, self.class_declaration(node)
        if isinstance(node, a.ExprStatement):
            ce = self.expr(node.expr)
            return (_EXPR if ce.gen else _SIMPLE), ce.fn
        if isinstance(node, a.Block):
            self.scope.names.append({})
            try:
                return _STATEMENT, self.statements(node.statements)
            finally:
                self.scope.names.pop()
        if isinstance(node, a.Break | a.Continue):
            ctl: Control = _BREAK if isinstance(node, a.Break) else _CONTINUE

            def jump(fr: _Frame) -> Generator[str, None, Control]:
                return ctl
                yield  # pragma: no cover

            return _STATEMENT, jump
        if isinstance(node, a.Return):
            return _STATEMENT, self.return_(node)
        if isinstance(node, a.If):
            return _STATEMENT, self.if_(node)
        if isinstance(node, a.While):
            return _STATEMENT, self.while_(node)
        if isinstance(node, a.DoWhile):
            return _STATEMENT, self.do_while(node)
        if isinstance(node, a.For):
            return _STATEMENT, self.for_(node)
        if isinstance(node, a.Switch):
            return _STATEMENT, self.switch(node)
        raise _syntax(node, f"unsupported statement {type(node).__name__}")

    def declaration(self, node: a.Declaration) -> tuple[str, Callable[[_Frame], Any]]:
        typ = _type_name(node.type)
        if typ not in ("byte", "int", "int16", "float", "double", "bool", "string") and not (
            is_array(typ)
        ):
            raise _syntax(node.type, f"unknown type {node.type}")
        if node.init is not None:
            _byte_range(node.init, typ)
        init = self.converted(node.init, typ, node, warn=True) if node.init is not None else None
        is_global, slot = self.declare(node, node.name, typ)
        default = default_value(typ)
        array = is_array(typ)
        if init is None:

            def declare_default(fr: _Frame) -> None:
                target = fr.g if is_global else fr.l
                target[slot] = [] if array else default

            return _SIMPLE, declare_default
        if not init.gen:
            fn = cast(PureFn, init.fn)
            if is_global:

                def declare_global(fr: _Frame) -> None:
                    fr.g[slot] = fn(fr)

                return _SIMPLE, declare_global

            def declare_local(fr: _Frame) -> None:
                fr.l[slot] = fn(fr)

            return _SIMPLE, declare_local
        gen = cast(GenFn, init.fn)

        def declare_gen(fr: _Frame) -> Generator[str, None, Control]:
            value = yield from gen(fr)
            (fr.g if is_global else fr.l)[slot] = value
            return None

        return _STATEMENT, declare_gen

    def class_declaration(self, node: a.ClassDeclaration) -> Callable[[_Frame], None]:
        # ModbusTCP name = host[, port[, timeout]] (TMscript 2.24 §16.1, p. 414).
        if not 1 <= len(node.args) <= 3:
            raise _syntax(node, "ModbusTCP takes an address, a port and a timeout")
        args = [self.pure(arg, "ModbusTCP") for arg in node.args]
        name = node.name
        _check_name(node, name)
        owner = None if self.scope.is_global else id(self.scope)
        owners = self.device_owners.setdefault(name, set())
        if owners and (owner is None or None in owners or owner in owners):
            raise _syntax(node, f"device {name} is declared twice")
        owners.add(owner)
        self.devices.add(name)
        fns = [
            self.to_type(arg, want, node)
            for arg, want in zip(args, ("string", "int", "int"), strict=False)
        ]

        def declare(fr: _Frame) -> None:
            values = [fn(fr) for fn in fns]
            port = cast(int, values[1]) if len(values) > 1 else 502
            timeout = cast(int, values[2]) if len(values) > 2 else 10000
            if not 0 <= timeout <= 10000:
                raise _runtime(
                    node, f"ModbusTCP timeout {timeout} ms is not 0..10000 (§16.1, p. 414)"
                )
            fr.rt.devices[name] = ModbusConfig(name, cast(str, values[0]), port, timeout)

        return declare

    def return_(self, node: a.Return) -> StmtFn:
        want = self.function.returns if self.function is not None else "void"
        if node.value is None:
            if want != "void" and self.function is not None:
                raise _syntax(node, f"{self.function.node.name} must return a {want}")

            def ret_void(fr: _Frame) -> Generator[str, None, Control]:
                return _Return(None)  # type: ignore[arg-type]
                yield  # pragma: no cover

            return ret_void
        if want == "void":
            raise _syntax(node, "a void function returns no value")
        ce = self.expr(node.value)
        if self.function is not None:
            _check_return(node, self.function.node.name, ce, want)
        value = _lift(self.converted_ce(node.value, ce, want, node))

        def ret(fr: _Frame) -> Generator[str, None, Control]:
            result = yield from value(fr)
            return _Return(result)

        return ret

    def condition(self, node: a.Expr) -> GenFn | PureFn:
        return self.expr(node).fn

    def if_(self, node: a.If) -> StmtFn:
        cond = self.expr(node.condition)
        then = self.scoped(node.then)
        other = self.scoped(node.otherwise) if node.otherwise is not None else None
        if not cond.gen:
            test = cast(PureFn, cond.fn)

            def run_if(fr: _Frame) -> Generator[str, None, Control]:
                c = test(fr)
                if c is True or (c is not False and truthy(c)):  # a bool without the call
                    return (yield from then(fr))
                if other is not None:
                    return (yield from other(fr))
                return None

            return run_if
        gtest = cast(GenFn, cond.fn)

        def run_if_gen(fr: _Frame) -> Generator[str, None, Control]:
            c = yield from gtest(fr)
            if c is True or (c is not False and truthy(c)):  # a bool without the call
                return (yield from then(fr))
            if other is not None:
                return (yield from other(fr))
            return None

        return run_if_gen

    def scoped(self, node: a.Statement) -> StmtFn:
        self.scope.names.append({})
        try:
            return self.as_gen(node)
        finally:
            self.scope.names.pop()

    def while_(self, node: a.While) -> StmtFn:
        pure, test = _pure_or_gen(self.expr(node.condition))
        body = self.scoped(node.body)

        def run_while(fr: _Frame) -> Generator[str, None, Control]:
            rt = fr.rt
            while True:
                rt.budget -= 1  # each iteration counts: while(true){} yields
                if rt.budget < 0 and rt.spent():
                    yield _BUDGET
                c = pure(fr) if pure is not None else (yield from test(fr))
                if c is not True and (c is False or not truthy(c)):  # a bool without the call
                    return None
                ctl = yield from body(fr)
                if ctl is _BREAK:
                    return None
                if ctl is not None and ctl is not _CONTINUE:
                    return ctl

        return run_while

    def do_while(self, node: a.DoWhile) -> StmtFn:
        body = self.scoped(node.body)
        pure, test = _pure_or_gen(self.expr(node.condition))

        def run_do(fr: _Frame) -> Generator[str, None, Control]:
            rt = fr.rt
            while True:
                rt.budget -= 1
                if rt.budget < 0 and rt.spent():
                    yield _BUDGET
                ctl = yield from body(fr)
                if ctl is _BREAK:
                    return None
                if ctl is not None and ctl is not _CONTINUE:
                    return ctl
                if not truthy(pure(fr) if pure is not None else (yield from test(fr))):
                    return None

        return run_do

    def for_(self, node: a.For) -> StmtFn:
        self.scope.names.append({})  # the initialization's variables live in the loop
        try:
            init = self.as_gen(node.init) if node.init is not None else None
            pure, test = (
                _pure_or_gen(self.expr(node.condition))
                if node.condition is not None
                else (None, None)
            )
            pure_step, step = (
                _pure_or_gen(self.expr(node.step)) if node.step is not None else (None, None)
            )
            body = self.scoped(node.body)
        finally:
            self.scope.names.pop()

        def run_for(fr: _Frame) -> Generator[str, None, Control]:
            rt = fr.rt
            if init is not None:
                yield from init(fr)
            while True:
                rt.budget -= 1
                if rt.budget < 0 and rt.spent():
                    yield _BUDGET
                if pure is not None:
                    if not truthy(pure(fr)):
                        return None
                elif test is not None and not truthy((yield from test(fr))):
                    return None
                ctl = yield from body(fr)
                if ctl is _BREAK:
                    return None
                if ctl is not None and ctl is not _CONTINUE:
                    return ctl
                if pure_step is not None:
                    pure_step(fr)
                elif step is not None:
                    yield from step(fr)

        return run_for

    def switch(self, node: a.Switch) -> StmtFn:
        subject = self.expr(node.subject)
        subject_fn = _lift(subject)
        cases: list[tuple[Callable[[Value, _Frame], Gen] | None, StmtFn]] = []
        self.warnings.extend(_no_duplicate_case(node))
        for case in node.cases:
            test = None
            if case.value is not None:
                test = self.case_test(case, subject.type)
            self.scope.names.append({})
            try:
                body = self.statements(case.body)
            finally:
                self.scope.names.pop()
            cases.append((test, body))

        def run_switch(fr: _Frame) -> Generator[str, None, Control]:
            # The subject is read once, then compared case by case (TMscript 2.24 §3.9.2);
            # from the matching case on, statements run until a break.
            value = yield from subject_fn(fr)
            matched = False
            for test, body in cases:
                if not matched:
                    if test is None:
                        matched = True
                    else:
                        matched = yield from test(value, fr)
                if matched:
                    ctl = yield from body(fr)
                    if ctl is _BREAK:
                        return None
                    if ctl is not None:
                        return ctl
            return None

        return run_switch

    def case_test(self, case: a.Case, subject_type: str) -> Callable[[Value, _Frame], Gen]:
        assert case.value is not None
        value = self.expr(case.value)
        compare = self.comparison(case, case.op, subject_type, value.type)
        value_fn = _lift(value)

        def test(subject: Value, fr: _Frame) -> Gen:
            other = yield from value_fn(fr)
            return compare(subject, other)

        return test


class _CallCompiler:
    """Calls: a built-in, a customized function, a device's method (§3.10, §16.1)."""

    def __init__(self, exprs: _ExprCompiler) -> None:
        self.c = exprs

    def call(self, node: a.Call) -> _CExpr:
        c = self.c
        if node.name in c.functions:
            return self.user_call(node, c.functions[node.name])
        builtin = BUILTINS.get(node.name)
        if builtin is None:
            if node.name in UNSUPPORTED:
                raise _syntax(node, f"{node.name}() is not supported by tmmaster.tmscript")
            raise _syntax(node, f"unknown function {node.name}()")
        if node.name == "WaitFor" and len(node.args) == 2:
            return self.wait_for(node, builtin)
        if node.name == "ThreadRun":
            return self.thread_run(node)
        if builtin.motion and c.section in ("closestop", "errorstop"):
            raise _syntax(node, f"{node.name}(): no motion in {c.section} (§3.3, §3.4)")
        if builtin.motion:
            builtin = _main_thread_only(builtin)
        args = [c.expr(arg) for arg in node.args]
        sig = self.resolve(node, builtin, [ce.type for ce in args])
        fns, types = self.arguments(node, args, _expand(sig.params, len(args)))
        ret = _return_type(sig.returns, types)
        arg_types = tuple(types)
        if builtin.impl is not None and not any(ce.gen for ce in fns):
            return _CExpr(_builtin_pure(node, builtin.impl, fns, arg_types), ret, False)
        return self.waiting(node, builtin, fns, arg_types, ret)

    def waiting(
        self,
        node: a.Call,
        builtin: Builtin,
        fns: list[_CExpr],
        arg_types: tuple[str, ...],
        ret: str,
    ) -> _CExpr:
        """A call that may wait (a generator): a built-in that waits or an argument that may."""
        fused = _int16_read(node, builtin, fns)
        if fused is not None:
            return _CExpr(fused, ret, True, fresh=True)
        ce = _CExpr(_builtin_gen(node, builtin, fns, arg_types), ret, True)
        if builtin.name == "modbus_read" and len(fns) == 5 and not any(f.gen for f in fns):
            ce.read = (node, _arguments(fns))
        return ce

    def arguments(
        self, node: a.Call, args: list[_CExpr], params: tuple[str, ...]
    ) -> tuple[list[_CExpr], list[str]]:
        """A built-in's arguments converted to its syntax's parameters, and their types."""
        fns: list[_CExpr] = []
        types: list[str] = []
        for ce, want, arg in zip(args, params, node.args, strict=True):
            if node.name == "Display" and ce.type != "string" and not ce.gen:
                # Display shows any value as TMflow writes it (§5.6; arrays as {1,2,3}).
                shown = cast(PureFn, ce.fn)
                fns.append(_CExpr(_shown(shown, ce.type, arg), "string", False))
                types.append("string")
            elif node.name == "Display" and is_array(ce.type):
                # An array a customized function returns (§3.5), shown as a variable's is.
                fns.append(_CExpr(_shown_gen(cast(GenFn, ce.fn), ce.type, arg), "string", True))
                types.append("string")
            elif want in ("?", "?[]", "*"):
                fns.append(ce)
                types.append(ce.type)
            else:
                fns.append(self.c.converted(arg, want, arg) if ce.type != want else ce)
                types.append(want)
        return fns, types

    def resolve(self, node: a.Call, builtin: Builtin, types: list[str]) -> Any:
        """Pick the syntax the arguments fit (TMscript 2.24 §2.2: smaller types widen)."""
        if builtin.name == "Display":
            types = ["string" if not t.endswith("?") else t for t in types]
        # The syntax the arguments reach at the least cost: exact types first, then the
        # smaller types widening to greater ones (§2.2, p. 15), then any other conversion.
        best: tuple[int, Any] | None = None
        for sig in builtin.signatures:
            cost = _cost(types, _expand(sig.params, len(types)))
            if cost is not None and (best is None or cost < best[0]):
                best = (cost, sig)
        if best is not None:
            return best[1]
        shown = ", ".join(types)
        syntaxes = "; ".join(f"{builtin.name}({', '.join(s.params)})" for s in builtin.signatures)
        raise _syntax(
            node,
            f"{builtin.name}({shown}) matches no syntax of §{builtin.section} "
            f"(p. {builtin.page}): {syntaxes}",
        )

    def wait_for(self, node: a.Call, builtin: Builtin) -> _CExpr:
        # WaitFor(condition, ms) evaluates the condition again on each poll (§5.4, p. 158).
        cond = _lift(self.c.expr(node.args[0]))
        timeout_ce = self.c.converted(node.args[1], "int", node.args[1])
        timeout = _lift(timeout_ce)

        def wait_gen(fr: _Frame) -> Gen:
            ms = cast(int, (yield from timeout(fr)))
            host = fr.rt.host
            start = host.now_s()
            while True:
                if truthy((yield from cond(fr))):
                    return True
                if ms >= 0 and host.now_s() - start >= ms / 1000.0:
                    return False
                yield _BLOCKED

        return _CExpr(wait_gen, "bool", True)

    def thread_run(self, node: a.Call) -> _CExpr:
        # ThreadRun(statement, nonpause) runs the statement in a new thread and goes on
        # (TMscript 2.24 §3.12.1, p. 47); the bool is false when left out.
        if len(node.args) not in (1, 2):
            raise _syntax(node, "ThreadRun(statement, bool) takes 1 or 2 arguments")
        body = _lift(self.c.expr(node.args[0]))
        nonpause = (
            _lift(self.c.converted(node.args[1], "bool", node.args[1]))
            if len(node.args) == 2
            else None
        )

        def start_thread(fr: _Frame) -> Gen:
            keep = truthy((yield from nonpause(fr))) if nonpause is not None else False
            rt = fr.rt
            ident = 2 + max((t.ident - 1 for t in rt.threads), default=0)
            rt.threads.append(_Thread(ident, body(fr), keep))
            return ident

        return _CExpr(start_thread, "int", True)

    def user_call(self, node: a.Call, fn: _Function) -> _CExpr:
        if len(node.args) != len(fn.params):
            raise _syntax(
                node, f"{fn.node.name}() takes {len(fn.params)} arguments, not {len(node.args)}"
            )
        args = [
            (ce.gen, ce.fn)
            for ce in (
                self.c.converted(arg, want, arg)
                for arg, want in zip(node.args, fn.params, strict=True)
            )
        ]
        returns = fn.returns
        # Plain arguments (the common case) are called without the generator protocol;
        # none (the other common case) need no call at all.
        pure = None if not args or any(gen for gen, _ in args) else _values_of([f for _, f in args])

        def call_user(fr: _Frame) -> Gen:
            if pure is not None:
                values = pure(fr)
            else:
                values = []
                for gen, f in args:
                    values.append((yield from f(fr)) if gen else f(fr))
            callee = _Frame(fr.g, fn.size, fr.rt)
            if values:
                callee.l[: len(values)] = values
            assert fn.body is not None
            ctl = yield from fn.body(callee)
            if isinstance(ctl, _Return):
                return ctl.value
            if returns != "void":
                raise _runtime(node, f"{fn.node.name}() ended without returning a {returns}")
            return None

        return _CExpr(call_user, returns, True)

    def method_call(self, node: a.MethodCall) -> _CExpr:
        # device.Preset(name, slave, "DO"/"DI"/"RO"/"RI", address, type[, suffix]) (§16.1.1).
        if not isinstance(node.target, a.Name) or node.target.name not in self.c.devices:
            raise _syntax(node, f"{node.method}() needs a ModbusTCP device variable")
        if node.method != "Preset":
            raise _syntax(node, f"{node.method}() is not supported by tmmaster.tmscript")
        if len(node.args) not in (5, 6):
            raise _syntax(node, "Preset() takes 5 or 6 arguments (§16.1.1)")
        wants = ("string", "byte", "string", "int", "string", "int")
        fns = [
            self.c.to_type(self.c.pure(arg, "Preset"), want, arg)
            for arg, want in zip(node.args, wants, strict=False)
        ]
        device = node.target.name

        def preset(fr: _Frame) -> Value:
            values = [f(fr) for f in fns]
            name, unit, kind, address, typ = (cast(Any, v) for v in values[:5])
            if not str(name).isidentifier() or str(name)[0].isdigit():
                raise _runtime(node, f'preset name "{name}" must be alphanumeric (§16.1.1)')
            if kind not in ("DO", "DI", "RO", "RI"):
                raise _runtime(node, f'signal type "{kind}" is not DO, DI, RO or RI')
            if typ not in ("bool", "byte", "int16", "int32", "float", "double", "string", "int"):
                raise _runtime(node, f'type "{typ}" is not supported by Preset()')
            suffix = cast(int, values[5]) if len(values) > 5 else (0 if typ == "string" else 1)
            fr.rt.devices[device].presets[name] = (unit, kind, address, typ, suffix)
            return True

        return _CExpr(preset, "bool", False)


def _main_thread_only(builtin: Builtin) -> Builtin:
    """A motion function that fails in any thread but main (TMscript 2.24 §3.12, p. 47),
    and in closestop and errorstop (§3.3, p. 30; §3.4, p. 31)."""
    impl = builtin.impl
    if impl is None:
        return builtin

    def guarded(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
        if not rt.motion_allowed:  # called through a function (a direct call: at parse)
            raise ValueError(
                "no motion in closestop or errorstop (§3.3, p. 30; §3.4, p. 31; TMflow 0x00048B53)"
            )
        if rt.thread != 1:
            raise ValueError("robot motion functions run in the main thread only (§3.12, p. 47)")
        return impl(rt, args, types)

    return dataclasses.replace(builtin, impl=guarded)


def _call_failure(node: a.Call, exc: Exception) -> TMScriptRuntimeError:
    return _runtime(node, f"{node.name}(): {str(exc) or type(exc).__name__}")


def _arguments(fns: list[_CExpr]) -> Callable[[_Frame], list[Value]]:
    """The values of a call's plain arguments, a new list each call: the constants (a
    literal, a converted literal) computed once, only the others called."""
    pure = [cast(PureFn, ce.fn) for ce in fns]
    if all(ce.const is None for ce in fns):
        return lambda fr: [fn(fr) for fn in pure]
    template: list[Value] = [None if ce.const is None else ce.const[0] for ce in fns]  # type: ignore[misc]
    varying = [(i, cast(PureFn, ce.fn)) for i, ce in enumerate(fns) if ce.const is None]
    if not varying:
        return lambda fr: template.copy()

    def values(fr: _Frame) -> list[Value]:
        out = template.copy()
        for i, fn in varying:
            out[i] = fn(fr)
        return out

    return values


def _int_with_constant(
    op: str, k: Value, place: tuple[bool, int] | None, left: _CExpr
) -> PureFn | None:
    """``left + k``, ``left - k`` or ``left % k`` (``k`` > 0) of ints, the operator's own
    expression written into one closure (the common ``i + 1``, ``ack % m + 1``); None for
    another operator or constant."""
    if k.__class__ is not int or op not in ("+", "-", "%"):
        return None
    if op == "%":
        return _int_mod_constant(k, place, left) if k > 0 else None
    # The table's x + y and x - y: ((x +/- y + 2**31) & 0xFFFFFFFF) - 2**31.
    return _int_add_constant(k if op == "+" else -k, place, left)


def _int_mod_constant(c: int, place: tuple[bool, int] | None, left: _CExpr) -> PureFn:
    """``left % c`` for ``c`` > 0: _int_mod's expression for such a divisor."""
    lf = cast(PureFn, left.fn)
    slot = -1 if place is None else place[1]

    def mod_global(fr: _Frame) -> Value:
        x: int = fr.g[slot]  # type: ignore[assignment]
        return x % c if x >= 0 else -(abs(x) % c)

    def mod_local(fr: _Frame) -> Value:
        x: int = fr.l[slot]  # type: ignore[assignment]
        return x % c if x >= 0 else -(abs(x) % c)

    def mod_any(fr: _Frame) -> Value:
        x: int = lf(fr)  # type: ignore[assignment]
        return x % c if x >= 0 else -(abs(x) % c)

    return mod_any if place is None else mod_global if place[0] else mod_local


def _int_add_constant(d: int, place: tuple[bool, int] | None, left: _CExpr) -> PureFn:
    """``left + d`` of ints wrapped to 32 bits, as the table's ``+`` computes it."""
    lf = cast(PureFn, left.fn)
    slot = -1 if place is None else place[1]

    def add_global(fr: _Frame) -> Value:
        x: int = fr.g[slot]  # type: ignore[assignment]
        return ((x + d + 0x80000000) & 0xFFFFFFFF) - 0x80000000

    def add_local(fr: _Frame) -> Value:
        x: int = fr.l[slot]  # type: ignore[assignment]
        return ((x + d + 0x80000000) & 0xFFFFFFFF) - 0x80000000

    def add_any(fr: _Frame) -> Value:
        x: int = lf(fr)  # type: ignore[assignment]
        return ((x + d + 0x80000000) & 0xFFFFFFFF) - 0x80000000

    return add_any if place is None else add_global if place[0] else add_local


def _assign_plain(vf: PureFn, is_global: bool, slot: int) -> PureFn:
    """``variable = vf()`` of a variable whose type needs no conversion: one closure."""
    if is_global:

        def assign_global(fr: _Frame) -> Value:
            result = fr.g[slot] = vf(fr)
            return result

        return assign_global

    def assign_local(fr: _Frame) -> Value:
        result = fr.l[slot] = vf(fr)
        return result

    return assign_local


def _values_of(fns: list[PureFn]) -> Callable[[_Frame], list[Value]]:
    """The values of plain arguments, a new list each call (no comprehension for the
    common one or two)."""
    if len(fns) == 1:
        (f1,) = fns
        return lambda fr: [f1(fr)]
    if len(fns) == 2:
        f1, f2 = fns
        return lambda fr: [f1(fr), f2(fr)]
    return lambda fr: [f(fr) for f in fns]


def _builtin_pure(
    node: a.Call, impl: Impl, fns: list[_CExpr], arg_types: tuple[str, ...]
) -> PureFn:
    """A call of a built-in that returns at once, with plain arguments: a plain closure."""
    arguments = _arguments(fns)

    def call_pure(fr: _Frame) -> Value:
        values = arguments(fr)
        try:
            result = impl(fr.rt, values, arg_types)
            if isinstance(result, str) and len(result) > STRING_MAX:  # _capped, inlined
                raise _too_long(node, len(result))
            return result
        except (ExitRequest, TMScriptRuntimeError):
            raise
        except (HostError, TMMasterError, OSError, ValueError, ArithmeticError) as exc:
            raise _call_failure(node, exc) from None
        except Exception as exc:
            raise _call_failure(node, exc) from None

    return call_pure


def _builtin_gen(
    node: a.Call, builtin: Builtin, fns: list[_CExpr], arg_types: tuple[str, ...]
) -> GenFn:
    """A call of a built-in that may wait, or with an argument that may: a generator."""
    if builtin.linked is not None and not any(ce.gen for ce in fns):
        return _builtin_linked(node, builtin.linked, fns, arg_types)
    impl = builtin.impl
    blocking = builtin.blocking
    # Arguments in order; a plain one is called, not wrapped into a generator; a
    # constant is in the template already.
    template: list[Value] = [None if ce.const is None else ce.const[0] for ce in fns]  # type: ignore[misc]
    steps = [(i, ce.gen, ce.fn) for i, ce in enumerate(fns) if ce.const is None]

    def call_gen(fr: _Frame) -> Gen:
        values = template.copy()
        for i, gen, f in steps:
            values[i] = (yield from f(fr)) if gen else f(fr)
        try:
            if blocking is not None:
                result = yield from blocking(fr.rt, values, arg_types)
            else:
                assert impl is not None
                result = impl(fr.rt, values, arg_types)
            if isinstance(result, str) and len(result) > STRING_MAX:  # _capped, inlined
                raise _too_long(node, len(result))
            return result
        except (ExitRequest, TMScriptRuntimeError, GeneratorExit):
            raise
        except Exception as exc:
            raise _call_failure(node, exc) from None

    return call_gen


def _int16_read(node: a.Call, builtin: Builtin, fns: list[_CExpr]) -> GenFn | None:
    """``Byte_ToInt16Array(modbus_read(...), ...)``, the common read of registers, in one
    generator: the read as its own call runs it (its errors its own), then the conversion
    of the bytes read (the byte array modbus_read returns holds them). None for another
    call."""
    if builtin.name != "Byte_ToInt16Array" or not fns or fns[0].read is None:
        return None
    if any(ce.gen for ce in fns[1:]):
        return None
    read_node, read_arguments = fns[0].read
    # The other arguments as _builtin_gen computes them (constants once), after the read.
    template: list[Value] = [None if ce.const is None else ce.const[0] for ce in fns]  # type: ignore[misc]
    steps = [(i, cast(PureFn, ce.fn)) for i, ce in enumerate(fns) if i and ce.const is None]

    def int16_read(fr: _Frame) -> Gen:
        values = read_arguments(fr)
        rt = fr.rt
        try:  # modbus_read, as _builtin_linked runs it
            device = link_device(rt, values)
            while not rt.host.modbus_ready(device):
                yield _BLOCKED
            data = read_registers(rt, values)
        except (ExitRequest, TMScriptRuntimeError, GeneratorExit):
            raise
        except Exception as exc:
            raise _call_failure(read_node, exc) from None
        args = template.copy()
        for i, f in steps:
            args[i] = f(fr)
        try:
            return int16_array(data, args)
        except (ExitRequest, TMScriptRuntimeError, GeneratorExit):
            raise
        except Exception as exc:
            raise _call_failure(node, exc) from None

    return int16_read


def _builtin_linked(
    node: a.Call, impl: Impl, fns: list[_CExpr], arg_types: tuple[str, ...]
) -> GenFn:
    """A Modbus function with plain arguments: it waits until the host's link can take
    the request, then calls ``impl`` (as the built-in's ``blocking`` does, without a
    second generator)."""
    arguments = _arguments(fns)

    def call_linked(fr: _Frame) -> Gen:
        values = arguments(fr)
        rt = fr.rt
        try:
            device = link_device(rt, values)
            while not rt.host.modbus_ready(device):
                yield _BLOCKED
            result = impl(rt, values, arg_types)
            if isinstance(result, str) and len(result) > STRING_MAX:  # _capped, inlined
                raise _too_long(node, len(result))
            return result
        except (ExitRequest, TMScriptRuntimeError, GeneratorExit):
            raise
        except Exception as exc:
            raise _call_failure(node, exc) from None

    return call_linked


def _shown(fn: PureFn, typ: str, node: a.Node) -> PureFn:
    """``Display``'s text of a value that is not a string (an array as ``{1,2,3}``)."""

    def show(fr: _Frame) -> str:
        value = fn(fr)
        if isinstance(value, list) and typ == "string[]":
            # Counted before it is built: the elements may be long strings.
            length = sum(len(cast(str, item)) + 1 for item in value) + 1
            if length > STRING_MAX:
                raise _too_long(node, length)
        text = display_text(value, typ)
        if len(text) > STRING_MAX:
            raise _too_long(node, len(text))
        return text

    return show


def _shown_gen(fn: GenFn, typ: str, node: a.Node) -> GenFn:
    """:func:`_shown` of a value that a call may wait for (a customized function's)."""

    def show_gen(fr: _Frame) -> Gen:
        value = yield from fn(fr)
        return _shown(lambda _: value, typ, node)(fr)

    return show_gen


def _copy(value: Value) -> Value:
    return list(value) if isinstance(value, list) else value


#: The order in which numeric types widen (TMscript 2.24 §2.2, p. 15: smaller to greater).
_RANK = {"byte": 0, "int16": 1, "int": 2, "int32": 2, "float": 3, "double": 4}


def _expand(params: tuple[str, ...], count: int) -> tuple[str, ...]:
    """A syntax's parameters for ``count`` arguments: ``*...`` repeats for the rest."""
    if params and params[-1] == "*...":
        return params[:-1] + ("*",) * max(count - len(params) + 1, 0)
    return params


def _return_type(returns: str, types: list[str]) -> str:
    """``$0``: the first argument's type; ``$num``: int for integers only, else double."""
    if returns == "$0":
        return types[0]
    if returns == "$num":
        return "int" if all(element_type(t) in INTEGRAL for t in types) else "double"
    return returns


def _cost(types: list[str], params: tuple[str, ...]) -> int | None:
    """What it costs to pass ``types`` to ``params``; None when they do not fit."""
    if len(types) != len(params) or (params and params[-1] == "*..."):
        return None
    total = 0
    for arg, param in zip(types, params, strict=True):
        if not _fits(arg, param):
            return None
        pe, ae = element_type(param), element_type(arg)
        if param in ("*", "?", "?[]"):
            total += 2
        elif pe != ae and ae != "?" and pe in _RANK and ae in _RANK:
            total += 1 if _RANK[ae] < _RANK[pe] else 3
        elif pe != ae and ae != "?":
            total += 4
    return total


def _fits(arg: str, param: str) -> bool:
    if param == "*":
        return True
    if param == "?":
        return not is_array(arg)
    if param == "?[]":
        return is_array(arg)
    if arg == "?":
        return True
    if is_array(param) != is_array(arg):
        return False
    pe, ae = element_type(param), element_type(arg)
    if pe == ae or ae == "?":
        return True
    if pe in NUMERIC and ae in NUMERIC:
        return True
    return pe == "string" and ae in NUMERIC


# ---- operators -------------------------------------------------------------------------


def _int_div(node: a.Node) -> Callable[[int, int], int]:
    def div(x: int, y: int) -> int:
        if y == 0:
            raise _runtime(node, "division by zero")
        q = abs(x) // abs(y)  # truncates toward zero, like C
        return wrap32(q if (x >= 0) == (y >= 0) else -q)

    return div


def _int_mod(node: a.Node) -> Callable[[int, int], int]:
    def mod(x: int, y: int) -> int:
        if y == 0:
            raise _runtime(node, "division by zero")
        if x >= 0 and y > 0:
            return x % y  # the common case: abs() of both is themselves
        r = abs(x) % abs(y)  # the sign of the dividend, like C
        return r if x >= 0 else -r

    return mod


def _float_op(
    node: a.Node, fn: Callable[[float, float], float], single: bool
) -> Callable[..., Value]:
    def op(x: float, y: float) -> float:
        try:
            result = fn(x, y)
        except ZeroDivisionError:
            raise _runtime(node, "division by zero") from None
        if single:
            try:
                return to_f32(result)
            except ConversionError as exc:
                raise _runtime(node, str(exc)) from None
        return result

    return op


def _shift_left(x: int, y: int) -> int:
    return wrap32(x << (y & 31))


def _arith_table() -> dict[tuple[str, str], Callable[[a.Node], Callable[..., Value]]]:
    table: dict[tuple[str, str], Callable[[a.Node], Callable[..., Value]]] = {
        # wrap32 written out: these run for every integer operation.
        ("+", "int"): lambda n: lambda x, y: ((x + y + 0x80000000) & 0xFFFFFFFF) - 0x80000000,
        ("-", "int"): lambda n: lambda x, y: ((x - y + 0x80000000) & 0xFFFFFFFF) - 0x80000000,
        ("*", "int"): lambda n: lambda x, y: ((x * y + 0x80000000) & 0xFFFFFFFF) - 0x80000000,
        ("/", "int"): _int_div,
        ("%", "int"): _int_mod,
        ("<<", "int"): lambda n: _shift_left,
        (">>", "int"): lambda n: lambda x, y: x >> (y & 31),
        ("&", "int"): lambda n: operator.and_,
        ("|", "int"): lambda n: operator.or_,
        ("^", "int"): lambda n: operator.xor,
    }
    ops: dict[str, Callable[[float, float], float]] = {
        "+": lambda x, y: x + y,
        "-": lambda x, y: x - y,
        "*": lambda x, y: x * y,
        "/": lambda x, y: x / y,
    }
    for sym, fn in ops.items():
        table[(sym, "float")] = lambda n, fn=fn: _float_op(n, fn, True)  # type: ignore[misc]
        table[(sym, "double")] = lambda n, fn=fn: _float_op(n, fn, False)  # type: ignore[misc]
    return table


_ARITH = _arith_table()
_COMPARE: dict[str, Callable[[Any, Any], bool]] = {
    "==": operator.eq,
    "!=": operator.ne,
    "<": operator.lt,
    "<=": operator.le,
    ">": operator.gt,
    ">=": operator.ge,
}


# ---- the program and its execution -----------------------------------------------------


@dataclass(frozen=True)
class Program:
    """A checked Script Project, ready to run any number of times (see :func:`parse`)."""

    script: a.Script
    define: StmtFn
    globals_size: int
    sections: dict[str, tuple[StmtFn, int]]
    #: Bare words taken as strings (TMscript 2.24 §2.7).
    warnings: tuple[ScriptWarning, ...]
    #: The name shown in messages.
    filename: str = "<script>"


def compile_program(script: a.Script, filename: str = "<script>") -> Program:
    """Check a syntax tree and compile it.

    :param script: from :func:`._parser.parse_script`.
    :param filename: shown in messages.
    :returns: the :class:`Program`.
    :raises TMScriptSyntaxError: an unknown or unsupported function, a type error, a
        variable declared twice.
    """
    program = _Compiler(script).compile()
    return Program(
        program.script,
        program.define,
        program.globals_size,
        program.sections,
        program.warnings,
        filename,
    )


def parse(text: str, filename: str = "<script>") -> Program:
    """Parse and check a Script Project (``define``, ``main``, ``closestop``, ``errorstop``).

    Example:
        ```python
        from tmmaster.tmscript import Execution, NullHost, parse

        program = parse('main { Display("hello " + (6 * 7)) }')
        Execution(program, NullHost()).run_to_end()  # prints: hello 42
        ```

    Args:
        text: The script.
        filename: The name shown in messages.

    Returns:
        The checked Program; ``Program.warnings`` lists bare words taken as strings
        (TMscript 2.24 §2.7).

    Raises:
        TMScriptSyntaxError: A syntax error, an unknown or unsupported function, a type
            error; ``.line`` and ``.column`` say where.
    """
    return compile_program(parse_script(text), filename)


class Execution:
    """One run of a :class:`Program` against a :class:`~tmmaster.tmscript.Host`.

    Nothing runs until :meth:`step`. The project runs ``define`` then ``main``; when main
    ends (or ``Exit()``, or :meth:`stop`) it runs ``closestop``; on an error (or
    ``Exit(-1)``, or :meth:`fail`) ``errorstop``. An error inside either ends the project
    at once (TMscript 2.24 §3.3, §3.4).

    Args:
        program: From :func:`parse`.
        host: The clock, dashboard, Modbus and motion.
        budget_clock: The clock of :meth:`step`'s ``max_seconds``: wall seconds
            (``time.monotonic``) by default; ``time.thread_time`` counts the CPU seconds
            of the calling thread, which do not depend on the machine's load.
    """

    def __init__(
        self, program: Program, host: Host, *, budget_clock: Callable[[], float] = time.monotonic
    ) -> None:
        #: The program that runs.
        self.program = program
        #: What the script reaches.
        self.host = host
        self._rt = _Run(host)
        self._rt.clock = budget_clock
        self._globals: list[Value] = [None] * program.globals_size  # type: ignore[list-item]
        #: Where the execution stands.
        self.state = ExecState.RUNNING
        #: The error that stopped the project (state ERROR), else None.
        self.error: TMScriptRuntimeError | None = None
        #: The code given to Exit(), if it was called.
        self.exit_code: int | None = None
        #: Whether Exit() asked to wait for the motion to end first (Exit(false): no).
        self.exit_waits = True
        self._phase = "main"
        self._phase_start = 0.0
        self._rt.started_s = host.now_s()
        self._gen: Generator[str, None, Control] | None = self._main()
        self._last_status = Status(self.state)

    @property
    def phase(self) -> str:
        """The section running: ``"main"``, ``"closestop"`` or ``"errorstop"``."""
        return self._phase

    def _section(self, kind: str) -> Generator[str, None, Control] | None:
        section = self.program.sections.get(kind)
        if section is None:
            return None
        body, size = section
        return body(_Frame(self._globals, size, self._rt))

    def _main(self) -> Generator[str, None, Control]:
        yield from self.program.define(_Frame(self._globals, 0, self._rt))
        main = self._section("main")
        if main is not None:
            yield from main
        return None

    def _enter(self, phase: str) -> None:
        if self._gen is not None:
            self._gen.close()
        # The threads end with main.
        threads, self._rt.threads = self._rt.threads, []
        for thread in threads:
            thread.gen.close()
        self._phase = phase
        self._phase_start = self.host.now_s()
        self._rt.motion_allowed = False
        self._gen = self._section(phase)
        if self._gen is None:
            self._finish()

    def _finish(self) -> None:
        self._gen = None
        self.state = ExecState.ERROR if self.error is not None else ExecState.ENDED

    def _on_error(self, error: TMScriptRuntimeError) -> None:
        if self._phase == "main":
            self.error = error
            self._enter("errorstop")
        else:  # an error in closestop or errorstop ends the project directly
            if self.error is None:
                self.error = error
            self._finish()

    def step(self, max_statements: int = 1000, max_seconds: float | None = None) -> Status:
        """Run until the script blocks, ends, fails or has spent its budget.

        Each statement and each loop iteration counts. The next call goes on where this
        one stopped. A statement that fails in Python (out of memory, too deep a
        recursion, a fault of the interpreter) is a runtime error of the script: it runs
        errorstop like any other.

        Args:
            max_statements: The most statements to run (at least 1).
            max_seconds: The most seconds to run by the budget clock (wall seconds
                unless the Execution was given another), or None for
                no limit: the step yields once they have passed, overshooting by the
                statement that was running (the clock is read every
                :data:`CLOCK_EVERY` statements, after every one once they run slowly).

        Returns:
            The new ``state``, with ``error`` and ``exit_code``.
        """
        self._step(max_statements, max_seconds)
        return self._status()

    def _status(self) -> Status:
        """``Status(state, error, exit_code)``: the one made last while they are the same
        (a Status is immutable; a program polling for a command reports the same one at
        every step)."""
        last = self._last_status
        if (
            last.state is self.state
            and last.error is self.error
            and last.exit_code is self.exit_code
        ):
            return last
        last = self._last_status = Status(self.state, self.error, self.exit_code)
        return last

    def _step(self, max_statements: int, max_seconds: float | None = None) -> ExecState:
        if self.state in (ExecState.ENDED, ExecState.ERROR):
            return self.state
        if self._rt.paused:
            self.state = ExecState.PAUSED
            return self.state
        self._rt.start(max_statements, max_seconds)
        if self._phase == "main":
            self._step_threads(nonpause_only=False)
            if self._rt.paused:  # a thread's Pause() (§5.2, p. 156): main waits too
                self.state = ExecState.PAUSED
                return self.state
        while self._gen is not None:
            if self._phase != "main" and (
                self.host.now_s() - self._phase_start > STOP_SECTION_LIMIT_S
            ):
                self._finish()  # closed after 12 s at most (§3.3, p. 30)
                break
            signal = self._advance(self._gen)
            if signal is None:
                continue
            if signal == _BUDGET:
                self.state = ExecState.RUNNING
            elif signal == _PAUSED:
                self.state = ExecState.PAUSED
            else:
                self.state = ExecState.BLOCKED
            return self.state
        return self.state

    def step_threads(self, max_statements: int = 1000, max_seconds: float | None = None) -> Status:
        """Run the non-pause threads only, as TMflow does while the project is paused.

        A thread started with ``ThreadRun(statement, true)`` goes on while the project
        is paused (TMscript 2.24 §3.12, p. 47); main and the other threads wait. Each
        runs to its next wait or until the budget is spent.

        Args:
            max_statements: The most statements to run (at least 1).
            max_seconds: The most seconds to run by the budget clock, or None.

        Returns:
            The new ``state``: a thread may have stopped the project (``Exit()``, an
            error), which leaves main for closestop or errorstop.
        """
        if self.state not in (ExecState.ENDED, ExecState.ERROR) and self._phase == "main":
            self._rt.start(max_statements, max_seconds)
            self._step_threads(nonpause_only=True)
        return self._status()

    def _step_threads(self, *, nonpause_only: bool) -> None:
        """Run each thread to its next yield; one that stops the project ends the round."""
        rt = self._rt
        for thread in list(rt.threads):
            if nonpause_only and not thread.nonpause:
                continue
            rt.thread = thread.ident
            try:
                self._advance(thread.gen, thread=thread)
            finally:
                rt.thread = 1
            if self._phase != "main" or self._gen is None:
                return

    def _advance(
        self, gen: Generator[str, None, Control], thread: _Thread | None = None
    ) -> str | None:
        """Run ``gen`` to its next yield; None when it ended or failed (handled here).

        ``thread``: ``gen`` is that thread's (ThreadRun); its end ends only the thread.
        """
        try:
            return next(gen)
        except StopIteration:
            if thread is not None:
                self._rt.threads.remove(thread)
            elif self._phase == "main":
                self._enter("closestop")
            else:
                self._finish()
        except ExitRequest as exit_:
            self.exit_code = exit_.code
            self.exit_waits = exit_.wait
            if self._phase != "main":
                self._finish()
            else:
                self._enter("errorstop" if exit_.code < 0 else "closestop")
        except TMScriptRuntimeError as exc:
            self._on_error(exc)
        except RecursionError:
            self._on_error(TMScriptRuntimeError("too deep recursion", line=0, column=0))
        except MemoryError:
            self._on_error(TMScriptRuntimeError("out of memory", line=0, column=0))
        except Exception as exc:  # a fault of the interpreter: the script stops in error
            reason = f"internal error: {type(exc).__name__}: {exc}"
            self._on_error(TMScriptRuntimeError(reason, line=0, column=0))
        return None

    def resume(self) -> None:
        """Resume after ``Pause()`` (the Play button)."""
        self._rt.paused = False
        if self.state == ExecState.PAUSED:
            self.state = ExecState.RUNNING

    def stop(self, max_statements: int = 100_000, max_seconds: float | None = None) -> ExecState:
        """Stop the project (the Stop button): run ``closestop`` (TMscript 2.24 §3.3).

        closestop runs at once with its own budget; if it blocks (a Sleep) or spends the
        budget, later :meth:`step` calls finish it.

        Args:
            max_statements: closestop's budget now.
            max_seconds: closestop's time budget now (wall seconds), None for none.

        Returns:
            The new ``state``.
        """
        if self._phase == "main" and self.state not in (ExecState.ENDED, ExecState.ERROR):
            self._rt.paused = False
            self._enter("closestop")
            self._step(max_statements, max_seconds)
        return self.state

    def fail(
        self,
        error: str | TMScriptRuntimeError,
        max_statements: int = 100_000,
        max_seconds: float | None = None,
    ) -> ExecState:
        """An error from outside the script (an emergency stop): run ``errorstop`` (§3.4).

        Args:
            error: The error, or its message.
            max_statements: errorstop's budget now.
            max_seconds: errorstop's time budget now (wall seconds), None for none.

        Returns:
            The new ``state``.
        """
        if isinstance(error, str):
            error = TMScriptRuntimeError(error, line=0, column=0)
        if self.state in (ExecState.ENDED, ExecState.ERROR):
            return self.state
        self._rt.paused = False
        self._on_error(error)
        if self._gen is not None:
            self._step(max_statements, max_seconds)
        return self.state

    def run_to_end(self, timeout_s: float | None = None, poll_s: float = 0.001) -> ExecState:
        """Step until the project ends, sleeping (wall clock) while it waits.

        Args:
            timeout_s: Stop the project (closestop) after this many wall seconds; None:
                no limit. It is checked every :data:`RUN_SLICE_S` at least (plus the
                statement running then), whatever the script does.
            poll_s: Wall seconds to sleep while the script waits.

        Returns:
            ``ExecState.ENDED`` or ``ExecState.ERROR``, or ``PAUSED`` when the script
            paused itself and nothing can resume it.

        Raises:
            TimeoutError: The timeout ran out (the project was stopped first: closestop
                got :data:`TIMEOUT_CLOSESTOP_S` at most).
        """
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            state = self._step(10_000, None if deadline is None else RUN_SLICE_S)
            if state in (ExecState.ENDED, ExecState.ERROR, ExecState.PAUSED):
                return state
            if deadline is not None and time.monotonic() > deadline:
                self.stop(max_seconds=TIMEOUT_CLOSESTOP_S)
                raise TimeoutError(f"the script ran longer than {timeout_s} s")
            if state == ExecState.BLOCKED:
                time.sleep(poll_s)
