"""A read-only status monitor for many robots, polled from one thread.

:class:`StatusMonitor` runs ONE asyncio event loop in ONE background thread, with one
:class:`AsyncLink` per robot (an asyncio protocol framed by pymodbus, in
``_transport.py`` with the other client-side pymodbus code; no retry, our own
timeout). Each robot is polled on its own drift-free schedule at ``rate_hz``, the
robots' phases spread evenly over the period; a slot that comes while the robot's
previous read is still outstanding is skipped and counted, never sent late in a burst.

It never writes a register: it is for watching fleets (dashboards, supervision) beyond
what one thread per :class:`~tmmaster.Robot` can poll. Commanding stays with ``Robot``
(one per thread), whose safety rules are not copied here.

Decoding is the library's own: the channel of the robot's profile names the status
fields (:attr:`CommandChannel.status_fields`), :class:`ReadPlan` groups and decodes them
exactly as ``Robot.status()`` does, and :meth:`CommandChannel.status_from` builds the
same :class:`RobotStatus`. The link maps pymodbus failures to tmmaster's
:class:`TransportError` subclasses (as the sync transport does); the monitor stores
them, never raises them.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
import time
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Self

from ._channels import CommandChannel, channel_for
from ._checks import require_positive
from ._codec import Value
from ._exceptions import (
    ConfigError,
    ConnectError,
    ModbusExceptionError,
    TMMasterError,
    TransportError,
)
from ._logging import get_logger
from ._profiles import DEFAULT_PROFILE, robot_profile
from ._registers import RobotProfile
from ._status import RobotStatus
from ._transport import AsyncLink, BlockTransport, ReadPlan, describe_read

_log = get_logger("tmmaster.monitor")

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
    :class:`TransportError`); :meth:`stop` wakes the coroutine's :meth:`ready` event
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

    def ready(self) -> asyncio.Event:
        """From the main coroutine: the loop is up; the event :meth:`stop` will set."""
        self.loop = asyncio.get_running_loop()
        if self.wake is None:
            self.wake = asyncio.Event()
        self._started.set()
        return self.wake

    def bind(self) -> asyncio.Event:
        """From the main coroutine, before :meth:`ready`: the event :meth:`stop` will set."""
        self.loop = asyncio.get_running_loop()
        self.wake = asyncio.Event()
        return self.wake

    def stop(self) -> None:
        """Wake the main coroutine to end and join the thread (bounded); safe twice."""
        loop, wake, thread = self.loop, self.wake, self.thread
        if loop is not None and wake is not None:
            with contextlib.suppress(RuntimeError):  # the loop already ended
                loop.call_soon_threadsafe(wake.set)
        if thread is not None and thread is not threading.current_thread():
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


class _UnusedLink(BlockTransport):
    """The transport a monitor's channel is built with: never used (the monitor reads async).

    A channel only needs it to exist; the monitor calls ``status_fields`` and
    ``status_from``, which read nothing. Any request through it is a bug.
    """

    def _link_open(self) -> bool:
        return False

    def _open_link(self) -> None:
        raise ConfigError("a StatusMonitor's channel never opens a link")

    def _close_link(self) -> None:
        return None

    def _exchange(
        self, what: str, function_code: int, address: int, count: int, values: list[int] | None
    ) -> list[int]:
        raise ConfigError(f"a StatusMonitor never sends requests through its channel ({what})")


class StatusRecord:
    """What was last seen of one watched robot, and the counters (touched by one loop only).

    A :class:`StatusMonitor`'s robots and a :class:`~tmmaster.Fleet`'s watched robots
    keep one each; readers in other threads see :attr:`published`.
    """

    def __init__(self, name: str, log: Any, *, events: str = "monitor") -> None:
        self.name = name
        self._failed_event = f"{events}.poll_failed"
        self._recovered_event = f"{events}.poll_recovered"
        self.status: RobotStatus | None = None
        self.read_at: float | None = None
        self.error: TMMasterError | None = None
        self.polls = 0
        self.skipped = 0
        self.failures = 0
        #: What readers see: replaced (one reference assignment) after every change.
        self.published = _NOTHING_YET
        self._log = log

    def publish(self) -> None:
        """Make the current state visible to readers."""
        self.published = MonitoredStatus(
            self.status, self.read_at, self.error, self.polls, self.skipped, self.failures
        )

    def skip(self, slots: int) -> None:
        """Record ``slots`` slots that passed without a poll."""
        self.skipped += slots
        self.publish()

    def fail(self, error: TMMasterError) -> None:
        """Record a failed poll (logged once as a warning, then at debug level)."""
        if self.error is None:
            self._log.warning(self._failed_event, error=str(error))
        else:
            self._log.debug(self._failed_event, error=str(error))
        self.error = error
        self.failures += 1
        self.publish()

    def succeed(self, status: RobotStatus) -> None:
        """Record a poll's status."""
        if self.error is not None:
            self._log.debug(self._recovered_event, failures=self.failures)
        self.status = status
        self.read_at = status.timestamp
        self.error = None
        self.polls += 1
        self.publish()


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
        if timings is not None and record.read_at is not None and record.read_at >= sent:
            timings.append((sent - due, now - sent))
        passed = math.floor((now - due) / period)
        if passed > 0:
            record.skip(passed)
        due += (max(passed, 0) + 1) * period


