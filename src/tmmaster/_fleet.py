"""The driver: robots' links and the polls of their waits on one event loop per process.

A :class:`Fleet` runs ONE asyncio event loop in ONE background thread. The process has
one by default (``_DEFAULT.fleet``: started by the first network link that connects,
stopped when the last one closes), which every :class:`~tmmaster.Robot`, stand-alone
gripper and :class:`ModbusTransport` made without a ``link=`` of its own joins;
a Fleet a user makes is the same driver, owned explicitly. Every robot on a driver
keeps its own thread for what it decides
(checks, the command write, withdraws, stops: the blocking code of ``_robot.py``,
unchanged), but its connection lives on the fleet's loop (:class:`LoopTransport`), and
the polls of its waits run there too: the loop polls each waiting robot on the same
:class:`~tmmaster._robot.FollowState` schedule the thread would, through the channel's
one poll (:meth:`CommandChannel.poll_steps`), and wakes the robot's thread only when a
poll needs it (acknowledged, done, failed, a deadline passed). So 400 waiting robots
cost one thread's wake-ups, not 400 threads queueing for the GIL
(docs/performance.md).

Whenever the loop cannot poll as the thread would (a stop request, the link busy with
another thread's request, a failed read), it hands the poll back: the thread polls
itself, with the transport's retry policy. So every rule stays in one place: the loop
only ever decides "poll again".

Requests from a robot's thread go to the loop and the thread waits for the answer
(bounded by the request timeout): one connection per robot, requests in order.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import functools
import os
import threading
import time
import weakref
from collections.abc import Callable, Coroutine, Iterable
from dataclasses import dataclass, field
from typing import Any, Generic, Protocol, Self, TypeVar, cast

from ._address import check_host, check_port, is_in_process, scheme_opener
from ._channels import CommandChannel, Observation
from ._checks import require_positive
from ._codec import Value
from ._exceptions import (
    ConfigError,
    ConnectionLostError,
    ResponseTimeoutError,
    TransportClosedError,
    TransportError,
)
from ._following import FollowState
from ._gate import CommandGate
from ._logging import get_logger
from ._loop import EventLoopName, LoopThread, MonitoredStatus, StatusRecord, poll_on_schedule
from ._registers import RegisterField
from ._retry import RetryPolicy
from ._sigint import deferred
from ._transport import AsyncLink, Block, ConnectionState, Transport, settle

_log = get_logger("tmmaster.fleet")

T = TypeVar("T")


class _Closable(Protocol):
    """A fleet's robot, as the fleet sees it: something to close at the end."""

    name: str

    def close(self, *, timeout_s: float | None = None) -> bool:
        """Withdraw or stop what is outstanding, then close the links; True when confirmed."""
        ...


#: The fastest watch: a status read per robot every 10 ms. A TM robot's status is several
#: requests (the tmflow profile: six), each a round trip to a controller that serves other
#: clients too; faster than this only queues reads behind the robot's own commands.
MAX_WATCH_HZ = 100.0

#: Beyond a request's own timeout: how long a thread waits for the loop to answer at all.
_LOOP_GRACE_S = 1.0


