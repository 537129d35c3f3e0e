"""A TMscript interpreter: check and run TMflow Script Projects (TMscript 2.24).

``program = parse(text)`` checks a script (raising :class:`~tmmaster.TMScriptSyntaxError`);
``Execution(program, host).step(n)`` runs it a bounded number of statements at a time, so
it can run on a robot's control tick. The :class:`Host` protocol is how a script reaches
the clock, the dashboard, Modbus devices and the motion queue; :class:`NullHost` serves
scripts that move nothing. See ``docs/tmscript.md``.
"""

from __future__ import annotations

from .._exceptions import TMScriptError, TMScriptRuntimeError, TMScriptSyntaxError
from ._builtins import BUILTINS, UNSUPPORTED, Builtin, Signature
from ._evaluator import ExecState, Execution, Program, ScriptWarning, Status, parse
from ._host import Host, HostError, ModbusDevice, MotionCall, NullHost, NullHostError
from ._types import Value, display_text

__all__ = [
    "BUILTINS",
    "UNSUPPORTED",
    "Builtin",
    "ExecState",
    "Execution",
    "Host",
    "HostError",
    "ModbusDevice",
    "MotionCall",
    "NullHost",
    "NullHostError",
    "Program",
    "ScriptWarning",
    "Signature",
    "Status",
    "TMScriptError",
    "TMScriptRuntimeError",
    "TMScriptSyntaxError",
    "Value",
    "display_text",
    "evaluate",
    "parse",
]


def evaluate(expression: str) -> tuple[Value, str]:
    """Evaluate one expression with no variables (``tmmaster tmscript eval``).

    Example:
        ```python
        from tmmaster.tmscript import evaluate

        print(evaluate("10 / 4"))  # (2, 'int')
        ```

    Args:
        expression: One expression on one line, e.g. ``"10 / 3.0"``.

    Returns:
        The value and its TMscript type.

    Raises:
        TMScriptSyntaxError: The expression is not valid.
        TMScriptRuntimeError: It failed (division by zero...).
    """
    try:
        return _evaluate(expression)
    except TMScriptError as exc:
        from ._parser import expression_error

        raise expression_error(exc, expression) from None


def _evaluate(expression: str) -> tuple[Value, str]:
    from ._ast import ExprStatement
    from ._evaluator import _CExpr, _Compiler, _Frame, _Run, _Scope
    from ._parser import expression_script, parse_script

    if "\n" in expression:
        raise TMScriptSyntaxError("expected one expression on one line", line=1, column=1)
    script = parse_script(expression_script(expression))
    assert script.main is not None
    statements = script.main.statements
    if len(statements) != 1 or not isinstance(statements[0], ExprStatement):
        raise TMScriptSyntaxError("expected one expression", line=1, column=1)
    compiler = _Compiler(script)
    compiler.scope = _Scope()
    statement = statements[0]
    assert isinstance(statement, ExprStatement)
    ce: _CExpr = compiler.expr(statement.expr)
    frame = _Frame([], compiler.scope.size, _Run(NullHost()))
    if ce.gen:
        gen = ce.fn(frame)
        try:
            while True:
                next(gen)
        except StopIteration as done:
            return done.value, ce.type
    return ce.fn(frame), ce.type
