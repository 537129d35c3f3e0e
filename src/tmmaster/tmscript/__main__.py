"""``python -m tmmaster.tmscript`` (and ``tmmaster tmscript``): check, evaluate or run TMscript.

``check FILE`` reads a Script Project and reports the first syntax error or unsupported
function; ``eval "EXPR"`` prints an expression's value as TMflow displays it; ``run FILE``
runs a Script Project without a robot (each ``Display()`` printed as one line).
Exit codes: 0 fine, 1 a runtime error or the timeout, 2 the script cannot run (a syntax
error, an unsupported function, it moves the robot or talks Modbus) or a wrong option.
"""

from __future__ import annotations

# isort: off
from .. import _sigint  # noqa: F401  first: a Ctrl-C while the rest loads exits 130 quietly
# isort: on

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from .._cliparse import ArgumentParser, one_line, run_command
from .._version import add_version_argument


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``check``, ``eval`` and ``run`` subcommands to ``parser``; return it."""
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
    return parser


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m tmmaster.tmscript``."""
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
    """Run ``check``, ``eval`` or ``run`` from parsed ``args``; return the exit code."""
    from .._exceptions import TMScriptRuntimeError, TMScriptSyntaxError
    from . import ExecState, Execution, NullHost, NullHostError, display_text, evaluate, parse

    if args.tmscript_command == "eval":
        try:
            value, typ = evaluate(args.expression)
        except TMScriptSyntaxError as exc:
            print(_where("<expr>", exc), file=sys.stderr)
            return 2
        except TMScriptRuntimeError as exc:
            print(_where("<expr>", exc), file=sys.stderr)
            return 1
        print(display_text(value, typ))
        return 0
    file = args.file
    try:
        text = Path(file).read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        print(f"{file}: cannot read: {one_line(exc)}", file=sys.stderr)
        return 2
    try:
        program = parse(text, filename=file)
    except TMScriptSyntaxError as exc:
        print(_where(file, exc), file=sys.stderr)
        return 2
    for warning in program.warnings:
        print(
            f"{file}:{warning.line}:{warning.column}: warning: {warning.message}", file=sys.stderr
        )
    if args.tmscript_command == "check":
        print(f"{file}: OK")
        return 0
    execution = Execution(program, NullHost(on_display=print))
    try:
        state = execution.run_to_end(args.timeout)  # an ExecState
    except TimeoutError as exc:
        print(f"{file}: {exc}", file=sys.stderr)
        return 1
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
    """Entry point of ``python -m tmmaster.tmscript``."""
    return run_command("tmscript", build_parser, run, argv)


if __name__ == "__main__":
    sys.exit(main())