class LoopTransport(Transport):
    """A robot's Modbus TCP link on a driver's event loop (a :class:`Fleet`'s).

    The robot's thread uses it like any transport (blocking, with the retry policy);
    each request is sent on the loop and the thread waits for its answer. The fleet's
    loop reads through :meth:`read_on_loop`, holding the same lock, so requests on the
    link never interleave. With ``fleet`` None the link is on the process's default
    driver (``_DEFAULT``): taken here, given back by :meth:`close` (or when
    the transport is garbage collected unclosed), its loop started by the first connect.
    """

    def __init__(
        self,
        fleet: Fleet | None,
        host: str,
        port: int,
        *,
        device_id: int,
        timeout: float,
        retry: RetryPolicy | None,
        name: str,
    ) -> None:
        super().__init__(host, port, device_id=device_id, timeout=timeout, retry=retry, name=name)
        self._link = AsyncLink(host, port, device_id=device_id, timeout=timeout, name=name)
        self._link.stats = self.stats
        # The driver taken and its release armed as one step: a Ctrl-C between them would
        # keep a default driver's loop running for good. The release runs by close(), or
        # once garbage unclosed (a Robot dropped without close()).
        with deferred():
            if default := fleet is None:
                fleet = _DEFAULT.acquire()
            self._release = weakref.finalize(self, _let_go, _DEFAULT, fleet, self._link)
            self._release.atexit = False  # at exit the daemon loop thread simply ends
        self._fleet, self._default = fleet, default

    @property
    def fleet(self) -> Fleet:
        """The driver this link lives on (the default one, or a Fleet of your own)."""
        return self._fleet

    @property
    def on_default_driver(self) -> bool:
        """True for a link on the process's default driver (not a Fleet of the user's)."""
        return self._default

    def close(self) -> None:
        """Close the link; safe to call more than once. A default driver's link gives it back."""
        super().close()
        self._release()  # once: a finalizer runs at most once

    # -- the link, from the robot's thread ----------------------------------------

    def _link_open(self) -> bool:
        return self._link.connected

    @property
    def state(self) -> ConnectionState:
        """Current connection state (a link the device closed is disconnected at once)."""
        lost = self._state is ConnectionState.CONNECTED and not self._link.connected
        return ConnectionState.DISCONNECTED if lost else self._state

    def _open_link(self) -> None:
        if self._default:
            self._fleet.start()  # the default driver's loop starts with its first link
        self._fleet._call(self._link.connect(), self.timeout + _LOOP_GRACE_S, self.name)

    def _close_link(self) -> None:
        if self._fleet._on_loop():
            self._link.close()
            return
        # Closed before this returns, as a socket of our own would be: a reconnect right
        # after must not find the old link still open.
        closed: _Latch[None] = _Latch()
        if self._fleet._call_soon(self._close_on_loop, closed):
            with contextlib.suppress(_NoAnswerError):
                closed.wait(_LOOP_GRACE_S)

    def _close_on_loop(self, closed: _Latch[None]) -> None:
        self._link.close()
        closed.settle(None)

    def _exchange(
        self, what: str, function_code: int, address: int, count: int, values: list[int] | None
    ) -> list[int]:
        # A callback on the loop and a lock to wait on: no task or coroutine per request
        # (about a third of a request's cost through run_coroutine_threadsafe).
        self._link.device_id = self.device_id  # the unit id may be changed between requests
        latch: _Latch[list[int]] = _Latch()
        start = self._link.start
        args = (what, function_code, address, count, values, latch.settle, latch.fail)
        return self._hand_over(what, self.timeout + _LOOP_GRACE_S, latch, start, *args)

    def _hand_over(
        self, what: str, bound: float, latch: _Latch[T], start: Callable[..., object], *args: Any
    ) -> T:
        """Run ``start(*args)`` on the loop and wait, at most ``bound`` s, for ``latch``.

        A request the loop has not started when the wait ends (no answer in time, Ctrl-C)
        is never started: a loop held up for longer than the bound must not send a
        command the robot has already given up on.
        """
        # Taken once, by whichever comes first: the loop starting the request, or this
        # thread giving it up.
        claim = threading.Lock()
        if not self._fleet._call_soon(lambda: claim.acquire(blocking=False) and start(*args)):
            raise TransportClosedError(f"{self.name}: the fleet is closed")
        try:
            return latch.wait(bound)
        except _NoAnswerError as exc:
            raise ResponseTimeoutError(
                f"{self.name}: the fleet's event loop did not answer {what}"
            ) from exc
        finally:
            claim.acquire(blocking=False)  # however the wait ended: never started after it

    def _read_blocks(
        self, blocks: tuple[Block, ...], retry: bool, interruptible: bool
    ) -> list[list[int]]:
        """Every block read on the loop in one go while the link is up, in one hand-over.

        Each request is sent once, one after the other, and the calling thread is woken
        once. A block that fails, and those after it, are read one at a time as any read
        is, with the retry policy: the failure counts as that block's first attempt.
        """
        self._yield_turn(interruptible)
        with self._lock:
            on_loop, up = self._fleet._on_loop(), self.state is ConnectionState.CONNECTED
            if on_loop or not up or not blocks:  # no blocks: nothing to hand over
                return super()._read_blocks(blocks, retry, interruptible)
            answers, failure = self._read_in_one_hand_over(blocks)
            for block in blocks[len(answers) :]:
                answers.append(
                    self._read_after(block, failure, retry=retry, interruptible=interruptible)
                )
                failure = None  # the failed block's first attempt was the hand-over's
            return answers

    def _read_in_one_hand_over(
        self, blocks: tuple[Block, ...]
    ) -> tuple[list[list[int]], BaseException | None]:
        """Every block's words, read on the loop in one go, up to the first failure."""
        requests = self._chained_requests(blocks)
        latch: _Latch[tuple[list[list[int]], BaseException | None]] = _Latch()
        chain = _ChainedRead(self, requests, latch.settle)
        bound = self.timeout * len(blocks) + _LOOP_GRACE_S
        try:
            answers, failure = self._hand_over(requests[0][0], bound, latch, chain.next)
        except TransportClosedError:
            raise  # the loop has ended: nothing was sent
        except BaseException as exc:  # no answer in time, or interrupted (Ctrl-C)
            self._request_failed(exc)  # an answer may still come
            raise
        if failure is not None:
            self._request_failed(failure)
        return answers, failure

    def _chained_requests(self, blocks: tuple[Block, ...]) -> list[tuple[str, int, Block]]:
        """Each block's (description, function code, block), for a :class:`_ChainedRead`."""
        self._link.device_id = self.device_id  # the unit id may be changed between reads
        return [(*self._read_request(b.table, b.address, b.count), b) for b in blocks]

    def _yield_turn(self, interruptible: bool) -> None:
        """Let a waiting heartbeat go first, never on the loop (the beat waits on it)."""
        if not self._fleet._on_loop():
            super()._yield_turn(interruptible)

    def _read_after(
        self, block: Block, first: BaseException | None, *, retry: bool, interruptible: bool
    ) -> list[int]:
        """One block read as :meth:`read_block` reads it; ``first``: its first attempt's failure."""
        what, function_code = self._read_request(block.table, block.address, block.count)
        failed = [first] if first is not None else []

        def once() -> list[int]:
            if failed:
                raise failed.pop()
            return self._read_once(what, function_code, block.address, block.count)

        return self._run(what, once, retry=retry, interruptible=interruptible)

    # -- the loop's side ------------------------------------------------------------

    def drop_on_loop(self) -> None:
        """From the loop, as it ends: close the link (a later request reconnects, and fails)."""
        self._link.close()

    async def read_on_loop(
        self, fields: Iterable[RegisterField], *, max_gap: int = 0
    ) -> dict[str, Value]:
        """From the loop, holding the lock: read and decode fields, each block once.

        No retry and no reconnect (the loop never blocks): a failure raises, counted and
        with the link dropped as for any request, and the robot's thread takes over.

        Args:
            fields: The fields.
            max_gap: A read may span this many unused addresses.

        Returns:
            Each field's engineering value, by name.

        Raises:
            TransportError: A read failed (a subclass says how).
        """
        plan = self.read_plan(fields, max_gap=max_gap)
        self._refuse_if_closed()
        requests = self._chained_requests(plan.blocks)
        if requests and not self._link.connected:
            raise ConnectionLostError(f"{self.name}: not connected for {requests[0][0]}")
        # The blocks chained on callbacks, as a thread's read is: one future per read.
        answer: asyncio.Future[tuple[list[list[int]], BaseException | None]]
        answer = asyncio.get_running_loop().create_future()
        _ChainedRead(self, requests, functools.partial(settle, answer)).next()
        try:
            answers, failure = await answer
        except BaseException as exc:  # cancelled: an answer may still come (link dropped)
            self._request_failed(exc)
            raise
        if failure is not None:
            self._request_failed(failure)
            raise failure
        return plan.decode(answers)

    async def write_on_loop(self, address: int, words: list[int]) -> None:
        """From the loop, holding the lock: write holding registers in one FC16 request, once.

        For the master's heartbeat (:mod:`._heartbeat`): no retry and no reconnect (the
        loop never blocks), and not counted as one of the link's requests. A failure
        raises, with the link dropped as for any request.

        Args:
            address: The first holding register.
            words: The words (0..65535).

        Raises:
            TransportError: The write failed (a subclass says how).
        """
        what = f"write holding {address}+{len(words)} (heartbeat)"
        self._refuse_if_closed()
        if not self._link.connected:
            raise ConnectionLostError(f"{self.name}: not connected for {what}")
        self._link.device_id = self.device_id
        try:
            await self._link.exchange(what, 16, address, len(words), words)
        except BaseException as exc:
            self._request_failed(exc)
            raise


