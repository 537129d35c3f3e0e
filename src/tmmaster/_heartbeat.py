"""The master's heartbeat: a command on the robot lives only as long as its master.

The ``tmflow`` robot program expires a command whose master went silent: once
``master_heartbeat`` (9050) has not changed for ``master_ttl_ms`` (9051) it takes no
command and lets no command go on, paused or not (docs/tmflow-program.md, "Command
expiry"; docs/safety.md). It also runs only the commands of the master that beats: each
master has a session, a random number in 1..32767 that it writes with every beat
(``master_session``, 9052) and with every command (``command_session``); a command of
another session is never run, and one running or paused is stopped.

A :class:`~tmmaster.Robot` claims the robot just before its first command (one read of
the session there, one beat with its own, different session) and from then on writes the
three registers in one FC16 request every ``TimeoutPolicy.heartbeat_s`` until it closes,
the heartbeat changed each time (1..32767, then 1 again), the time-to-live
``TimeoutPolicy.heartbeat_ttl_s``. A robot that only reads never beats, so it disturbs
no other master.

A heartbeat write is no command: it never passes the command gate nor the command
path's retry, and a write that fails is simply followed by the next one. It is not
counted in the link's request counters either (:attr:`Heartbeat.writes` counts it), so
what a move costs reads the same with or without it.

Where it runs:

* a network robot: a task on its driver's event loop (the loop every link of the
  process runs on). It takes the link's lock as the fleet's polls do, without ever
  blocking: a link busy with the robot's thread skips the slot, tried again shortly.
* an in-process robot (``sim://``, a MemoryTransport: each request waits for the
  simulator's thread, which the driver's loop must never do) or any other ready
  Transport: a small daemon thread of its own, ended by ``close()``.

Either stops at ``close()``, when the link is closed, when the driver stops, or when
the Robot is garbage.
"""

from __future__ import annotations

import asyncio
import secrets
import threading
import time
import weakref
from typing import TYPE_CHECKING, Any

from ._registers import RobotProfile, Table
from ._transport import ConnectionState, Transport

if TYPE_CHECKING:
    from ._fleet import FleetMember

#: The registers of the heartbeat, in this order (adjacent holding registers).
HEARTBEAT_FIELDS = ("master_heartbeat", "master_ttl_ms", "master_session")

#: The heartbeat counts 1..32767, then 1 again (0: never written).
HEARTBEAT_MAX = 32767

#: After a write failed: try again this soon, s.
_RETRY_S = 0.05
#: While the link is busy with the robot's own requests: look again this often, s (a
#: poll that skipped a busy link missed beats while a robot polled densely).
_BUSY_POLL_S = 0.005


