"""One asyncio event loop in one daemon thread, and what a watch of robots keeps.

:class:`LoopThread` runs a driver's loop (a :class:`~tmmaster.Fleet`'s, the process's
default driver's, a :class:`~tmmaster.StatusMonitor`'s); :class:`StatusRecord` and
:func:`poll_on_schedule` are the watch of one robot's status on such a loop, shared by
a Fleet's watch and a StatusMonitor.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
import time
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass, replace
from typing import Any, Literal

from ._exceptions import ConfigError, TMMasterError, TransportError
from ._logging import get_logger
from ._status import RobotStatus

_log = get_logger("tmmaster.loop")

#: How long close() waits for the loop thread (it stops within a loop turn normally).
_JOIN_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class MonitoredStatus:
    """What a :class:`StatusMonitor` last saw of one robot."""

    #: The last status read successfully (None before the first).
    status: RobotStatus | None
    #: ``time.monotonic()`` when that status's poll finished (None before the first).
    read_at: float | None
    #: The last failure (a :class:`TransportError` subclass), or None once a poll succeeds.
    error: TMMasterError | None
    #: Polls answered and decoded.
    polls: int
    #: Slots skipped because the robot's previous read (or connect) was still outstanding.
    skipped: int
    #: Polls (or connects) that failed.
    failures: int


_NOTHING_YET = MonitoredStatus(None, None, None, 0, 0, 0)

#: The event loops a monitor can run on.
EventLoopName = Literal["auto", "asyncio", "uvloop"]


def _loop_factory(event_loop: str) -> tuple[str, Callable[[], asyncio.AbstractEventLoop]]:
    """The loop a monitor runs on: ``uvloop`` when asked for (or installed, for ``auto``)."""
    if event_loop not in ("auto", "asyncio", "uvloop"):
        raise ConfigError(f"event_loop must be 'auto', 'asyncio' or 'uvloop', got {event_loop!r}")
    if event_loop == "asyncio":
        return "asyncio", asyncio.new_event_loop
    try:
        import uvloop
    except ImportError as exc:
        if event_loop == "uvloop":
            raise ConfigError(
                "event_loop='uvloop' needs uvloop: pip install 'tmmaster[monitor]'"
            ) from exc
        return "asyncio", asyncio.new_event_loop
    return "uvloop", uvloop.new_event_loop


class LoopThread:
    """One asyncio event loop in one daemon thread (a StatusMonitor's, a Fleet's).

    :meth:`start` runs the owner's main coroutine on a new loop and returns once that
    coroutine called :meth:`ready` (or failed: a bug, raised by ``start`` as a
    :class:`TransportError`); :meth:`stop` sets the event its :meth:`bind` gave
    and joins the thread.
    """

    def __init__(self, event_loop: str, *, name: str, owner: str) -> None:
        #: The event loop it runs: "uvloop" or "asyncio".
        self.event_loop, self._new_loop = _loop_factory(event_loop)
        self._name = name
        self._owner = owner
        self.thread: threading.Thread | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        #: Set (on the loop) to end the main coroutine's wait.
        self.wake: asyncio.Event | None = None
        self._started = threading.Event()
        self._crash: BaseException | None = None

    def start(self, main: Callable[[], Coroutine[Any, Any, None]]) -> None:
        """Run ``main()`` in the thread; return once it called :meth:`ready` (no-op if started)."""
        if self.thread is not None:
            return
        self.thread = threading.Thread(target=self._run, args=(main,), name=self._name, daemon=True)
        self.thread.start()
        self._started.wait()
        if self._crash is not None:
            raise TransportError(
                f"the {self._owner}'s loop failed: {self._crash!r}"
            ) from self._crash

    def bind(self) -> asyncio.Event:
        """From the main coroutine, first: the event :meth:`stop` will set."""
        self.loop = asyncio.get_running_loop()
        self.wake = asyncio.Event()
        return self.wake

    def ready(self) -> None:
        """From the main coroutine, after :meth:`bind`: the loop is up, :meth:`start` returns."""
        self._started.set()

    def end_soon(self) -> None:
        """Wake the main coroutine to end, without waiting for it (from any thread)."""
        if (loop := self.loop) is not None and (wake := self.wake) is not None:
            with contextlib.suppress(RuntimeError):  # the loop already ended
                loop.call_soon_threadsafe(wake.set)

    def stop(self) -> None:
        """Wake the main coroutine to end and join the thread (bounded); safe twice."""
        if self.thread is not None:  # bound first (start() may still be running): woken
            self._started.wait(_JOIN_TIMEOUT_S)
        self.end_soon()
        if (thread := self.thread) is not None and thread is not threading.current_thread():
            thread.join(_JOIN_TIMEOUT_S)
            if thread.is_alive():
                _log.warning(
                    "loop.thread_still_running", owner=self._owner, timeout_s=_JOIN_TIMEOUT_S
                )

    def _run(self, main: Callable[[], Coroutine[Any, Any, None]]) -> None:
        try:
            with asyncio.Runner(loop_factory=self._new_loop) as runner:
                runner.run(main())
        except BaseException as exc:  # a bug: reported by start(), never lost silently
            self._crash = exc
            _log.warning("loop.failed", owner=self._owner, error=repr(exc))
        finally:
            self._started.set()


class StatusRecord:
    """What was last seen of one watched robot, and the counters (touched by one loop only).

    A :class:`StatusMonitor`'s robots and a :class:`~tmmaster.Fleet`'s watched robots
    keep one each; readers in other threads see :attr:`published`.
    """

    def __init__(self, name: str, log: Any, *, events: str = "monitor") -> None:
        self.name = name
        self._failed_event = f"{events}.poll_failed"
        self._recovered_event = f"{events}.poll_recovered"
        #: The state, as readers see it: replaced (one reference assignment) after every
        #: change, never changed in place.
        self.published = _NOTHING_YET
        self._log = log

    def skip(self, slots: int) -> None:
        """Record ``slots`` slots that passed without a poll."""
        self.published = replace(self.published, skipped=self.published.skipped + slots)

    def fail(self, error: TMMasterError) -> None:
        """Record a failed poll (logged once as a warning, then at debug level)."""
        now = self.published
        log = self._log.warning if now.error is None else self._log.debug
        log(self._failed_event, error=str(error))
        self.published = replace(now, error=error, failures=now.failures + 1)

    def succeed(self, status: RobotStatus) -> None:
        """Record a poll's status."""
        now = self.published
        if now.error is not None:
            self._log.debug(self._recovered_event, failures=now.failures)
        self.published = replace(
            now, status=status, read_at=status.timestamp, error=None, polls=now.polls + 1
        )


async def poll_on_schedule(
    record: StatusRecord,
    poll: Callable[[], Awaitable[None]],
    *,
    due: float,
    period: float,
    running: Callable[[], bool],
    timings: list[tuple[float, float]] | None,
) -> None:
    """Poll one robot every ``period`` from ``due`` while ``running()``, drift-free.

    The slots that come while a poll is outstanding are skipped and counted, never sent
    late in a burst. ``timings``, when a list: (lateness, response) of every answered poll.
    """
    while running():
        delay = due - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
        sent = time.monotonic()
        await poll()
        now = time.monotonic()
        read_at = record.published.read_at
        if timings is not None and read_at is not None and read_at >= sent:
            timings.append((sent - due, now - sent))
        passed = math.floor((now - due) / period)
        if passed > 0:
            record.skip(passed)
        due += (max(passed, 0) + 1) * period
