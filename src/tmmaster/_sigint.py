"""Ctrl-C in tmmaster's commands, and the critical sections it must not cut short.

Nothing happens when this module is imported: a program that imports tmmaster keeps its
own Ctrl-C handling. Each command's ``main()`` runs through :func:`run_main`, the one
place a command handles Ctrl-C:

- the first Ctrl-C raises :class:`KeyboardInterrupt` wherever the command is, so its
  clean-up runs as for any exception (a robot withdraws or stops its command, a
  simulator closes); :func:`run_main` turns it into one line,
  ``PROG: interrupted [exit 130]``, never a traceback;
- any later Ctrl-C is ignored, so it cuts short neither the clean-up, nor that line,
  nor Python's exit hooks (a robot still open withdraws or stops its command there);
- a command that winds down by itself on the first Ctrl-C (a pick & place run stops the
  arm and writes its report) asks for that with :func:`first_stops`;
- in a command's process, SIGTERM (a supervisor's stop) and SIGHUP (its terminal hung up)
  do what Ctrl-C does at that moment, unless the command started with Ctrl-C ignored
  (``command &``) or with them ignored (``nohup``): then they keep their handling.

A Ctrl-C before ``main()`` runs, while tmmaster and the command's modules load, is
:mod:`tmmaster._startup`'s: the same line and exit 130 (before tmmaster's first line
runs, Python's own traceback). Nothing is connected or started then.

:class:`deferred` is the critical section, for commands and library programs alike: a
withdraw or a stop runs to its end, and a Ctrl-C that came meanwhile is delivered after it.
"""

from __future__ import annotations

import _thread
import atexit
import functools
import gc
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from types import FrameType
from typing import Any

#: Exit status of an interrupted command (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130

#: The signals that end a command's process as Ctrl-C does: a supervisor's stop (``kill``,
#: ``systemctl stop``, ``docker stop``) and a terminal's hang-up (an SSH session lost).
_ENDING = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))

#: Test hook: ``start`` or ``exit``: a command says so on stderr there and waits for a
#: byte on stdin (a test sends Ctrl-C at that very point instead of after a guessed delay).
_PAUSE_AT = "TMMASTER_TEST_SIGINT_AT"


def _in_main_thread() -> bool:
    """True in the main thread, the only one Python runs signal handlers in (asked by
    ident: ``current_thread()`` in a ``_thread`` thread would register a dummy thread)."""
    return threading.get_ident() == threading.main_thread().ident


def _ignore() -> None:
    """From now on a Ctrl-C, and a SIGTERM or SIGHUP doing what it does, change nothing
    (main thread only: elsewhere it cannot be set). Ignored, not handled by a function:
    Python puts a function handler back to the default as it exits, and a late SIGTERM
    would kill."""
    if _in_main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        for ending in _ENDING:
            if signal.getsignal(ending) is _as_ctrl_c:
                signal.signal(ending, signal.SIG_IGN)


def _interrupt_once(_signum: int, _frame: FrameType | None) -> None:
    """A command's first Ctrl-C: a KeyboardInterrupt; any later one is ignored.

    Ignoring comes first, so a Ctrl-C arriving while this runs finds SIG_IGN: at most
    one KeyboardInterrupt comes out, whatever the number of Ctrl-C.
    """
    _ignore()  # a signal handler runs in the main thread
    raise KeyboardInterrupt


def _as_ctrl_c(_signum: int, frame: FrameType | None) -> None:
    """SIGTERM or SIGHUP (:data:`_ENDING`) does what a Ctrl-C would do now: the command
    winds down as after Ctrl-C, never gone at once with its arm moving (ignored once
    Ctrl-C is, so it cannot cut a clean-up short)."""
    if callable(handler := signal.getsignal(signal.SIGINT)):
        handler(signal.SIGINT, frame)