@dataclass(eq=False)
class _ChainedRead:
    """On the loop: a read's blocks one after the other, each sent once, then one answer.

    ``done((answers, None))`` with every block's words, or ``done((answers, error))``
    with those read before the first failure.
    """

    transport: LoopTransport
    requests: list[tuple[str, int, Block]]
    done: Callable[[tuple[list[list[int]], BaseException | None]], None]
    answers: list[list[int]] = field(default_factory=list, init=False)

    def next(self) -> None:
        """Send the next block's request, or answer when every block is read."""
        index = len(self.answers)
        if index == len(self.requests):
            self.done((self.answers, None))
            return
        what, function_code, block = self.requests[index]
        link = self.transport._link
        if not link.connected:
            self.done((self.answers, ConnectionLostError(f"{link.name}: not connected for {what}")))
            return
        self.transport._count_request(function_code)
        link.start(what, function_code, block.address, block.count, None, self._read, self._fail)

    def _read(self, words: list[int]) -> None:
        what, _function_code, block = self.requests[len(self.answers)]
        if len(words) != block.count:
            self._fail(ResponseTimeoutError(f"{self.transport.name}: short answer to {what}"))
            return
        self.answers.append(words)
        self.next()

    def _fail(self, error: BaseException) -> None:
        self.done((self.answers, error))


