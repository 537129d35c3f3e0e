"""The commands' argument parser: a bad option is one line and exit 2, never a usage dump."""

from __future__ import annotations

import argparse
import difflib
import os
import signal
import sys
from collections.abc import Callable, Iterable, Sequence
from contextlib import suppress
from typing import Any, NoReturn

from ._exceptions import ConfigError
from ._sigint import run_main


class UsageError(ConfigError):
    """A command-line option is wrong (the command exits 2)."""


def did_you_mean(value: str, choices: Iterable[str]) -> str:
    """``"; did you mean X?"`` for the choice closest to ``value``, or ``""`` when none is close.

    The one helper every "unknown name" message uses (options, sub-commands, profiles,
    grippers, physics backends, fault kinds).

    Args:
        value: The name as typed.
        choices: The names it may be.

    Returns:
        The hint, to append to the message, or an empty string.
    """
    names = [str(choice) for choice in choices]
    close = difflib.get_close_matches(value, names, n=1, cutoff=0.6)
    if not close:  # a case slip (``DEBUG``, ``TMflow``) is close whatever its length
        close = [name for name in names if name.lower() == value.lower()][:1]
    return f"; did you mean {close[0]}?" if close else ""


#: Where a sub-command's parser leaves its hints for the top-level parser's message.
_HINTS = "_tmmaster_option_hints"


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors raise :class:`UsageError` for ``main()``.

    Options are never abbreviated: a mistyped or shortened option (``--speed`` for
    ``--speed-factor``) is refused by name instead of silently taken as another one,
    and adding an option never changes what an existing command line means. An unknown
    option, sub-command or choice is said with the closest known one (did you mean).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        """Raise instead of printing the usage and exiting: ``main()`` says it in one line."""
        raise UsageError(f"{message} (see {self.prog} --help)")

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """argparse's, noting for each unknown option the closest of this parser's own.

        A sub-command's parser runs this too: its hints travel in the namespace up to
        the top-level :meth:`parse_args`, which names them.
        """
        parsed, extras = super().parse_known_args(args, namespace)
        known = [s for a in self._actions for s in a.option_strings if s.startswith("--")]
        hints: dict[str, str] = dict(getattr(parsed, _HINTS, {}))
        for token in extras:
            name = token.split("=", 1)[0]
            if name.startswith("-") and (name in known or not hints.get(name)):
                own = f"; {name} is {self.prog}'s own: give it before the sub-command"
                hints[name] = own if name in known else did_you_mean(name, known)
        if hints:
            setattr(parsed, _HINTS, hints)
        return parsed, extras

    def parse_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> argparse.Namespace:
        """argparse's, with a did-you-mean for a mistyped option (``--cycle`` for ``--cycles``).

        Raises:
            UsageError: An unknown option or argument, or any other usage error.
        """
        parsed, extras = self.parse_known_args(args, namespace)
        hints: dict[str, str] = vars(parsed).pop(_HINTS, {})  # not an option: taken out
        if extras:
            said = "".join(hints.get(token.split("=", 1)[0], "") for token in extras)
            self.error(f"unrecognized arguments: {' '.join(extras)}{said}")
        return parsed

    def _check_value(self, action: argparse.Action, value: Any) -> None:
        """argparse's choice check, with the closest choice (a sub-command, a backend)."""
        choices = action.choices
        if choices is None or value in choices:
            return
        listed = ", ".join(map(repr, choices))
        hint = did_you_mean(str(value), [str(c) for c in choices])
        raise argparse.ArgumentError(
            action, f"invalid choice: {value!r} (choose from {listed}){hint}"
        )


def one_line(text: object) -> str:
    """``text`` on one line (a multi-line validation report joined by spaces)."""
    return " ".join(str(text).split())


#: Exit status when the output cannot be written (a full disk, an unwritable file): the
#: command failed, but not because of bad input (that is 2), so the generic failure, 1.
EXIT_OUTPUT_FAILED = 1

