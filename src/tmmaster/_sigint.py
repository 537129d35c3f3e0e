"""Ctrl-C while a command starts or ends: one line, never a traceback.

Imported first by each command's entry module, before pymodbus, pydantic and the rest
load. When the running program is one of tmmaster's commands:

- until the command's ``main()`` takes over (:func:`handled_by_main`), a Ctrl-C ends the
  process at once with one line and exit 130: nothing is connected or started yet, so
  there is nothing to clean up. The handler is installed before this module imports
  anything that Python's start-up has not already loaded;
- from then on a Ctrl-C is a :class:`KeyboardInterrupt`, which ``main()`` turns into one
  line, until the interpreter exits: once the main thread has ended (Python's exit, its
  exit hooks: a :class:`~tmmaster.Robot` still open withdraws or stops its command) a
  Ctrl-C is ignored, so it neither cuts a hook short nor prints a traceback.

Imported any other way (a library user, a test), the handlers are left alone; only a
Ctrl-C that :class:`deferred` held back during an exit hook is dropped there, not raised.

A Ctrl-C before the first line of tmmaster runs (Python's own start-up: ``site``, the
``-m`` machinery) is Python's: its usual ``KeyboardInterrupt`` traceback.
"""

# No ``from __future__ import annotations`` and only modules Python's start-up has
# loaded (``_signal`` is the C module under ``signal``): nothing to load before the
# handler is in place.
import _signal  # type: ignore[import-not-found]  # no stubs: the C module under signal
import os
import sys

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

#: Test hook: ``import`` or ``exit``: say so on stderr there and wait for a byte on stdin
#: (a test sends Ctrl-C at that very point instead of after a guessed delay).
_PAUSE_AT = "TMMASTER_TEST_SIGINT_AT"


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


def _install() -> str | None:
    """For a command: Ctrl-C exits 130 in one line; the command's name (None: not one)."""
    name = _command_name()
    if name is None or _signal.getsignal(_signal.SIGINT) == _signal.SIG_IGN:
        return None  # not a command; or started in the background by a shell: left ignored

    def interrupted(signum: int, frame: object) -> None:
        _ = signum, frame
        os.write(2, f"{name}: interrupted [exit {EXIT_INTERRUPTED}]\n".encode())
        os._exit(EXIT_INTERRUPTED)

    try:
        _signal.signal(_signal.SIGINT, interrupted)
    except ValueError:  # imported in another thread than the main one
        return None
    return name


_NAME = _install()

# Only now: a Ctrl-C while these load is already one line (isort: the order matters).
import atexit  # noqa: E402
import signal  # noqa: E402
import threading  # noqa: E402
from types import FrameType  # noqa: E402


def _exiting() -> bool:
    """True once the main thread has ended: the interpreter exits (its exit hooks run)."""
    return not threading.main_thread().is_alive()


def _interrupt(signum: int, frame: FrameType | None) -> None:
    """A command's Ctrl-C: KeyboardInterrupt for ``main()``; ignored once Python exits."""
    _ = signum, frame
    if _exiting():
        return  # an exit hook (a robot's withdraw or stop) runs to its end
    raise KeyboardInterrupt


def handled_by_main() -> None:
    """Hand Ctrl-C to ``main()`` as a :class:`KeyboardInterrupt` (Python's default handler
    outside a command; in a command, one that is quiet once the interpreter exits)."""
    if threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        handler = signal.default_int_handler if _NAME is None else _interrupt
        signal.signal(signal.SIGINT, handler)


def _pause(point: str) -> None:
    """The test hook (:data:`_PAUSE_AT`)."""
    if os.environ.get(_PAUSE_AT) == point:
        os.write(2, f"tmmaster-test: paused at {point}\n".encode())
        os.read(0, 1)


if _NAME is not None and os.environ.get(_PAUSE_AT) == "exit":
    atexit.register(_pause, "exit")  # registered first: runs last of the exit hooks
_pause("import")


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
            if _exiting():
                return  # an exit hook's: the program is over, nothing left to interrupt
            if previous is signal.SIG_DFL:
                signal.raise_signal(signal.SIGINT)
            elif callable(previous):
                previous(signal.SIGINT, None)
