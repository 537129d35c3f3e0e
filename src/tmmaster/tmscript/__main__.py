"""``python -m tmmaster.tmscript`` (and ``tmmaster tmscript``): check, evaluate or run TMscript.

``check FILE`` reads a Script Project and reports every syntax error, unknown or
unsupported function and type error it finds, one ``FILE:LINE:COLUMN: message`` line each;
``eval "EXPR"`` prints an expression's value as TMflow displays it; ``run FILE`` runs a
Script Project without a robot (each ``Display()`` printed as one line). Each takes
``--log-json`` and ``--log-level`` as every tmmaster command does.
Exit codes: 0 fine, 1 a runtime error or the timeout, 2 the script cannot run (a syntax
error, an unsupported function, it moves the robot or talks Modbus) or a wrong option.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .._cliparse import ArgumentParser, one_line, run_command
from .._logging import add_logging_arguments, configure_logging, get_logger
from .._version import add_version_argument

if TYPE_CHECKING:
    from .._exceptions import TMScriptSyntaxError
    from ._ast import Script
    from ._evaluator import ScriptWarning

#: The level of the events logged on stderr when ``--log-level`` is not given.
DEFAULT_LOG_LEVEL = "warning"

_log = get_logger("tmmaster.tmscript")


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``check``, ``eval`` and ``run`` subcommands to ``parser``; return it.

    Args:
        parser: ``python -m tmmaster.tmscript``'s parser, or ``tmmaster tmscript``'s.

    Returns:
        ``parser``.
    """
    add_version_argument(parser)
    sub = parser.add_subparsers(dest="tmscript_command", required=True, metavar="{check,eval,run}")
    check = sub.add_parser("check", help="check a Script Project without running it")
    check.add_argument("file", metavar="FILE", help="a TMscript Script Project")
    evaluate = sub.add_parser("eval", help="print the value of one expression")
    evaluate.add_argument("expression", metavar="EXPR", help='e.g. "10 / 3.0"')
    run = sub.add_parser("run", help="run a Script Project that moves nothing")
    run.add_argument("file", metavar="FILE", help="a TMscript Script Project")
    run.add_argument(
        "--timeout", type=float, default=None, metavar="S", help="stop it after S seconds"
    )
    for command in (check, evaluate, run):
        # No default of its own: ``tmmaster --log-level debug tmscript ...`` then counts.
        add_logging_arguments(
            command,
            level_help=f"level of the events logged on stderr (default: {DEFAULT_LOG_LEVEL})",
        )
    return parser


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m tmmaster.tmscript``.

    Returns:
        The parser, with its ``check``, ``eval`` and ``run`` subcommands.
    """
    parser = ArgumentParser(
        prog="python -m tmmaster.tmscript",
        description="Check, evaluate or run TMscript (TMflow Script Projects).",
    )
    return add_arguments(parser)


def _where(file: str, exc: Exception) -> str:
    from .._exceptions import TMScriptError

    if isinstance(exc, TMScriptError):
        return f"{file}:{exc.line}:{exc.column}: {exc.reason}"
    return f"{file}: {one_line(exc)}"


def run(args: argparse.Namespace) -> int:
    """Run ``check``, ``eval`` or ``run`` from parsed ``args``; return the exit code.

    Args:
        args: The parsed options.

    Returns:
        0 fine; 1 a runtime error or the timeout; 2 the script cannot run.
    """
    level = getattr(args, "log_level", None) or DEFAULT_LOG_LEVEL
    undo = configure_logging(
        json=bool(getattr(args, "log_json", False)), level=level, stream=sys.stderr
    )
    try:
        if args.tmscript_command == "eval":
            return _eval(args.expression)
        return _on_file(args)
    finally:
        undo()


def _eval(expression: str) -> int:
    from .._exceptions import TMScriptRuntimeError, TMScriptSyntaxError
    from . import display_text, evaluate

    try:
        value, typ = evaluate(expression)
    except TMScriptSyntaxError as exc:
        print(_where("<expr>", exc), file=sys.stderr)
        return 2
    except TMScriptRuntimeError as exc:
        print(_where("<expr>", exc), file=sys.stderr)
        return 1
    _log.debug("tmscript.evaluated", expression=expression, type=typ)
    print(display_text(value, typ))
    return 0


def _on_file(args: argparse.Namespace) -> int:
    file = args.file
    try:
        text = Path(file).read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        print(f"{file}: cannot read: {one_line(exc)}", file=sys.stderr)
        return 2
    if args.tmscript_command == "check":
        return _check(file, text)
    return _run(file, text, args.timeout)


def _check(file: str, text: str) -> int:
    """``check``: every error and warning, one line each in the order of the text."""
    from ._parser import MAX_ERRORS, check_script

    script, errors = check_script(text)
    warnings: tuple[ScriptWarning, ...] = ()
    if script is not None:
        errors, warnings = _semantic_errors(script)
    lines = [(e.line, e.column, _where(file, e)) for e in errors]
    lines += [
        (w.line, w.column, f"{file}:{w.line}:{w.column}: warning: {w.message}") for w in warnings
    ]
    for _, _, line in sorted(lines):
        print(line, file=sys.stderr)
    _log.info("tmscript.checked", file=file, errors=len(errors), warnings=len(warnings))
    if not errors:
        print(f"{file}: OK")
        return 0
    if len(errors) > 1:
        more = f" (check stops at {MAX_ERRORS})" if len(errors) >= MAX_ERRORS else ""
        print(f"{file}: {len(errors)} errors{more}", file=sys.stderr)
    return 2


def _semantic_errors(script: Script) -> tuple[list[TMScriptSyntaxError], tuple[ScriptWarning, ...]]:
    """The errors a syntactically right script has (unknown functions, wrong arguments,
    types): each statement's, not only the first; and its warnings."""
    from .._exceptions import TMScriptSyntaxError
    from . import _ast
    from ._evaluator import _SIMPLE, _Compiler

    class CheckAll(_Compiler):
        """The compiler, going on after a statement's error to check the next ones."""

        def __init__(self, script: Script) -> None:
            super().__init__(script)
            self.errors: list[TMScriptSyntaxError] = []

        def statement(self, node: _ast.Statement) -> tuple[str, Callable[[Any], Any]]:
            try:
                return super().statement(node)
            except TMScriptSyntaxError as exc:
                self.errors.append(exc)
            if isinstance(node, _ast.Declaration) and node.init is not None:
                # The variable is declared all the same: its uses are no errors of their own.
                with contextlib.suppress(TMScriptSyntaxError):
                    super().statement(dataclasses.replace(node, init=None))
            return _SIMPLE, _nothing

    compiler = CheckAll(script)
    try:
        compiler.compile()
    except TMScriptSyntaxError as exc:  # not in a statement: a function defined twice...
        compiler.errors.append(exc)
    errors = sorted(compiler.errors, key=lambda e: (e.line, e.column))
    return errors, tuple(compiler.warnings)