#: Exit status when the reader of stdout went away (``| head``): 128 + SIGPIPE, what a
#: shell reports for any program the closed pipe stopped (``yes | head -1`` under
#: ``set -o pipefail``). Nothing is printed: the reader left on purpose.
EXIT_BROKEN_PIPE = 128 + int(signal.SIGPIPE)


def write_stdout(text: str, *, prog: str) -> int:
    """Write ``text`` on ``sys.stdout``, flush, and turn a write error into a status.

    Args:
        text: the command's output.
        prog: the command's name for the error line (``tmmaster``, ``report``).

    Returns:
        0 when everything was written; :data:`EXIT_OUTPUT_FAILED` when it could not be,
        with one line on stderr (e.g. ``> /dev/full``); :data:`EXIT_BROKEN_PIPE`, quietly,
        when the reader went away (a closed pipe, as ``| head`` does).
    """

    def write() -> int:
        sys.stdout.write(text)
        return 0

    try:
        return ended_quietly(write)
    except OSError as exc:
        discard_stdout()
        return output_failed(prog, "the output", exc)


def output_failed(prog: str, what: str, exc: OSError) -> int:
    """Say on stderr that ``what`` could not be written, in one line; the exit status.

    Args:
        prog: the command's name, the start of the line.
        what: what could not be written (``the output``, a file's name).
        exc: the error the write raised.

    Returns:
        :data:`EXIT_OUTPUT_FAILED`.
    """
    reason = exc.strerror or str(exc)
    print(f"{prog}: cannot write {what}: {reason} [exit {EXIT_OUTPUT_FAILED}]", file=sys.stderr)
    return EXIT_OUTPUT_FAILED


def discard_stdout() -> None:
    """Point file descriptor 1 at the null device after a failed write.

    What is left in ``sys.stdout``'s buffer would otherwise be written again when the
    interpreter exits, fail again and print a traceback-like warning (exit 120).
    """
    with suppress(OSError, ValueError):  # not a real file (a test's captured stdout)
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, sys.stdout.fileno())
        finally:
            os.close(null)


def ended_quietly(body: Callable[[], int]) -> int:
    """Run a command's ``body``, then flush stdout; a reader gone away ends it quietly.

    The shared end of every command's ``main()``: a :class:`BrokenPipeError` (the reader
    of stdout closed it, as ``| head`` does) is neither a traceback nor a line on
    stderr, but :data:`EXIT_BROKEN_PIPE`.

    Args:
        body: Runs the command; returns its exit status.

    Returns:
        ``body``'s status, or :data:`EXIT_BROKEN_PIPE` after a closed stdout.
    """
    try:
        code = body()
        sys.stdout.flush()
    except BrokenPipeError:
        discard_stdout()
        return EXIT_BROKEN_PIPE
    return code


def run_command(
    prog: str,
    build_parser: Callable[[], argparse.ArgumentParser],
    run: Callable[[argparse.Namespace], int],
    argv: Sequence[str] | None,
) -> int:
    """A command's ``main()``: parse ``argv`` and run; bad usage and Ctrl-C are one line.

    Runs under :func:`tmmaster._sigint.run_main`, the one place a command handles Ctrl-C.

    Args:
        prog: the name the messages start with.
        build_parser: makes the command's parser.
        run: runs the parsed command; returns the exit status.
        argv: the arguments; None: ``sys.argv[1:]``, and the command is the process
            itself (its ``__main__``, the console script).

    Returns:
        ``run``'s status; 2 for bad usage; 130 after a Ctrl-C;
        :data:`EXIT_BROKEN_PIPE` when the reader of stdout went away.
    """

    def parse_and_run() -> int:
        try:
            args = build_parser().parse_args(argv)
        except UsageError as exc:
            print(f"{prog}: {one_line(exc)} [exit 2]", file=sys.stderr)
            return 2
        return run(args)

    return run_main(prog, lambda: ended_quietly(parse_and_run), process=argv is None)