class Heartbeat:
    """One robot's heartbeat writer (nothing to write where the profile has no such fields).

    Args:
        profile: The robot's register map.
        transport: The robot's link.
        period_s: Seconds between two writes.
        ttl_s: The time-to-live written with each beat, s.
        log: The robot's logger.
    """

    def __init__(
        self,
        profile: RobotProfile,
        transport: Transport,
        *,
        period_s: float,
        ttl_s: float,
        log: Any,
    ) -> None:
        self._fields = profile.published(HEARTBEAT_FIELDS)
        if self._fields:
            first = self._fields[0]
            if first.table is not Table.HOLDING or any(
                f.address != first.address + i for i, f in enumerate(self._fields)
            ):
                self._fields = ()  # not one FC16 request: the program could not read it so
        self._transport = transport
        self.period_s = period_s
        self.ttl_ms = round(ttl_s * 1000)
        self._log = log
        #: The last heartbeat value sent (0: none yet).
        self.beat = 0
        #: This master's session, written with every beat and every command (0: none).
        self.session = _new_session() if self._fields else 0
        #: The session of the last beat answered: the one the robot holds of this master.
        self.held = 0
        #: Writes answered by the robot.
        self.writes = 0
        #: When a write was last answered (time.monotonic()).
        self.wrote_at = 0.0
        #: Slots that found the link busy, closed or failing (the next slot writes).
        self.missed = 0
        self._stop = threading.Event()
        weakref.finalize(self, self._stop.set)  # once: a thread of it ends with the Robot
        self._thread: threading.Thread | None = None
        self._task: asyncio.Task[None] | None = None
        self._member: FleetMember | None = None
        self._failing = False

    @property
    def enabled(self) -> bool:
        """True when the profile has the heartbeat registers (``tmflow``)."""
        return bool(self._fields)

    @property
    def running(self) -> bool:
        """True between :meth:`start` and :meth:`stop`."""
        return (self._thread is not None or self._task is not None) and not self._stop.is_set()

    @property
    def address(self) -> int:
        """The first register (``master_heartbeat``)."""
        return self._fields[0].address

    def next_words(self) -> list[int]:
        """The next beat, the time-to-live and the session: the words of one write."""
        self.beat = self.beat % HEARTBEAT_MAX + 1
        return [self.beat, self.ttl_ms, self.session]

    @property
    def claim_due(self) -> bool:
        """True while a command must first :meth:`claim` the robot: not beating yet, or
        no beat answered for half the time-to-live (the link was down: the robot may
        see this master gone, and would consume the command as cancelled), or the last
        beat answered carried another session (a renewed session's beat missed, or an
        older beat landed after it: the program would refuse the command as
        ``another_master``)."""
        stale = time.monotonic() - self.wrote_at > self.ttl_ms / 2000
        return self.enabled and (not self.running or stale or self.held != self.session)

    def claim(self, member: FleetMember | None) -> int:
        """Before this master's first command: beat once with a session the robot does not
        hold yet (a new one when beating again after :meth:`stop`: the robot program may
        have seen the old one replaced, and takes no beat of it back), then go on beating
        (:meth:`start`). Once beating, nothing, unless :attr:`claim_due` (a silence, or
        the robot holding another session): then one beat first, with this session.

        Args:
            member: The robot's side of its driver (a network robot), or None.

        Returns:
            This master's session, for its commands (0: the profile has no heartbeat).

        Raises:
            TMMasterError: The session could not be read or the beat not written: the
                robot would refuse the command, so it is not sent.
        """
        if not self.claim_due:
            return self.session
        if not self.running:
            theirs = int(self._transport.read_fields(self._fields[2:])["master_session"])
            if self.writes:  # beating again after a stop
                self.session = _new_session()
            while self.session == theirs:  # never a predecessor's
                self.session = _new_session()
        # Not a command: a beat sent twice is harmless, so the link's retries apply.
        words = self.next_words()
        self._transport.write_block(Table.HOLDING, self.address, words, retry=True)
        self.wrote(None, words)
        self.start(member)
        return self.session

    def renew(self) -> int:
        """Beat at once with a new session, once a command with a copy of its frame still
        in the network (its write resent) ended: that copy carries the old session, so the
        robot program consumes it as another master's (``another_master``), even after a
        controller restart put its sequence numbers back at 0 and freed the frame's number.

        The beat is written once, as any beat: one that fails is logged and counted missed
        (``robot.heartbeat_failed``), the next beat carries the new session, and the next
        command beats with it first (:attr:`claim_due`) rather than be refused. It never
        raises, so the caller's error (the command given up) is what the user sees. A
        heartbeat not running (silenced while a give-up is owed: the next claim takes a
        new session) writes nothing.

        Returns:
            The session for this master's next commands.
        """
        if not self.running:
            return self.session
        self.session = (self.session + secrets.randbelow(HEARTBEAT_MAX - 1)) % HEARTBEAT_MAX + 1
        words = self.next_words()
        self.wrote(_write_once(self._transport, self.address, words, self.period_s), words)
        return self.session

    def start(self, member: FleetMember | None) -> None:
        """Start writing: on ``member``'s driver loop, or (None) in a thread of its own.

        Args:
            member: The robot's side of its driver (a network robot), or None.
        """
        if not self.enabled or self.running:
            return
        self._stop.clear()
        if member is not None:
            self._member = member
            member.fleet._call_soon(self._start_task, member)
            return
        self._thread = threading.Thread(
            target=_beat_in_thread,
            args=(weakref.ref(self), self._stop, self._transport),
            name=f"tmmaster-heartbeat-{getattr(self._transport, 'name', 'robot')}",
            daemon=True,
        )
        self._thread.start()

    def _start_task(self, member: FleetMember) -> None:
        """On the loop: the task, cancelled with the fleet's other tasks when it stops."""
        if self._stop.is_set():
            return
        task = asyncio.get_running_loop().create_task(
            _beat_on_loop(weakref.ref(self), member, self._stop),
            name=f"tmmaster-heartbeat-{member.transport.name}",
        )
        self._task = task
        member.fleet._watches.add(task)
        task.add_done_callback(member.fleet._watches.discard)

    def stop(self, *, timeout_s: float = 1.0) -> None:
        """Stop writing (the robot program expires a command after ``ttl_s``).

        Args:
            timeout_s: How long to wait for a write in flight to end.
        """
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
        task, self._task = self._task, None
        member, self._member = self._member, None
        if task is not None and member is not None:
            member.fleet._call_soon(task.cancel)

    def wrote(self, outcome: BaseException | bool | None, words: list[int]) -> float:
        """Count one slot of the beat ``words`` and say when the next beat is due, s from now.

        ``outcome``: None, written; True, missed (the link busy or down); an error, missed
        (logged once per run of failures). A missed beat is tried again soon, and a beat
        of a session renewed since it was built at once (the robot holds the old one).
        """
        if outcome is None:
            self.writes += 1
            self.wrote_at = time.monotonic()
            self.held = words[2]
            if self._failing:
                self._failing = False
                self._log.info("robot.heartbeat_resumed", beat=self.beat)
            return self.period_s if self.held == self.session else 0.0
        self.missed += 1
        if isinstance(outcome, BaseException) and not self._failing:
            self._failing = True
            self._log.warning("robot.heartbeat_failed", error=str(outcome))
        return min(self.period_s, _RETRY_S)