def _deliver_dropped(hook: Callable[[Any], object], unraisable: Any) -> None:
    """``sys.unraisablehook`` while a command runs: a Ctrl-C's KeyboardInterrupt raised
    where Python drops exceptions (a garbage collection's callback, a ``__del__``) is
    delivered again in the main thread, instead of lost with Ctrl-C ignored from then on."""
    if unraisable.exc_type is not KeyboardInterrupt or not _in_main_thread():
        hook(unraisable)
        return
    signal.signal(signal.SIGINT, _interrupt_once)
    # From another thread: called here, the handler would raise inside this hook again.
    _thread.start_new_thread(_thread.interrupt_main, ())


def _pause(point: str) -> None:
    """The test hook (:data:`_PAUSE_AT`)."""
    if os.environ.get(_PAUSE_AT) == point:
        os.write(2, f"tmmaster-test: paused at {point}\n".encode())
        os.read(0, 1)


def run_main(prog: str, body: Callable[[], int], *, process: bool) -> int:
    """Run a command's ``body`` so that Ctrl-C ends it in one line and exit 130.

    Every command's ``main()`` runs through this (``tmmaster``, ``python -m
    tmmaster.pickplace``, ``.sim``, ``.report``, ``.tmscript``). A run started with
    Ctrl-C ignored (``command &`` in a script) leaves it ignored. Nested (``tmmaster
    pickplace`` runs pickplace's under tmmaster's), the inner one names the command.

    Args:
        prog: The command's name, the start of its line (``pickplace``).
        body: Runs the command; returns its exit status.
        process: True when the command is the process itself (its ``__main__``, the
            console script): SIGTERM and SIGHUP do what Ctrl-C does (where their
            handling is the default), and Ctrl-C stays ignored once ``body`` returns,
            while Python exits. False (a caller in the same process, a test): the
            caller's handler is put back, and SIGTERM and SIGHUP are left alone.

    Returns:
        ``body``'s status; :data:`EXIT_INTERRUPTED` after a Ctrl-C.
    """
    previous = signal.getsignal(signal.SIGINT) if _in_main_thread() else None
    hook = sys.unraisablehook
    if previous is not None and previous is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, _interrupt_once)
        sys.unraisablehook = functools.partial(_deliver_dropped, hook)
        for ending in _ENDING if process else ():  # the process ends with the command
            if signal.getsignal(ending) is signal.SIG_DFL:
                signal.signal(ending, _as_ctrl_c)
    if process and os.environ.get(_PAUSE_AT) == "exit":
        atexit.register(_pause, "exit")  # registered before any robot's: runs after them
    try:
        if process:
            # The process ends with this command: its objects are left to the operating
            # system (registered before any robot's exit hook, this runs after them).
            # Python's last collections would traverse the whole heap again, about 0.1 s
            # of CPU for memory about to be freed; what else runs at exit (logging's
            # flush, objects freed as the modules go) runs as before.
            atexit.register(gc.freeze)
            _pause("start")
        return body()
    except (KeyboardInterrupt, RuntimeError) as exc:
        # Python 3.11 wraps a KeyboardInterrupt raised in a class's __set_name__ (a
        # dataclass field's, while a module loads) in a RuntimeError: a Ctrl-C too.
        interrupt = exc.__cause__ if isinstance(exc, RuntimeError) else exc
        if not isinstance(interrupt, KeyboardInterrupt):
            raise
        _ignore()  # also when the KeyboardInterrupt came from elsewhere (interrupt_main)
        with suppress(OSError):  # stderr a terminal that hung up (SIGHUP): said to nobody
            print(f"{prog}: interrupted [exit {EXIT_INTERRUPTED}]", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED
    finally:
        if not process:
            sys.unraisablehook = hook
        _hand_back(previous, process=process)


def _hand_back(previous: object, *, process: bool) -> None:
    """:func:`run_main`'s way out: what a Ctrl-C does after the command."""
    if process:
        _ignore()  # the process only exits now
        # CPython remembers a KeyboardInterrupt that ended code it ran from a string
        # (``exec``/``eval`` of source text: dataclasses and namedtuple make their methods
        # so) even when a caller caught it, and under ``python -m`` it then kills the
        # process with SIGINT at exit: status -2 instead of the 130 ``main()`` returned.
        # Any later evaluation of source text clears that memory; this is one.
        exec("", {})  # the empty program: clears that record, runs nothing
    # Else: not set here (another thread), or left ignored; or nested in a command that a
    # Ctrl-C ends too (its handler, Ctrl-C ignored now): it stays ignored.
    elif previous not in (None, signal.SIG_IGN) and (
        previous is not _interrupt_once or signal.getsignal(signal.SIGINT) is not signal.SIG_IGN
    ):
        signal.signal(signal.SIGINT, previous)  # type: ignore[arg-type]


@contextmanager
def first_stops(stop: Callable[[], None], *, noted: Callable[[], None]) -> Iterator[None]:
    """While the block runs, the first Ctrl-C calls ``stop`` instead of interrupting.

    The command then winds down by itself (a pick & place run stops the arm, writes its
    report and says how it ended). A second Ctrl-C gives up at once: a
    :class:`KeyboardInterrupt` (a :class:`deferred` withdraw or stop still runs to its
    end); any later one is ignored. After a Ctrl-C, Ctrl-C stays ignored once the block
    ends: the command only says how it ended. Outside the main thread, or with Ctrl-C
    ignored, it changes nothing.

    Args:
        stop: Asks the command to stop (sets events: thread-safe). It runs in a thread
            of its own, started at once: the handler may have interrupted the main
            thread inside the very lock ``stop`` takes (an Event's, while the main thread
            waits on it), which ``stop`` then waits for instead of deadlocking.
        noted: Called in the handler itself at each Ctrl-C, before anything it sets off
            (it must only set a flag): the command knows it was interrupted even when a
            second Ctrl-C's clean-up runs before ``stop``'s thread does.

    Yields:
        Nothing.
    """
    previous = signal.getsignal(signal.SIGINT) if _in_main_thread() else None
    if previous is None or previous is signal.SIG_IGN:
        yield
        return
    pressed = False

    def handler(signum: int, frame: FrameType | None) -> None:
        nonlocal pressed
        noted()
        if pressed:
            _interrupt_once(signum, frame)
        pressed = True
        # _thread, not threading: Thread.start() takes locks of its own the main thread
        # may hold at this point.
        _thread.start_new_thread(stop, ())

    signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        if signal.getsignal(signal.SIGINT) is handler:
            signal.signal(signal.SIGINT, signal.SIG_IGN if pressed else previous)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold Ctrl-C back for the length of a critical section, then deliver it.

    A withdraw or stop that a second Ctrl-C cuts short leaves a command armed. In the
    main thread (the only one that receives SIGINT), the handler is replaced by one that
    only records the signal; on exit the previous handler is restored and, if a signal
    came meanwhile, called once, so the interrupt still happens, just after the clean-up.
    Once the interpreter exits (an exit hook's section), a Ctrl-C held back is dropped:
    the program is over. Elsewhere (other threads, a handler Python did not install, or
    Ctrl-C ignored) it does nothing. Re-entrant: a nested section leaves the outer one's
    recorder in place.

    Yields:
        Nothing.
    """
    pending = False

    def record(_signum: int, _frame: FrameType | None) -> None:
        nonlocal pending
        pending = True

    record.deferring = True  # type: ignore[attr-defined]
    previous = signal.getsignal(signal.SIGINT) if _in_main_thread() else None
    if previous is signal.SIG_IGN or getattr(previous, "deferring", False):
        previous = None  # ignored, or an outer section's recorder: left in place
    try:
        if previous is not None:
            signal.signal(signal.SIGINT, record)
    except ValueError:  # not the main interpreter
        previous = None
    try:
        yield
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
            # Once the main thread has ended (an exit hook's section), the program is
            # over: nothing is left to interrupt.
            if pending and threading.main_thread().is_alive():
                if previous is signal.SIG_DFL:
                    signal.raise_signal(signal.SIGINT)
                elif callable(previous):
                    previous(signal.SIGINT, None)