class FleetMember:
    """One robot of a fleet: the loop's side of its waits (touched by the loop thread)."""

    def __init__(
        self, fleet: Fleet, channel: CommandChannel, transport: LoopTransport, gate: CommandGate
    ) -> None:
        self.fleet = fleet
        self.channel = channel
        self.transport = transport
        #: The robot's command gate: closed by the fleet before any robot is closed.
        self.gate = gate
        self.polling = False
        self._nap: asyncio.Future[None] | None = None
        # On the loop, the polls of a wait and the watch's reads take turns on the link
        # (both hold its lock from the same thread, the loop's, which would not tell them
        # apart).
        self._turn = asyncio.Lock()
        #: What the fleet's watch last saw of this robot (``Fleet(watch_hz=...)``).
        self.record = StatusRecord(transport.name, _log.bind(robot=transport.name), events="fleet")
        #: A status read this recently (s) is fresh: the watch does not read it again
        #: (0: the fleet does not watch).
        self.fresh_s = 0.0 if fleet.watch_hz is None else 0.5 / fleet.watch_hz

    def follow(self, follow: FollowState) -> Observation | None:
        """From the robot's thread: poll on the loop until the thread must act (None: poll)."""
        if follow.stop_event.is_set():
            return None
        # The loop hands back by the deadlines; beyond them, the last poll's requests.
        bound = max(follow.ack_deadline - time.monotonic(), 0.0) + follow.longest_budget()
        bound += 4 * self.transport.timeout + _LOOP_GRACE_S
        job = _Job(self._follow(follow))
        if not self.fleet._call_soon(job.begin, self.fleet):
            job.close()
            return None  # the loop has ended: the thread polls (and its requests fail)
        try:
            return job.latch.wait(bound)
        except _CANCELLED:
            return None  # the loop ended meanwhile: as above
        except _NoAnswerError as exc:
            raise TransportError(
                f"{self.transport.name}: the fleet's event loop did not answer within {bound:.1f} s"
            ) from exc
        finally:
            if job.running.locked() and self.fleet._call_soon(job.cancel):
                # Given up (Ctrl-C, the bound): the loop's poll must be over before the
                # thread acts on the command (withdraw, stop), so nothing interleaves.
                job.running.acquire(timeout=self.transport.timeout + _LOOP_GRACE_S)

    def wake(self) -> None:
        """On the loop: end the current nap early (a stop request)."""
        if self._nap is not None:
            settle(self._nap, None)

    async def _sleep(self, delay: float) -> None:
        loop = asyncio.get_running_loop()
        self._nap = nap = loop.create_future()
        timer = loop.call_later(delay, settle, nap, None)
        try:
            await nap
        finally:
            timer.cancel()
            self._nap = None

    async def _follow(self, follow: FollowState) -> Observation | None:
        """Poll on the follow's schedule until a poll settles it, or hand the poll back."""
        if self.polling:
            return None  # another wait on this robot is being polled: this one polls itself
        self.polling = True
        try:
            motion = follow.motion
            stop = follow.stop_event
            while True:
                delay = follow.due() - time.monotonic()
                if delay > 0:
                    if stop.is_set():
                        # Checked with no await before the nap begins: a stop request
                        # set after this finds the nap to wake (interrupt() wakes it).
                        return None
                    await self._sleep(delay)
                async with self._turn:
                    if stop.is_set() or not self.transport.hold():
                        return None  # a stop request, or another thread's request on the link
                    try:
                        follow.poll_started = time.monotonic()
                        observation = await self._poll(follow)
                    except TransportError:
                        return None  # the thread polls again, with the transport's retries
                    finally:
                        self.transport.release()
                if observation.pose is not None:
                    motion.last_pose = observation.pose
                if follow.settled(observation, time.monotonic()):
                    return observation
        finally:
            self.polling = False

    def watching(self) -> bool:
        """True until the robot is closed or the fleet stops."""
        return self.transport.state is not ConnectionState.CLOSED and self.fleet._running

    async def watch_once(self) -> None:
        """Read the robot's status once for the fleet's watch (nothing before the first
        connect; a lost link recorded as a ``ConnectionLostError``, as a monitor records it).

        Nothing either when a poll of the robot's wait read the whole status within the
        last half period (the article's polls do): that status is published already.
        """
        if not self.linked():
            if self.transport.state is ConnectionState.DISCONNECTED:
                self.record.fail(ConnectionLostError(f"{self.transport.name}: the link is down"))
            return
        read_at = self.record.published.read_at
        if read_at is not None and time.monotonic() - read_at < self.fresh_s:
            return
        async with self._turn:
            if not self.transport.hold():
                self.record.skip(1)  # the robot's thread is using the link: next slot
                return
            try:
                values = await self.transport.read_on_loop(
                    self.channel.status_fields, max_gap=self.channel.profile.max_read_gap
                )
            except TransportError as exc:
                self.record.fail(exc)
                return
            finally:
                self.transport.release()
        self.record.succeed(self.channel.status_from(values))

    def linked(self) -> bool:
        """True while the robot's link is up (the robot's thread opens it, never the watch).

        A link the device closed reads as disconnected (:attr:`LoopTransport.state`).
        """
        return self.transport.state is ConnectionState.CONNECTED

    async def write_when_free(
        self, address: int, words: list[int], *, wait_s: float, poll_s: float
    ) -> BaseException | bool | None:
        """On the loop: one heartbeat write on the robot's link, once the link is free.

        Never blocks the loop on the robot's thread: the link's lock is taken only when
        free (as a poll takes it), looked at again every ``poll_s`` for up to ``wait_s``;
        polls and watch reads on the loop take turns with it.

        Args:
            address: The first holding register.
            words: The words.
            wait_s: How long to wait for the link to be free, s.
            poll_s: How often to look, s.

        Returns:
            None when written; True when the link stayed busy or is down (nothing
            sent); the error when the write failed.
        """
        deadline = asyncio.get_running_loop().time() + wait_s
        with self.transport.let_in():
            while self.linked():
                async with self._turn:
                    if self.transport.hold():
                        try:
                            await self.transport.write_on_loop(address, words)
                        except TransportError as exc:
                            return exc
                        finally:
                            self.transport.release()
                        return None
                if asyncio.get_running_loop().time() >= deadline:
                    return True
                await asyncio.sleep(poll_s)
        return True

    async def _poll(self, follow: FollowState) -> Observation:
        """The channel's one poll, its reads made on the loop."""
        steps = self.channel.poll_steps(follow.motion.ticket)
        fields = next(steps)
        max_gap = self.channel.profile.max_read_gap
        while True:
            values = await self.transport.read_on_loop(fields, max_gap=max_gap)
            if fields is self.channel.status_fields and self.fresh_s > 0:
                # The whole status, read anyway: the watch publishes it, and skips its read.
                self.record.succeed(self.channel.status_from(values))
            try:
                fields = steps.send(values)
            except StopIteration as finished:
                observation: Observation = finished.value
                return observation