async def _beat_on_loop(
    ref: weakref.ref[Heartbeat], member: FleetMember, stop: threading.Event
) -> None:
    """On the driver's loop: one write per period while the robot and its link live."""
    while not stop.is_set() and member.watching():
        beat = ref()
        if beat is None:
            return
        delay = beat.period_s
        if member.linked():
            words = beat.next_words()
            outcome = await member.write_when_free(
                beat.address, words, wait_s=beat.period_s, poll_s=_BUSY_POLL_S
            )
            delay = beat.wrote(outcome, words)
        del beat  # the task keeps no Robot alive between two beats
        await asyncio.sleep(delay)


def _new_session() -> int:
    """A master's session: random in 1..32767."""
    return secrets.randbelow(HEARTBEAT_MAX) + 1


def _beat_in_thread(
    ref: weakref.ref[Heartbeat], stop: threading.Event, transport: Transport
) -> None:
    """In a thread of its own: one write per period while the robot and its link live."""
    delay = 0.0
    while not stop.wait(delay):
        beat = ref()
        if beat is None or transport.state is ConnectionState.CLOSED:
            return
        words = beat.next_words()
        delay = beat.wrote(_write_once(transport, beat.address, words, beat.period_s), words)
        del beat


def _write_once(
    transport: Transport, address: int, words: list[int], wait_s: float
) -> BaseException | bool | None:
    """One FC16 write, sent once, under the link's lock, waited for at most ``wait_s``
    (:meth:`Transport.write_when_free`); None when answered, True when the link stayed
    busy for ``wait_s`` or is down, the error when it failed."""
    return transport.write_when_free(address, words, wait_s=wait_s)
