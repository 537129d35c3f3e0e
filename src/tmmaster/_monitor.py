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

A robot this process also commands is watched over the Robot's own link
(:meth:`StatusMonitor.add_robot`): a worker thread takes the transport's lock only when
it is free (never waiting for it), reads with no retry and no reconnect, and gives the
lock back; a slot that finds the link busy is skipped. A Modbus slave that accepts one
client then sees one client. A robot watched over a link of the monitor's own
(:meth:`StatusMonitor.add`) is reconnected after a doubling back-off, never on every
slot, so a monitor that lost the only slot to a Robot does not keep taking it back.

Decoding is the library's own: the channel of the robot's profile names the status
fields (:attr:`CommandChannel.status_fields`), :class:`ReadPlan` groups and decodes them
exactly as ``Robot.status()`` does, and :meth:`CommandChannel.status_from` builds the
same :class:`RobotStatus`. The link maps pymodbus failures to tmmaster's
:class:`TransportError` subclasses (as the sync transport does); the monitor stores
them, never raises them.
"""

from __future__ import annotations

import asyncio
import time
import weakref
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Self

from ._address import check_host, check_port, is_in_process
from ._channels import CommandChannel, channel_for
from ._checks import Bounds, require_in
from ._codec import Value
from ._commanded import commanding
from ._exceptions import (
    ConfigError,
    ConnectError,
    ConnectionLostError,
    ModbusExceptionError,
    TMMasterError,
    TransportError,
)
from ._fleet import LoopTransport
from ._logging import get_logger
from ._loop import EventLoopName, LoopThread, MonitoredStatus, StatusRecord, poll_on_schedule
from ._profiles import DEFAULT_PROFILE, robot_profile
from ._registers import RobotProfile
from ._robot import Robot
from ._transport import AsyncLink, ConnectionState, ReadPlan, Transport, describe_read

_log = get_logger("tmmaster.monitor")

#: Worker threads that read robots' own links (one read outstanding per robot at most):
#: beyond this many robots, a slot's read may wait for a worker (and be late or skipped).
_MAX_READ_WORKERS = 32


class _UnusedLink(Transport):
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


class _Watched(StatusRecord):
    """One robot of a monitor: its link, plan and counters (touched by the loop thread only).

    After a refused connect or a lost link, the next connect waits: one period after the
    first loss in a row, doubling with each further one up to ``backoff_max_s``. The row
    starts again only once a link stayed up ``backoff_max_s``: a link the slave keeps
    closing (another client took the only slot) is not retried on every slot.
    """

    def __init__(
        self, link: AsyncLink, profile: RobotProfile, *, period: float, backoff_max_s: float
    ) -> None:
        super().__init__(link.name, _log.bind(robot=link.name, host=link.host, port=link.port))
        #: The robot's link (its name, address, unit id and answer timeout).
        self.link = link
        self._period = period
        self._backoff_max_s = backoff_max_s
        #: Refused connects and lost links in a row (the back-off's exponent).
        self._losses = 0
        #: ``time.monotonic()`` before which no connect is tried.
        self._retry_at = 0.0
        #: When the current link opened (None while there is none).
        self._opened_at: float | None = None
        unused = _UnusedLink(
            link.host,
            link.port,
            device_id=link.device_id,
            timeout=link.timeout,
            retry=None,
            name=link.name,
        )
        self.channel: CommandChannel = channel_for(profile, unused)
        self.plan = ReadPlan.build(self.channel.status_fields, max_gap=profile.max_read_gap)
        #: Per block of the plan: (table, address, count, description).
        self.reads = tuple(
            (b.table, b.address, b.count, describe_read(b.table, b.address, b.count))
            for b in self.plan.blocks
        )

    async def connect(self) -> None:
        """Open a fresh link; on failure record the :class:`ConnectError` and back off."""
        try:
            await self.link.connect()
        except ConnectError as exc:
            self._lost(exc)
        else:
            self._opened_at = time.monotonic()
            self._log.debug("monitor.connected")

    def _lost(self, error: TransportError) -> None:
        """A refused connect or a lost link: the link closed, the failure recorded, and
        when the next connect may be tried."""
        self.drop()
        now = time.monotonic()
        if self._opened_at is not None and now - self._opened_at >= self._backoff_max_s:
            self._losses = 0  # the link had been up a while: a new row of losses begins
        self._opened_at = None
        self._losses += 1
        # The exponent is bounded: 2**64 periods exceed any cap anyway.
        delay = min(self._period * 2.0 ** min(self._losses - 1, 64), self._backoff_max_s)
        self._retry_at = now + delay
        self._log.debug("monitor.backing_off", delay_s=round(delay, 3), losses=self._losses)
        self.fail(error)

    def drop(self) -> None:
        """Close the link: after a failure the stream may still carry a late answer."""
        self.link.close()

    async def poll(self) -> None:
        """Read the status blocks once, decode them and publish the status or the failure.

        Without a link, a slot before the back-off's end is skipped and counted; the
        first slot after it connects.
        """
        if not self.link.connected:
            if self._opened_at is not None:  # the peer closed the link between two polls
                self._lost(ConnectionLostError(f"{self.name}: the robot closed the link"))
                return
            if time.monotonic() < self._retry_at:
                self.skip(1)
                return
            await self.connect()
            if not self.link.connected:
                return
        try:
            answers = [await self.link.read_block(*read) for read in self.reads]
            status = self.channel.status_from(self.plan.decode(answers))
        except ModbusExceptionError as exc:
            self.fail(exc)  # the device answered: the link is fine
            return
        except TransportError as exc:
            self._lost(exc)
            return
        self.succeed(status)


class _SharedWatched(StatusRecord):
    """A robot watched over the :class:`~tmmaster.Robot`'s own link (one connection in all).

    The robot's transport is blocking and guarded by its lock: each poll runs in a worker
    thread that takes the lock only when it is free, reads the status with no retry and
    no reconnect, and gives the lock back. A slot that finds the robot's thread (or
    another) using the link is skipped and counted; a link that is down is a failure,
    never reopened from here: only the robot's own requests reconnect it.
    """

    def __init__(self, name: str, transport: Transport, channel: CommandChannel) -> None:
        super().__init__(
            name, _log.bind(robot=name, host=transport.host, port=transport.port, shared=True)
        )
        self.transport = transport
        self.channel = channel
        self.executor: ThreadPoolExecutor | None = None

    async def connect(self) -> None:
        """Nothing: the robot opens its link (``Robot.connect``), never the monitor."""

    def drop(self) -> None:
        """Nothing: the link is the robot's, closed by ``Robot.close``."""

    async def poll(self) -> None:
        """Read the status in a worker thread; publish it, the failure, or a skipped slot."""
        loop = asyncio.get_running_loop()
        try:
            values = await loop.run_in_executor(self.executor, self._read_if_free)
        except TMMasterError as exc:
            self.fail(exc)
            return
        if values is None:
            self.skip(1)  # the robot is using its link: the next slot tries again
            return
        self.succeed(self.channel.status_from(values))

    def _read_if_free(self) -> dict[str, Value] | None:
        """In a worker thread: the status fields' values; None when the link is busy."""
        transport = self.transport
        # Never wait for the robot: its thread may hold the lock for a whole retried
        # request, and a stop it sends must not queue behind a monitor's read.
        if not transport.hold():
            return None
        try:
            # Checked under the lock: nobody can reconnect or close the link meanwhile.
            if transport.state is not ConnectionState.CONNECTED or not transport._link_open():
                raise ConnectionLostError(
                    f"{self.name}: the robot's link is not connected"
                    " (a StatusMonitor never opens or reopens a Robot's link)"
                )
            # No retry (its sleeps would hold the lock) and so no reconnect: a failure
            # drops the link as any failed request does, and the robot's next request
            # reconnects it.
            return transport.read_fields(
                self.channel.status_fields,
                max_gap=self.channel.profile.max_read_gap,
                retry=False,
                interruptible=False,
            )
        finally:
            transport.release()