class _Watched(StatusRecord):
    """One robot of a monitor: its link, plan and counters (touched by the loop thread only)."""

    def __init__(
        self, name: str, host: str, port: int, profile: RobotProfile, timeout_s: float
    ) -> None:
        super().__init__(name, _log.bind(robot=name, host=host, port=port))
        self.channel: CommandChannel = channel_for(
            profile,
            _UnusedLink(
                host, port, device_id=profile.device_id, timeout=timeout_s, retry=None, name=name
            ),
        )
        plan = ReadPlan.build(self.channel.status_fields, max_gap=profile.max_read_gap)
        #: Per block of the plan: (table, address, count, description, decoding slots).
        self.requests = tuple(
            (
                block.table,
                block.address,
                block.count,
                describe_read(block.table, block.address, block.count),
                slots,
            )
            for block, slots in zip(plan.blocks, plan.slots, strict=True)
        )
        self.link = AsyncLink(host, port, device_id=profile.device_id, timeout=timeout_s, name=name)

    async def connect(self) -> None:
        """Open a fresh link; on failure record the :class:`ConnectError`."""
        try:
            await self.link.connect()
        except ConnectError as exc:
            self.fail(exc)
        else:
            self._log.debug("monitor.connected")

    def drop(self) -> None:
        """Close the link: after a failure the stream may still carry a late answer."""
        self.link.close()

    async def poll(self) -> None:
        """Read the status blocks once, decode them and publish the status or the failure."""
        if not self.link.connected:
            await self.connect()
            if not self.link.connected:
                return
        read_block = self.link.read_block
        values: dict[str, Value] = {}
        try:
            for table, address, count, what, slots in self.requests:
                words = await read_block(table, address, count, what)
                for field_name, offset, decode in slots:
                    values[field_name] = decode(words, offset)
            status = self.channel.status_from(values)
        except ModbusExceptionError as exc:
            self.fail(exc)  # the device answered: the link is fine
            return
        except TransportError as exc:
            self.drop()
            self.fail(exc)
            return
        self.succeed(status)