#: How often the main thread looks up from a wait the loop polls: a Ctrl-C that did not
#: interrupt the wait itself (signalled to another thread, ``_thread.interrupt_main()``)
#: is raised within this. Other threads wait in one piece: they get no KeyboardInterrupt.
_MAIN_THREAD_SLICE_S = 0.05


class _Job(Generic[T]):
    """A coroutine run on the loop for a thread that waits for it (a wait's polls, a connect).

    Started by a callback on the loop, its end settling a :class:`_Latch`: no concurrent
    future chained to the task, the thread woken once. ``running`` is released once the
    coroutine can run no more: it never began, or its task is done (also when cancelled
    before its first step, where the coroutine runs none of its code, not even a
    ``finally``).
    """

    __slots__ = ("_coroutine", "latch", "running", "task")

    def __init__(self, coroutine: Coroutine[Any, Any, T]) -> None:
        self._coroutine = coroutine
        #: Held until the coroutine can run no more (the thread waits for it after giving
        #: up): a lock released once, where an Event costs about four times the CPU run cold.
        self.running = threading.Lock()
        self.running.acquire()
        self.latch: _Latch[T] = _Latch()
        self.task: asyncio.Task[T] | None = None

    def close(self) -> None:
        """The coroutine will not run (nothing awaited it), or has ended: called once (a
        job never begun, its begin finding the loop ending, or its task done)."""
        self._coroutine.close()
        self.running.release()

    def begin(self, fleet: Fleet) -> None:
        """On the loop: run the coroutine (CancelledError when the loop is ending)."""
        # A thread queues a job's cancel only after its begin: the loop runs them in order.
        if not fleet._running:
            self.close()
            self.latch.fail(concurrent.futures.CancelledError())
            return
        self.task = asyncio.get_running_loop().create_task(self._coroutine)
        self.task.add_done_callback(self._finished)

    def _finished(self, task: asyncio.Task[T]) -> None:
        """On the loop, the task done: ended first, then the thread's answer (its result,
        or its exception: cancelled, ``CancelledError``)."""
        self.close()  # closing a finished coroutine does nothing
        try:
            value = task.result()
        except BaseException as exc:
            self.latch.fail(exc)
        else:
            self.latch.settle(value)

    def cancel(self) -> None:
        """On the loop: the thread gave up waiting; cancel the coroutine."""
        if self.task is not None:  # None: the loop was ending, the coroutine never ran
            self.task.cancel()


#: What a job's latch raises when its coroutine was cancelled, or never ran.
_CANCELLED = (concurrent.futures.CancelledError, asyncio.CancelledError)


class _Latch(Generic[T]):
    """One answer handed from the loop to a waiting thread: a value or an exception."""

    __slots__ = ("_error", "_lock", "_value")

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._lock.acquire()  # released once, when settled
        self._value: T | None = None
        self._error: BaseException | None = None

    def settle(self, value: T) -> None:
        """From the loop: the answer."""
        self._value = value
        self._lock.release()

    def fail(self, error: BaseException) -> None:
        """From the loop: the failure."""
        self._error = error
        self._lock.release()

    def wait(self, bound: float) -> T:
        """The answer, or its failure raised; :class:`_NoAnswerError` after ``bound`` seconds.

        In the main thread in slices, so Ctrl-C is never held up.
        """
        main = threading.current_thread() is threading.main_thread()
        deadline = time.monotonic() + bound
        while True:
            left = deadline - time.monotonic()
            wait = max(min(left, _MAIN_THREAD_SLICE_S) if main else left, 0.0)
            if self._lock.acquire(timeout=wait):
                break
            if left <= wait:
                raise _NoAnswerError
        if self._error is not None:
            raise self._error
        return cast(T, self._value)


class _NoAnswerError(Exception):
    """The loop did not finish a coroutine within its bound (not the coroutine's own error)."""


