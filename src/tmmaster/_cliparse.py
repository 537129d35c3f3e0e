"""The commands' argument parser: a bad option is one line and exit 2, never a usage dump."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from typing import NoReturn

from ._exceptions import ConfigError


class UsageError(ConfigError):
    """A command-line option is wrong (the command exits 2)."""


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors raise :class:`UsageError` for ``main()``."""

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