class StatusMonitor:
    """Watch the status of many robots from one thread: read-only, for dashboards and supervision.

    One background thread runs one asyncio event loop with one Modbus TCP link per robot;
    every robot is polled at ``rate_hz`` on its own drift-free schedule (phases spread
    over the period; a slot that comes while the last read is still outstanding is
    skipped and counted). Each poll reads and decodes the profile's status registers
    exactly as :meth:`Robot.status` does and yields the same :class:`RobotStatus`.

    It NEVER writes a register. Commanding stays with :class:`Robot`, one per thread,
    whose safety rules (command checks, withdraws, bounded waits) are not copied here: use
    a monitor to watch more robots than one thread each can poll, not to drive them.
    Failures are never raised: each robot's last error (a :class:`TransportError`
    subclass) is kept in :meth:`latest`, and the link is retried on the next slot.

    ``event_loop``: ``"auto"`` (the default) runs on uvloop when it is installed
    (``pip install 'tmmaster[monitor]'``), else on asyncio's own loop; ``"asyncio"`` or
    ``"uvloop"`` choose. uvloop's loop takes about a quarter to a third off the
    monitor's CPU at a few hundred robots (docs/performance.md).
    """

    def __init__(
        self, *, rate_hz: float = 20.0, timeout_s: float = 1.0, event_loop: EventLoopName = "auto"
    ) -> None:
        self.rate_hz = require_positive("rate_hz", rate_hz)
        self.timeout_s = require_positive("timeout_s", timeout_s)
        self._runner = LoopThread(event_loop, name="tmmaster-monitor", owner="StatusMonitor")
        #: The event loop the monitor runs on: "uvloop" or "asyncio".
        self.event_loop = self._runner.event_loop
        self._robots: dict[str, _Watched] = {}
        self._stopping = False
        self._closed = False
        #: Set to a list before start() to record (lateness s, response s) of every
        #: answered poll (benchmarks); None records nothing.
        self._timings: list[tuple[float, float]] | None = None

    # -- configuration ----------------------------------------------------------------

    def add(
        self,
        name: str,
        host: str,
        port: int = 502,
        *,
        profile: str | Path | RobotProfile = DEFAULT_PROFILE,
    ) -> None:
        """Add a robot to watch, before :meth:`start` (ConfigError naming a bad argument)."""
        if self._runner.thread is not None or self._closed:
            raise ConfigError("add robots before StatusMonitor.start()")
        if not isinstance(name, str) or not name:
            raise ConfigError(f"name must be a non-empty string, got {name!r}")
        if name in self._robots:
            raise ConfigError(f"name {name!r} is already watched by this StatusMonitor")
        if not isinstance(host, str) or not host:
            raise ConfigError(f"host must be a non-empty string, got {host!r}")
        if "://" in host:
            raise ConfigError(
                f"host {host!r}: a StatusMonitor polls over Modbus TCP (no in-process endpoints)"
            )
        if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
            raise ConfigError(f"port must be 1..65535, got {port!r}")
        self._robots[name] = _Watched(name, host, port, robot_profile(profile), self.timeout_s)

    # -- reading ----------------------------------------------------------------------

    def latest(self, name: str) -> MonitoredStatus:
        """What was last seen of robot ``name`` (ConfigError listing the names when unknown)."""
        robot = self._robots.get(name)
        if robot is None:
            known = ", ".join(repr(n) for n in self._robots) or "none"
            raise ConfigError(f"no robot named {name!r} in this StatusMonitor (known: {known})")
        return robot.published

    def snapshot(self) -> dict[str, MonitoredStatus]:
        """What was last seen of every robot, by name."""
        return {name: robot.published for name, robot in self._robots.items()}

    # -- lifecycle --------------------------------------------------------------------

    def start(self) -> Self:
        """Start the loop thread; return once every link tried to connect (failures are kept)."""
        if self._closed:
            raise ConfigError("a closed StatusMonitor cannot be restarted; make a new one")
        try:
            self._runner.start(self._main)
        except TransportError:
            self.close()
            raise
        return self

    def close(self) -> None:
        """Stop the loop, close every link and join the thread; safe to call more than once."""
        if self._closed:
            return
        self._closed = True
        self._stopping = True
        self._runner.stop()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- the loop thread --------------------------------------------------------------

    async def _main(self) -> None:
        wake = self._runner.bind()
        robots = list(self._robots.values())
        tasks: list[asyncio.Task[None]] = []
        try:
            await asyncio.gather(*(robot.connect() for robot in robots))
            self._runner.ready()
            if not self._stopping:
                origin = time.monotonic()
                period = 1.0 / self.rate_hz
                tasks = [
                    asyncio.create_task(
                        self._watch(robot, origin + period * i / len(robots), period),
                        name=f"tmmaster-monitor-{robot.name}",
                    )
                    for i, robot in enumerate(robots)
                ]
                await wake.wait()
        finally:
            self._stopping = True
            pending = set(tasks)
            while pending:  # a cancellation that meets an answer may be lost: cancel again
                for task in pending:
                    task.cancel()
                _done, pending = await asyncio.wait(pending, timeout=0.1)
            for robot in robots:
                robot.drop()
            # Closing transports release their sockets on a later loop turn.
            for _ in range(3):
                await asyncio.sleep(0)

    async def _watch(self, robot: _Watched, due: float, period: float) -> None:
        """Poll one robot on its schedule until cancelled or stopping."""
        await poll_on_schedule(
            robot,
            robot.poll,
            due=due,
            period=period,
            running=lambda: not self._stopping,
            timings=self._timings,
        )