def _nothing(frame: object) -> None:
    """What a statement in error compiles to (a checked script never runs)."""


def _run(file: str, text: str, timeout: float | None) -> int:
    from .._exceptions import TMScriptSyntaxError
    from . import ExecState, Execution, NullHost, NullHostError, parse

    try:
        program = parse(text, filename=file)
    except TMScriptSyntaxError as exc:
        print(_where(file, exc), file=sys.stderr)
        return 2
    for warning in program.warnings:
        print(
            f"{file}:{warning.line}:{warning.column}: warning: {warning.message}", file=sys.stderr
        )
    execution = Execution(program, NullHost(on_display=print))
    try:
        state = execution.run_to_end(timeout)  # an ExecState
    except TimeoutError as exc:
        print(f"{file}: {exc}", file=sys.stderr)
        return 1
    _log.info("tmscript.ran", file=file, state=str(state))
    if state == ExecState.ERROR and execution.error is not None:
        error = execution.error
        print(_where(file, error), file=sys.stderr)
        cause = error.reason
        return 2 if NullHostError.__name__ in cause or "run it on a robot" in cause else 1
    if state == ExecState.PAUSED:
        print(f"{file}: the script paused itself (Pause()) and nothing resumes it", file=sys.stderr)
        return 1
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m tmmaster.tmscript``.

    Args:
        argv: The arguments (None: ``sys.argv[1:]``).

    Returns:
        The exit status.
    """
    return run_command("tmscript", build_parser, run, argv)


if __name__ == "__main__":
    sys.exit(main())