class Fleet:
    """Drive many robots from one process: their links and the polls of their waits on one loop.

    Make each robot with ``Robot(host, port, link=fleet)`` and drive it from its own
    thread as usual (``move_to``, ``wait``, ``stop``): the safety rules are the
    Robot's, unchanged. What changes is who polls: while a robot's thread waits for a
    move, the fleet's single event loop polls it on the same schedule and wakes the
    thread only when the poll needs it, so hundreds of robots do not mean hundreds of
    threads waking for every poll (docs/performance.md).

    :meth:`close` closes every robot still open (withdrawing or stopping what each has
    outstanding), then the loop; safe to call more than once.

    A robot made without a Fleet runs the same way on the process's default driver, a
    Fleet of the library's own (started by the first connect, stopped when the last
    link closes); make a Fleet of your own to watch its robots (``watch_hz``), to close
    them all at once, or to keep groups of robots on separate loops.

    Example:
        Two robots against two simulators (``python -m tmmaster.sim --port 5020`` and
        ``--port 5021``), one thread each:

        ```python
        import threading

        from tmmaster import Fleet, Pose, Robot

        def cycle(robot: Robot) -> None:
            with robot:
                robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=50)

        with Fleet(watch_hz=10) as fleet:
            robots = [Robot("127.0.0.1", port, link=fleet, name=f"r{port}")
                      for port in (5020, 5021)]
            threads = [threading.Thread(target=cycle, args=(r,)) for r in robots]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join()
        ```

    Args:
        watch_hz: Also read every connected robot's status this often on the loop, over
            the robot's own link, between its other requests (:meth:`latest`); None: no
            watch. The robots' phases are spread over the period; a slot that finds the
            link busy or a read outstanding is skipped and counted, as in
            :class:`StatusMonitor`.
        event_loop: ``"auto"`` (uvloop when installed, else asyncio's own loop),
            ``"asyncio"`` or ``"uvloop"``.

    Raises:
        ConfigError: ``watch_hz`` not a number > 0 or above 100 Hz, or an unknown or
            missing event loop.
    """

    def __init__(
        self, *, watch_hz: float | None = None, event_loop: EventLoopName = "auto"
    ) -> None:
        if watch_hz is not None:
            require_positive("watch_hz", watch_hz)
            if watch_hz > MAX_WATCH_HZ:
                raise ConfigError(
                    f"watch_hz must be at most {MAX_WATCH_HZ:g} Hz (one status read per robot"
                    f" every {1000 / MAX_WATCH_HZ:g} ms at most), got {watch_hz!r}"
                )
        #: How often each robot's status is read for :meth:`latest` (None: not watched).
        self.watch_hz = watch_hz
        self._runner = LoopThread(event_loop, name="tmmaster-fleet", owner="Fleet")
        #: The event loop the fleet runs on: "uvloop" or "asyncio".
        self.event_loop = self._runner.event_loop
        self._members: weakref.WeakKeyDictionary[_Closable, FleetMember] = (
            weakref.WeakKeyDictionary()
        )
        self._watches: set[asyncio.Task[None]] = set()
        #: Set to a list before the robots connect to record (lateness s, response s) of
        #: every answered watch read (benchmarks); None records nothing.
        self._timings: list[tuple[float, float]] | None = None
        self._lock = threading.Lock()
        self._closed = False

    def latest(self, robot: _Closable) -> MonitoredStatus:
        """What the fleet's watch last saw of ``robot``.

        Args:
            robot: One of this fleet's robots.

        Returns:
            Its last status read (or the error of the last read), and when.

        Raises:
            ConfigError: The fleet does not watch (no ``watch_hz``), or the robot is not
                one of its own.
        """
        if self.watch_hz is None:
            raise ConfigError("this Fleet does not watch its robots: make it with watch_hz")
        try:
            with self._lock:
                member = self._members.get(robot)
        except TypeError:  # not a robot at all (cannot be weakly referenced)
            member = None
        if member is None:
            raise ConfigError("that robot is not one of this Fleet's")
        return member.record.published

    def _start_watch(self, member: FleetMember, index: int) -> None:
        """On the loop: start one robot's watch, its phase spread over the period."""
        assert self.watch_hz is not None
        period = 1.0 / self.watch_hz
        # Golden-ratio phases: evenly spread however many robots join, and when.
        due = time.monotonic() + period * ((index * 0.6180339887) % 1.0)
        # The watch holds no member (nor its link, nor the fleet): a robot dropped
        # unclosed is garbage, its link let go, and the watch ends.
        ref = weakref.ref(member)

        async def watch_once() -> None:
            if (alive := ref()) is not None:
                await alive.watch_once()

        task = asyncio.get_running_loop().create_task(
            poll_on_schedule(
                member.record,
                watch_once,
                due=due,
                period=period,
                running=lambda: (alive := ref()) is not None and alive.watching(),
                timings=self._timings,
            ),
            name=f"tmmaster-fleet-watch-{member.transport.name}",
        )
        self._watches.add(task)
        task.add_done_callback(self._watches.discard)

    # -- lifecycle ----------------------------------------------------------------------

    def start(self) -> Self:
        """Start the loop thread (done by the first robot; a no-op when running).

        Returns:
            The fleet.

        Raises:
            ConfigError: The fleet is closed.
        """
        with self._lock:
            if self._closed:
                raise ConfigError("this Fleet is closed; make a new one")
            # Started once (start() runs at every join and reconnect), with one finalizer.
            # The loop holds no fleet: one dropped unclosed (its robots too) is garbage,
            # and its finalizer ends the loop.
            if (runner := self._runner).thread is None:
                watches, lock, members = self._watches, self._lock, self._members
                runner.start(lambda: _serve(runner, watches, lock, members))
                weakref.finalize(self, runner.end_soon)
        return self

    def close(self, *, timeout_s: float = 2.0) -> tuple[str, ...]:
        """Close every robot at once, then stop the loop and join its thread.

        First every robot's gate closes, so no robot writes a new command from then on
        (a write already in flight finishes and is given up like any other), and every
        wait the loop polls ends. Then all robots are closed in parallel, each
        withdrawing or stopping what it has outstanding, within ``timeout_s`` in all
        (beyond it by each robot's requests already on its link, its look at the move,
        the first attempts of its give-up and a command write still on its way, as
        :meth:`Robot.close` says): a robot whose link is dead does
        not hold the others up. Safe to call more than once, and from several threads at
        once: each call returns only once every robot's clean-up is over (a call while
        another is at work waits for it, as :meth:`Robot.close` does) and says what
        could not be confirmed, never an empty tuple while an arm is still being stopped.

        Args:
            timeout_s: the budget for the robots' clean-up, in seconds.

        Returns:
            The names of the robots whose withdraw or stop could not be confirmed
            (a dead link, the budget spent); each is also logged as an error. Empty
            when every command the fleet's robots sent can no longer run.

        Raises:
            ConfigError: ``timeout_s`` is not a finite number > 0.
        """
        require_positive("timeout_s", timeout_s)
        with self._lock:  # a later call closes them again: it waits for a close at work
            self._closed = True
            members = list(self._members.items())
        deadline = time.monotonic() + timeout_s
        for _robot, member in members:
            member.gate.close()  # no new command anywhere, before any robot is closed
            wake_waits(member)
        outcomes: dict[str, bool] = {}

        def close_one(robot: _Closable) -> None:
            outcomes[robot.name] = robot.close(timeout_s=max(deadline - time.monotonic(), 1e-3))

        threads = [
            threading.Thread(
                target=close_one, args=(robot,), name=f"tmmaster-close-{robot.name}", daemon=True
            )
            for robot, _member in members
        ]
        for thread in threads:
            thread.start()
        for thread in threads:  # past the deadline too: see Robot.close
            thread.join()
        unconfirmed = tuple(r.name for r, _m in members if not outcomes.get(r.name, False))
        for name in unconfirmed:
            _log.error("fleet.close_unconfirmed", robot=name)
        self._runner.stop()
        return unconfirmed

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _retire(self) -> None:
        """The default driver, given back by its last link: stop the loop (its robots are
        closed, or garbage); from the loop thread itself, without waiting for it."""
        with self._lock:
            self._closed = True
        self._runner.stop()

    # -- calling the loop ------------------------------------------------------------------

    @property
    def _running(self) -> bool:
        """True while the loop runs and takes work."""
        loop, wake = self._runner.loop, self._runner.wake
        return loop is not None and not loop.is_closed() and wake is not None and not wake.is_set()

    def _on_loop(self) -> bool:
        """True in the loop's own thread."""
        return threading.current_thread() is self._runner.thread

    def _call(self, coroutine: Coroutine[Any, Any, T], bound: float, name: str) -> T:
        """Run ``coroutine`` on the loop and wait for its result, at most ``bound`` seconds."""
        job = _Job(coroutine)
        if self._on_loop():
            job.close()
            raise RuntimeError("a Fleet's loop must never wait for itself")
        if not self._call_soon(job.begin, self):
            job.close()
            raise TransportClosedError(f"{name}: the fleet is closed")
        try:
            return job.latch.wait(bound)
        except _NoAnswerError as exc:
            self._call_soon(job.cancel)
            raise ResponseTimeoutError(
                f"{name}: the fleet's event loop did not answer within {bound:.1f} s"
            ) from exc
        except _CANCELLED as exc:
            raise ConnectionLostError(f"{name}: the fleet closed during the request") from exc
        except BaseException:
            # Interrupted (Ctrl-C): the request is dropped with its link.
            self._call_soon(job.cancel)
            raise

    def _call_soon(self, callback: Callable[..., object], *args: Any) -> bool:
        """Run ``callback(*args)`` on the loop soon; False when the loop has ended."""
        loop = self._runner.loop
        if loop is None or not self._running:
            return False
        try:
            loop.call_soon_threadsafe(callback, *args)
        except RuntimeError:  # the loop ended meanwhile
            return False
        return True


