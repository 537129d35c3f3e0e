"""The commands' argument parser: a bad option is one line and exit 2, never a usage dump."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from . import _sigint
from ._exceptions import ConfigError


class UsageError(ConfigError):
    """A command-line option is wrong (the command exits 2)."""


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors raise :class:`UsageError` for ``main()``.

    Options are never abbreviated: a mistyped or shortened option (``--speed`` for
    ``--speed-factor``) is refused by name instead of silently taken as another one,
    and adding an option never changes what an existing command line means.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        """Raise instead of printing the usage and exiting: ``main()`` says it in one line."""
        raise UsageError(f"{message} (see {self.prog} --help)")


def one_line(text: object) -> str:
    """``text`` on one line (a multi-line validation report joined by spaces)."""
    return " ".join(str(text).split())


#: Exit status when the output cannot be written (a full disk, a closed pipe): the
#: command failed, but not because of bad input (that is 2), so the generic failure, 1.
EXIT_OUTPUT_FAILED = 1


def write_stdout(write: Callable[[], object], *, prog: str) -> int:
    """Run ``write`` (which prints to ``sys.stdout``), flush, and turn a write error into a status.

    Args:
        write: prints the command's output on ``sys.stdout``.
        prog: the command's name for the error line (``tmmaster``, ``report``).

    Returns:
        0 when everything was written; :data:`EXIT_OUTPUT_FAILED` when it could not be:
        one line on stderr (e.g. ``> /dev/full``), or nothing for a reader that went away
        (a closed pipe, as ``| head`` does: the usual quiet end).
    """
    try:
        write()
        sys.stdout.flush()
    except BrokenPipeError:
        _discard_stdout()
        return EXIT_OUTPUT_FAILED
    except OSError as exc:
        _discard_stdout()
        reason = exc.strerror or str(exc)
        print(
            f"{prog}: cannot write the output: {reason} [exit {EXIT_OUTPUT_FAILED}]",
            file=sys.stderr,
        )
        return EXIT_OUTPUT_FAILED
    return 0


def _discard_stdout() -> None:
    """Point file descriptor 1 at the null device after a failed write.

    What is left in ``sys.stdout``'s buffer would otherwise be written again when the
    interpreter exits, fail again and print a traceback-like warning (exit 120).
    """
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, sys.stdout.fileno())
        finally:
            os.close(null)
    except (OSError, ValueError):  # not a real file (a test's captured stdout)
        pass


def run_command(
    prog: str,
    build_parser: Callable[[], argparse.ArgumentParser],
    run: Callable[[argparse.Namespace], int],
    argv: Sequence[str] | None,
) -> int:
    """A command's ``main()``: parse ``argv``, run, and turn bad usage and Ctrl-C into one line.

    Args:
        prog: the name the messages start with.
        build_parser: makes the command's parser.
        run: runs the parsed command; returns the exit status.
        argv: the arguments (None: ``sys.argv[1:]``).

    Returns:
        ``run``'s status; 2 for bad usage; 130 when interrupted before the command's
        own handling of Ctrl-C took over.
    """
    _sigint.handled_by_main()
    try:
        try:
            args = build_parser().parse_args(argv)
        except UsageError as exc:
            print(f"{prog}: {one_line(exc)} [exit 2]", file=sys.stderr)
            return 2
        return run(args)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted [exit {_sigint.EXIT_INTERRUPTED}]", file=sys.stderr)
        return _sigint.EXIT_INTERRUPTED
