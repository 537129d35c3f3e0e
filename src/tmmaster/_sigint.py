"""Ctrl-C while a command starts: exit 130 with one line, never a traceback.

Imported first by each command's entry module, before pymodbus, pydantic and the rest
load. When the running program is one of tmmaster's commands, a Ctrl-C until the
command's ``main()`` takes over (:func:`handled_by_main`) ends the process at once:
nothing is connected or started yet, so there is nothing to clean up. Imported any
other way (a library user, a test), this module does nothing.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from types import FrameType

#: Entry modules of the commands, and the name each prints its messages under.
_COMMANDS = {
    "tmmaster.__main__": "tmmaster",
    "tmmaster.pickplace.__main__": "pickplace",
    "tmmaster.report.__main__": "report",
    "tmmaster.sim.__main__": "sim",
    "tmmaster.tmscript.__main__": "tmscript",
}

#: Exit status of an interrupted command (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130


def _command_name() -> str | None:
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None and spec.name in _COMMANDS:
        return _COMMANDS[spec.name]
    # ``python -m tmmaster.pickplace``: while runpy imports the packages (tmmaster's
    # __init__ imports this module first), __main__ is not set up yet; the command line
    # already says which module runs.
    argv = getattr(sys, "orig_argv", [])
    if "-m" in argv[:-1]:
        module = argv[argv.index("-m") + 1]
        return _COMMANDS.get(f"{module}.__main__")
    if os.path.basename(sys.argv[0] if sys.argv else "") == "tmmaster":
        return "tmmaster"  # the console script
    return None


def _install() -> None:
    name = _command_name()
    if name is None or threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        return  # started in the background by a shell: leave it ignored

    def interrupted(signum: int, frame: FrameType | None) -> None:
        _ = signum, frame
        os.write(2, f"{name}: interrupted [exit {EXIT_INTERRUPTED}]\n".encode())
        os._exit(EXIT_INTERRUPTED)

    signal.signal(signal.SIGINT, interrupted)


def handled_by_main() -> None:
    """Hand Ctrl-C back to Python's default (KeyboardInterrupt), which ``main()`` catches."""
    if threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


_install()


class deferred:  # noqa: N801 - used as a context manager, like contextlib's lower-case ones
    """Hold Ctrl-C back for the length of a critical section, then deliver it.

    A withdraw or stop that a second Ctrl-C cuts short leaves a command armed. In the
    main thread (the only one that receives SIGINT), the handler is replaced by one that
    only records the signal; on exit the previous handler is restored and, if a signal
    came meanwhile, called once, so the interrupt still happens, just after the clean-up.
    Elsewhere (other threads, a handler Python did not install) it does nothing.
    Re-entrant: a nested section leaves the outer one's recorder in place.
    """

    __slots__ = ("_pending", "_previous")

    def __init__(self) -> None:
        self._previous: signal.Handlers | object | None = None
        self._pending = False

    def __enter__(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        try:
            previous = signal.getsignal(signal.SIGINT)
        except ValueError:  # not the main interpreter
            return
        if previous is None or previous is signal.SIG_IGN or getattr(previous, "deferring", False):
            return

        def record(signum: int, frame: FrameType | None) -> None:
            _ = signum, frame
            self._pending = True

        record.deferring = True  # type: ignore[attr-defined]
        try:
            signal.signal(signal.SIGINT, record)
        except ValueError:
            return
        self._previous = previous

    def __exit__(self, *exc_info: object) -> None:
        previous, self._previous = self._previous, None
        if previous is None:
            return
        signal.signal(signal.SIGINT, previous)  # type: ignore[arg-type]
        if self._pending:
            self._pending = False
            if previous is signal.SIG_DFL:
                signal.raise_signal(signal.SIGINT)
            elif callable(previous):
                previous(signal.SIGINT, None)