async def _serve(
    runner: LoopThread,
    watches: set[asyncio.Task[None]],
    lock: threading.Lock,
    members: weakref.WeakKeyDictionary[_Closable, FleetMember],
) -> None:
    """A fleet's loop, until the runner is stopped (it holds no fleet: a fleet dropped
    unclosed is garbage once its robots are, and its finalizer ends this)."""
    wake = runner.bind()
    runner.ready()
    try:
        await wake.wait()
    finally:
        wake.set()  # submit() refuses from now on
        for task in list(watches):
            task.cancel()
        with lock:
            left = list(members.values())
        for member in left:
            member.transport.drop_on_loop()
        # Closing transports release their sockets on a later loop turn; the requests
        # still awaited (none, normally) end with ConnectionLostError.
        for _ in range(3):
            await asyncio.sleep(0)


def join_fleet(
    fleet: Fleet,
    host: str,
    port: int,
    *,
    device_id: int,
    timeout: float,
    retry: RetryPolicy | None,
    name: str,
) -> LoopTransport:
    """For :class:`~tmmaster.Robot`: a new robot's link on ``fleet``'s loop (started here)."""
    host, port = check_host(host), check_port(port)
    if is_in_process(host):
        raise ConfigError(
            f"host {host!r}: a Fleet's robots speak Modbus TCP (no in-process endpoints)"
        )
    fleet.start()
    return LoopTransport(
        fleet, host, port, device_id=device_id, timeout=timeout, retry=retry, name=name
    )


def fleet_driver(
    fleet: Fleet,
    robot: _Closable,
    channel: CommandChannel,
    transport: LoopTransport,
    gate: CommandGate,
) -> FleetMember:
    """For :class:`~tmmaster.Robot`: the loop's side of its waits and watch, registered.

    The fleet closes ``gate`` and then ``robot`` when it closes (:meth:`Fleet.close`).

    Raises:
        ConfigError: The fleet began to close since ``join_fleet()`` (the robot is never
            connected: that close would not give up what it wrote).
    """
    member = FleetMember(fleet, channel, transport, gate)
    with fleet._lock:
        if fleet._closed:  # since join_fleet(): its close has listed its robots without this one
            raise ConfigError("this Fleet is closed; make a new one")
        fleet._members[robot] = member
        index = len(fleet._members) - 1
    if fleet.watch_hz is not None:
        fleet._call_soon(fleet._start_watch, member, index)
    return member