def _refuse_commanded(name: str, host: str, port: int) -> None:
    """Refuse a link of the monitor's own to an address a Robot of this process commands."""
    commander = commanding(host, port)
    if commander is not None:
        raise ConfigError(
            f"StatusMonitor.add({name!r}, {host!r}, {port}): Robot {commander!r} of this"
            " process commands that address; a second connection could lock it out or"
            " take the connection its stop needs. Watch it over its own link:"
            f" monitor.add_robot(robot, name={name!r})"
        )


class StatusMonitor:
    """Watch the status of many robots from one thread: read-only, for dashboards and supervision.

    One background thread runs one asyncio event loop; every robot is polled at
    ``rate_hz`` on its own drift-free schedule (phases spread over the period; a slot
    that comes while the last read is still outstanding is skipped and counted). Each
    poll reads and decodes the profile's status registers exactly as
    :meth:`Robot.status` does and yields the same :class:`RobotStatus`.

    Two ways to watch a robot:

    * :meth:`add_robot`: over a :class:`Robot`'s own link, for a robot this process also
      commands (the default for those: a Modbus slave may accept only one client). The
      monitor opens no connection; it reads between the robot's requests, only when the
      link is free, and skips the slot otherwise.
    * :meth:`add`: over a Modbus TCP link of the monitor's own, for robots nobody in this
      process commands. After a refused connect or a lost link it reconnects after a
      back-off (one period, doubling per loss in a row, at most ``backoff_max_s``).

    It NEVER writes a register. Commanding stays with :class:`Robot`, one per thread,
    whose safety rules (command checks, withdraws, bounded waits) are not copied here.
    Failures are never raised: each robot's last error (a :class:`TransportError`
    subclass) is kept in :meth:`latest`.

    Example:
        Watching the simulator (``python -m tmmaster.sim --port 5020``) for a second:

        ```python
        import time

        from tmmaster import StatusMonitor

        monitor = StatusMonitor(rate_hz=10)
        monitor.add("cell-1", "127.0.0.1", 5020)
        with monitor:  # started here, closed at the end
            time.sleep(1.0)
            seen = monitor.latest("cell-1")
            print(seen.polls, seen.status.mode if seen.status else seen.error)
        ```

    Args:
        rate_hz: Polls per second of each robot, at most :attr:`MAX_RATE_HZ`.
        timeout_s: The answer timeout of the monitor's own links (a shared robot's
            reads use the robot's request timeout), within
            :attr:`MIN_TIMEOUT_S`..:attr:`MAX_TIMEOUT_S`.
        backoff_max_s: The longest wait before reconnecting an own link, at most
            :attr:`MAX_BACKOFF_S`.
        event_loop: ``"auto"`` runs on uvloop when it is installed (``pip install
            'tmmaster[monitor]'``), else on asyncio's own loop; ``"asyncio"`` or
            ``"uvloop"`` choose. uvloop's loop takes about a quarter to a third off the
            monitor's CPU at a few hundred robots (docs/performance.md).

    Raises:
        ConfigError: An argument out of its range (named in the message).
    """

    #: The fastest poll rate (Hz) per robot: a TM status is up to six Modbus requests, so
    #: 100 Hz is already 600 requests a second to one slave, which also serves the
    #: robot's own program and its commanding master (docs/robot-api.md).
    MAX_RATE_HZ = 100.0
    #: The slowest poll rate (Hz): one poll every 100 s.
    MIN_RATE_HZ = 0.01
    #: The answer timeouts (s) a Modbus TCP link can sensibly use: below 10 ms even a
    #: loaded loopback misses answers; beyond a minute a dead robot goes unnoticed.
    MIN_TIMEOUT_S = 0.01
    #: The longest answer timeout, s.
    MAX_TIMEOUT_S = 60.0
    #: The longest reconnect back-off (s) that may be asked for.
    MAX_BACKOFF_S = 3600.0

    def __init__(
        self,
        *,
        rate_hz: float = 20.0,
        timeout_s: float = 1.0,
        backoff_max_s: float = 5.0,
        event_loop: EventLoopName = "auto",
    ) -> None:
        #: Polls per second of each robot.
        self.rate_hz = require_in(
            "rate_hz", rate_hz, Bounds(self.MIN_RATE_HZ, self.MAX_RATE_HZ, "Hz")
        )
        #: The answer timeout of the monitor's own links, s.
        self.timeout_s = require_in(
            "timeout_s", timeout_s, Bounds(self.MIN_TIMEOUT_S, self.MAX_TIMEOUT_S, "s")
        )
        #: The longest wait before reconnecting an own link, s.
        self.backoff_max_s = require_in(
            "backoff_max_s", backoff_max_s, Bounds(0.0, self.MAX_BACKOFF_S, "s", open_low=True)
        )
        self._runner = LoopThread(event_loop, name="tmmaster-monitor", owner="StatusMonitor")
        #: The event loop the monitor runs on: "uvloop" or "asyncio".
        self.event_loop = self._runner.event_loop
        self._robots: dict[str, _Watched | _SharedWatched] = {}
        self._executor: ThreadPoolExecutor | None = None
        self._closed = False
        #: Set to a list before start() to record (lateness s, response s) of every
        #: answered poll (benchmarks); None records nothing.
        self._timings: list[tuple[float, float]] | None = None

    # -- configuration ----------------------------------------------------------------

    def _check_name(self, name: object) -> None:
        """ConfigError unless robots may still be added under ``name``."""
        if self._runner.thread is not None or self._closed:
            raise ConfigError("add robots before StatusMonitor.start()")
        if not isinstance(name, str) or not name:
            raise ConfigError(f"name must be a non-empty string, got {name!r}")
        if name in self._robots:
            raise ConfigError(f"name {name!r} is already watched by this StatusMonitor")

    def add(
        self,
        name: str,
        host: str,
        port: int = 502,
        *,
        profile: str | Path | RobotProfile = DEFAULT_PROFILE,
    ) -> None:
        """Add a robot to watch over a Modbus TCP link of the monitor's own, before :meth:`start`.

        For a robot this process also commands, use :meth:`add_robot`: a slave that
        accepts one client cannot serve both links, so an address that an open
        :class:`~tmmaster.Robot` of this process was made for (the same host string and
        port) is refused here, and again at :meth:`start` for a Robot made since.

        Args:
            name: The robot's name in :meth:`latest` and :meth:`snapshot`.
            host: The robot's address (Modbus TCP; no ``sim://`` endpoints).
            port: Its Modbus TCP port.
            profile: The register profile it speaks (a built-in name, a TOML path or a
                :class:`RobotProfile`).

        Raises:
            ConfigError: After :meth:`start`, naming a bad argument, or naming the open
                Robot of this process that commands ``host``:``port`` (watch it with
                :meth:`add_robot`).
            RegisterMapError: The profile cannot be loaded.
        """
        self._check_name(name)
        host = check_host(host)
        if is_in_process(host):
            raise ConfigError(
                f"host {host!r}: a StatusMonitor polls over Modbus TCP (no in-process endpoints)"
            )
        port = check_port(port)
        _refuse_commanded(name, host, port)
        robot = robot_profile(profile)
        link = AsyncLink(host, port, device_id=robot.device_id, timeout=self.timeout_s, name=name)
        period = 1.0 / self.rate_hz
        self._robots[name] = _Watched(link, robot, period=period, backoff_max_s=self.backoff_max_s)

    def add_robot(self, robot: Robot, name: str | None = None) -> str:
        """Watch ``robot`` over its own link (no second connection), before :meth:`start`.

        Each poll runs in a worker thread: it takes the robot link's lock only when it is
        free (never waiting for the robot's requests), reads the status once with no
        retry and no reconnect (the robot's request timeout bounds it), and gives the lock
        back; a slot that finds the link busy is skipped and counted. While the robot's
        link is down (not connected yet, lost, closed) each slot records a
        :class:`ConnectionLostError` and the monitor leaves the link alone: only the
        robot's own requests reconnect it. The reads count in ``robot.stats``.

        Args:
            robot: A :class:`Robot` (connected now or later) made without a Fleet as ``link=``.
            name: Its name here; the robot's ``name`` when None.

        Returns:
            The name it is watched under.

        Raises:
            ConfigError: After :meth:`start`; for a name or a robot already watched
                here, a closed robot, or a robot of a :class:`Fleet` (watched by
                ``Fleet(watch_hz=...)`` and read with ``Fleet.latest``).
        """
        if not isinstance(robot, Robot):
            raise ConfigError(f"robot must be a tmmaster.Robot, got {robot!r}")
        transport, channel = robot._transport, robot._channel
        name = robot.name if name is None else name
        self._check_name(name)
        for known, watched in self._robots.items():
            if isinstance(watched, _SharedWatched) and watched.transport is transport:
                raise ConfigError(f"that robot is already watched by this monitor as {known!r}")
        # A robot of a Fleet of the user's: that fleet watches it on its own loop.
        if isinstance(transport, LoopTransport) and not transport.on_default_driver:
            raise ConfigError(
                f"{robot.name!r} is a Fleet's robot: the Fleet watches it over its link;"
                " make the Fleet with watch_hz and read Fleet.latest(robot)"
            )
        if transport.state is ConnectionState.CLOSED:
            raise ConfigError(f"{robot.name!r} is closed: a StatusMonitor never reopens it")
        self._robots[name] = _SharedWatched(name, transport, channel)
        return name

    # -- reading ----------------------------------------------------------------------

    def latest(self, name: str) -> MonitoredStatus:
        """What was last seen of robot ``name``.

        Args:
            name: The name it was added under.

        Returns:
            Its last status (or the error of the last poll), and when.

        Raises:
            ConfigError: An unknown name (the message lists the names).
        """
        robot = self._robots.get(name)
        if robot is None:
            known = ", ".join(repr(n) for n in self._robots) or "none"
            raise ConfigError(f"no robot named {name!r} in this StatusMonitor (known: {known})")
        return robot.published

    def snapshot(self) -> dict[str, MonitoredStatus]:
        """What was last seen of every robot, by name.

        Returns:
            Each robot's last status, by name.
        """
        return {name: robot.published for name, robot in self._robots.items()}

    # -- lifecycle --------------------------------------------------------------------

    def start(self) -> Self:
        """Start the loop thread; return once every own link tried to connect (failures kept).

        Returns:
            The monitor.

        Raises:
            ConfigError: The monitor was closed.
        """
        if self._closed:
            raise ConfigError("a closed StatusMonitor cannot be restarted; make a new one")
        if self._runner.thread is not None:
            return self
        for robot in self._robots.values():
            if isinstance(robot, _Watched):  # a Robot made since add() commands it now?
                _refuse_commanded(robot.name, robot.link.host, robot.link.port)
        shared = [r for r in self._robots.values() if isinstance(r, _SharedWatched)]
        if shared and self._executor is None:
            self._executor = ThreadPoolExecutor(
                max_workers=min(len(shared), _MAX_READ_WORKERS),
                thread_name_prefix="tmmaster-monitor-read",
            )
            for robot in shared:
                robot.executor = self._executor
        # The loop holds no monitor: one dropped unclosed is garbage, and its loop ends.
        runner, robots, timings = self._runner, list(self._robots.values()), self._timings
        period = 1.0 / self.rate_hz
        try:
            runner.start(lambda: _watch(runner, robots, period, timings))
            weakref.finalize(self, runner.end_soon)
        except TransportError:
            self.close()
            raise
        return self

    def close(self) -> None:
        """Stop the loop, close every own link and join the threads; safe to call twice.

        A read outstanding on a robot's own link is waited for (its request timeout
        bounds it): it holds the robot's lock until it ends.
        """
        if self._closed:
            return
        self._closed = True
        self._runner.stop()
        executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()


async def _watch(
    runner: LoopThread, robots: list[_Watched | _SharedWatched], period: float, timings: Any
) -> None:
    """A monitor's loop: every robot polled on its schedule until the runner is stopped
    (it holds no monitor: a monitor dropped unclosed is garbage, its finalizer ends this)."""
    wake = runner.bind()
    tasks: list[asyncio.Task[None]] = []
    try:
        await asyncio.gather(*(robot.connect() for robot in robots))
        runner.ready()
        if not wake.is_set():  # not closed while connecting
            origin = time.monotonic()
            tasks = [
                asyncio.create_task(
                    poll_on_schedule(
                        robot,
                        robot.poll,
                        due=origin + period * i / len(robots),
                        period=period,
                        running=lambda: not wake.is_set(),
                        timings=timings,
                    ),
                    name=f"tmmaster-monitor-{robot.name}",
                )
                for i, robot in enumerate(robots)
            ]
            await wake.wait()
    finally:
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