def _let_go(driver: _DefaultDriver, fleet: Fleet, link: AsyncLink) -> None:
    """A link's end: closed on its loop, and a default driver's share given back to the
    ``driver`` it was taken from (a Fleet of the user's is not the default one: nothing to
    give back). A Ctrl-C meanwhile comes after it: cut short, the finalizer has run all
    the same, and the share is never back."""
    with deferred():
        fleet._call_soon(link.close)
        driver.release(fleet)


def wake_waits(member: FleetMember) -> None:
    """For :meth:`Robot.interrupt`: a wait the loop polls for ``member`` ends now."""
    member.fleet._call_soon(member.wake)


class _DefaultDriver:
    """The process's default driver: one Fleet, made by its first user, retired with its last.

    Every network link not on a Fleet of the user's (a Robot's, a stand-alone gripper's, a
    :class:`ModbusTransport`, an AsyncRobot's) takes it and gives it back once closed,
    so a process with no open link has no loop thread, and the next link starts a new one.
    """

    def __init__(self) -> None:
        # Reentrant: a collection inside acquire() (Fleet() allocates) may run a garbage
        # link's finalizer, which gives its share back through this lock on this thread.
        self._lock = threading.RLock()
        #: The default driver while it has users (None: no link holds it).
        self.fleet: Fleet | None = None
        self._users = 0

    def acquire(self) -> Fleet:
        """Take the default driver (made now if none); give it back with :meth:`release`."""
        with self._lock:
            if self.fleet is None:
                self.fleet = Fleet()
            self._users += 1
            return self.fleet

    def release(self, fleet: Fleet) -> None:
        """Give ``fleet`` back; the last user's release stops its loop."""
        with self._lock:
            if fleet is not self.fleet:
                return  # a driver forgotten at a fork
            self._users -= 1
            if self._users > 0:
                return
            self.fleet = None
        fleet._retire()

    def forget(self) -> None:
        """In a forked child: the parent's loop thread is not there; the next link makes one."""
        self._lock = threading.RLock()
        self.fleet = None
        self._users = 0


_DEFAULT = _DefaultDriver()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_DEFAULT.forget)


class ModbusTransport(LoopTransport):
    """Reads and writes one Modbus TCP device, with counting, error mapping and retries.

    The link is an :class:`~tmmaster._transport.AsyncLink` on the process's default
    driver, the event loop every Robot without a Fleet as ``link=`` uses (started by the
    first connect, stopped when the last link closes): each request is sent once, and
    its answer (decoded here, or by pymodbus' framer where uncommon) is taken only
    under the request's own transaction id and from the transport's unit id. A failure
    closes the link, so a late answer can never be read as a later request's. Nothing
    is ever resent here: the :class:`RetryPolicy` decides. ``Robot(host, port)`` makes
    one; make your own to read or write a device directly, and close it when done.

    Example:
        Against the simulator (``python -m tmmaster.sim --port 5020``):

        ```python
        from tmmaster import ModbusTransport, robot_profile

        profile = robot_profile("tmflow")
        with ModbusTransport("127.0.0.1", 5020, device_id=profile.device_id) as link:
            print(link.read_fields(profile.select(["tcp_x", "tcp_y", "tcp_z"])))
        ```

    Args:
        host: The device's address (an IP address or a host name).
        port: Its Modbus TCP port.
        device_id: The Modbus unit id of every request.
        timeout: Bound of one request (and of a connect), s.
        retry: How failed requests and connects are retried; None: the default policy.
        name: The link's name in messages and logs.

    Raises:
        ConfigError: An invalid host or port, or an in-process ``scheme://name`` address
            (``sim://``).
    """

    def __init__(
        self,
        host: str,
        port: int = 502,
        *,
        device_id: int = 1,
        timeout: float = 1.0,
        retry: RetryPolicy | None = None,
        name: str = "device",
    ) -> None:
        host, port = check_host(host), check_port(port)
        if scheme_opener(host) is not None:
            raise ConfigError(
                f"host {host!r}: a ModbusTransport speaks Modbus TCP (use open_transport or"
                " Robot for an in-process endpoint)"
            )
        super().__init__(
            None, host, port, device_id=device_id, timeout=timeout, retry=retry, name=name
        )


def open_transport(
    host: str,
    port: int,
    *,
    role: str = "robot",
    device_id: int = 1,
    timeout: float = 1.0,
    retry: RetryPolicy | None = None,
    name: str = "device",
) -> Transport:
    """A Modbus TCP transport to ``host:port``, or an in-process one for ``scheme://name``.

    The host and port are checked first (:func:`check_host`): a port in the host, a URL,
    or anything that is no address is a :class:`ConfigError`, before any I/O. A host of
    a scheme a plugin registered (:func:`~tmmaster._address.register_scheme`, as
    ``tmmaster.sim`` does for ``sim://``) opens through that plugin's opener; any other
    is a :class:`ModbusTransport` on the default driver.
    """
    host = check_host(host)
    opener = scheme_opener(host)
    if opener is None:
        return ModbusTransport(
            host, port, device_id=device_id, timeout=timeout, retry=retry, name=name
        )
    transport: Transport = opener(
        host, role=role, device_id=device_id, timeout=timeout, retry=retry, name=name
    )
    return transport
