"""The command path: gate, send once, read back, follow, abandon.

A :class:`~tmmaster.Robot` owns one :class:`_MotionFollower`. Every command the robot
sends passes its :class:`~tmmaster._gate.CommandGate` and is written exactly once
(:meth:`_MotionFollower.send`: after a failed write, the registers are read back to
find out whether it landed); the :class:`Motion` handle it returns is polled and
waited for by the follower, which is also the one place where a command the master
gives up on is withdrawn or stopped (docs/safety.md).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import threading
import time
from collections.abc import Callable
from typing import Any, Literal

from ._channels import Command, CommandChannel, Observation, Ticket, heartbeat_stalled
from ._checks import require_positive
from ._exceptions import (
    AcknowledgeTimeoutError,
    CommandRejectedError,
    CommandStateUnknownError,
    ConnectionLostError,
    EmergencyStopError,
    MotionTimeoutError,
    ResponseTimeoutError,
    RobotError,
    RobotFaultError,
    StopRequestedError,
    TMMasterError,
)
from ._following import FollowState, Overdue, SharedDriver
from ._gate import CommandGate
from ._planning import Plan, TimeoutPolicy
from ._poller import TICK_S, Poller, PollPolicy
from ._pose import Pose
from ._retry import is_transient
from ._sigint import deferred
from ._status import MovePhase, MoveProgress


class Motion:
    """A move that was sent; ask for its progress, or wait for it.

    Made by :meth:`Robot.start_move` (and returned by :meth:`Robot.move_to`, done).

    Example:
        Against the simulator (``python -m tmmaster.sim --port 5020``):

        ```python
        from tmmaster import Pose, connect

        with connect("127.0.0.1", 5020) as robot:
            motion = robot.start_move(Pose(300, -200, 200, 180, 0, 90), speed=50)
            print(motion.progress().phase)  # sent or running
            motion.wait()
            print(motion.done, motion.last_pose)
        ```
    """

    def __init__(self, follower: _MotionFollower, ticket: Ticket, plan: Plan) -> None:
        self._follower, self._ticket, self._gauge = follower, ticket, plan.gauge
        #: Where the move started, when known.
        self.start = plan.start
        #: The TCP target (None for a gripper command).
        self.target = ticket.command.target
        #: The expected duration by the arm model, s.
        self.expected_s = plan.expected_s
        #: How long the move may take before its wait gives up, s.
        self.timeout_s = plan.timeout_s
        #: The move's acceleration time by the arm model, s (0: not a move).
        self.accel_s = plan.accel_s
        #: True when ``timeout_s`` was derived from the model's expected time: the wait
        #: then gives a robot the polls see moving slower than the model more time.
        self.timeout_from_model = plan.timeout_from_model
        #: Where the move stands.
        self.phase = MovePhase.SENT
        #: The last TCP pose read during the move (None before the first read).
        self.last_pose: Pose | None = None
        #: ``time.monotonic()`` when the move was seen done or failed (None before).
        self.finished_at: float | None = None
        #: After the master gave up on this command: True when it was withdrawn before the
        #: robot took it, False when the withdraw failed or came too late, None otherwise.
        self.withdrawn: bool | None = None
        #: After the master gave up on a running move: True when the stop was delivered,
        #: False when it could not be, None when no stop was needed.
        self.stop_delivered: bool | None = None
        #: The project speed its expected time assumes, % (the robot's, read at connect).
        self.project_speed_percent = plan.project_speed_percent
        #: ``time.monotonic()`` when the poll that saw it reported finished returned.
        self.reported_finished_at: float | None = None
        # Set by the follower (under its abandon lock): why the master gave this command
        # up (None before); then, once that clean-up is over, True when safe, False when
        # it could not be confirmed.
        self._given_up: BaseException | None = None
        self._settled: bool | None = None

    def path_fraction(self, pose: Pose) -> float | None:
        """How much of the path the robot covered at ``pose``, by the arm model (0..1).

        Args:
            pose: a TCP pose the robot reported during the move.

        Returns:
            The fraction of the path, or None where the model cannot tell (not a move,
            or a PTP whose distance to the target does not shrink all the way).
        """
        return None if self._gauge is None else self._gauge.fraction(pose)

    @property
    def command(self) -> Command:
        """The command this motion carries."""
        return self._ticket.command

    @property
    def ticket(self) -> Ticket:
        """The channel's record of the command sent (sequence number, acknowledgement).

        Low level, for diagnostics: the robot's follower updates it; do not change it.
        """
        return self._ticket

    @property
    def done(self) -> bool:
        """True once the robot acknowledged and then finished the move."""
        return self.phase is MovePhase.DONE

    @property
    def abandoned(self) -> bool:
        """True once the master gave up on this command (failure, timeout, stop, close)."""
        return self._given_up is not None

    def progress(self) -> MoveProgress:
        """Poll the robot once and report where the move stands (raises on robot failure).

        Returns:
            The phase, the last pose, the time elapsed and expected, and the fraction
            of the distance covered.

        Raises:
            RobotFaultError: The robot reported an error (EmergencyStopError for an
                e-stop).
        """
        if self.phase in (MovePhase.SENT, MovePhase.RUNNING):
            with _Following(self._follower, self):
                self._follower.poll(self)
        elapsed = (self.finished_at or time.monotonic()) - self._ticket.sent_at
        fraction: float | None = None
        if self.last_pose is not None and self.target is not None and self.start is not None:
            total = self.start.distance_to(self.target)
            remaining = self.last_pose.distance_to(self.target)
            fraction = 1.0 if total == 0 else max(0.0, min(1.0, 1 - remaining / total))
        return MoveProgress(self.phase, self.last_pose, elapsed, self.expected_s, fraction)

    def cancel(self) -> bool:
        """Give the command up, as a wait that something ends early does: withdrawn if
        the robot has not taken it, the arm stopped if it runs; nothing once it finished.
        For a move started with :meth:`Robot.start_move` that is not to be waited for.
        One poll first (as :meth:`progress`), so a move that finished while nobody
        polled it is found done, neither "withdrawn" nor stopped (on ``tmflow`` a Stop
        would stop the project); a poll that fails gives the command up as a wait does.
        That poll is made once, not retried (as ``close()``'s, which its stop request
        cuts short): where the robot's reads are lost, the arm is not left running for
        the retry policy's whole budget first (``tests/test_lostreads_giveup.py``).

        Returns:
            True when the command can no longer run: never written, finished, withdrawn,
            or stopped. False when that could not be confirmed (the link is down: the
            give-up is then owed and delivered before anything else is sent).
        """
        if self.phase in (MovePhase.SENT, MovePhase.RUNNING):
            # One poll, one attempt: a move that finished is left as it is (a failure
            # gave the command up already, at once).
            with contextlib.suppress(TMMasterError), _Following(self._follower, self):
                self._follower.poll(self, retry=False)
        return self._follower.abandon(self, StopRequestedError("the motion was cancelled"))

    def wait(self, timeout_s: float | None = None) -> None:
        """Block until the move is done; raises a typed error on failure or timeout.

        Whatever ends the wait early (robot failure, timeout, stop request, lost link,
        an exception), the command is withdrawn if the robot has not taken it, and a
        running move is stopped unless the robot stopped it itself.

        Args:
            timeout_s: How long to wait, s; None: the move's own ``timeout_s``.

        Raises:
            AcknowledgeTimeoutError: The robot did not take the command in time.
            MotionTimeoutError: The move did not finish in time.
            RobotFaultError: The robot reported an error (EmergencyStopError for an
                e-stop).
            StopRequestedError: A stop was requested (:meth:`Robot.interrupt`), or the
                command was given up before this wait (:meth:`cancel`, a wait that
                ended early): it can never finish, and nothing is read.
            ConnectionLostError: The link broke and did not come back in time.
        """
        if timeout_s is not None:
            require_positive("timeout_s", timeout_s)
        with _Following(self._follower, self):
            self._follower.wait(self, timeout_s)


#: What a wait on a motion given up raises (StopRequestedError): before it, or meanwhile.
_GIVEN_UP = "the motion was cancelled or given up: it never finishes"


class _Following:
    """Whatever escapes the block, the master gives the command up safely first: an
    escaping exception abandons the motion (:meth:`_MotionFollower.abandon`).

    A motion given up already is not entered (nothing is read). One given up by another
    thread meanwhile (:meth:`Motion.cancel`, ``close()``) raises StopRequestedError from
    what its give-up made the robot report (a stopped project, a cancelled number, a
    move seen ended short), which is not the robot's failure; an e-stop stays itself,
    and so does a fault that the other thread's poll saw first (it gave the motion up).

    A class rather than a generator context manager: entered on every wait and send,
    it costs one object instead of a generator's frame and ``contextlib``'s machinery.
    The exception is never swallowed.
    """

    __slots__ = ("_follower", "_motion")

    def __init__(self, follower: _MotionFollower, motion: Motion) -> None:
        self._follower, self._motion = follower, motion

    def __enter__(self) -> None:
        if self._motion._given_up:  # cancel(), or a wait that ended early
            raise StopRequestedError(_GIVEN_UP)

    def __exit__(self, _type: object, exc: BaseException | None, _tb: object) -> Literal[False]:
        motion, follower = self._motion, self._follower
        # Not on entering: by another thread meanwhile, asked to or for a lost read (as
        # cancel()'s one-attempt poll), not for a robot fault it saw (that stays itself).
        cancelled = not isinstance(motion._given_up, RobotError | None)
        if exc is not None:
            follower.abandon(motion, exc)
        if motion.ticket.resent and (motion.done or motion._given_up):
            # Its copy still in the network is refused from now on; once the give-up
            # another thread has under way is over (its withdraw reads the session).
            with follower._abandon_lock:
                motion.ticket.resent = False
                follower._channel.session = follower.renew()
        if cancelled and isinstance(exc, RobotError) and not isinstance(exc, EmergencyStopError):
            raise StopRequestedError(_GIVEN_UP) from exc
        return False


#: Per robot (``Transport.endpoint``: its address however spelled, port, unit id): a
#: running move's Stop that the link could not carry (article: no cancel record), owed by
#: this process: whichever follower on that robot calls next delivers it first, a Robot
#: made after the one that owed it was closed too.
#: A Stop the slave refused stays with the Robot that sent it (docs/safety.md).
_STOPS_OWED: dict[tuple[str, int, int], Motion] = {}
#: How long after a done the pose registers may trail it, s: 200 ms of lag (a TM5's, as
#: estimated, not measured) and five robot ticks to spare. A correct move waits only as
#: long as they lag; never past the wait's deadline.
SETTLE_S = 0.3


class _MotionFollower:
    """Follows every command a Robot sent: polls it, waits for it, gives it up safely.

    Writes each command once through its gate (:meth:`start`, :meth:`send`), and is
    the one place where a command the master gives up on is withdrawn or stopped
    (docs/safety.md). A :class:`Robot` owns one and hands it to each :class:`Motion`;
    the Robot's polling, timeout and tolerance settings are this object's attributes.
    """

    def __init__(
        self,
        channel: CommandChannel,
        stop_event: threading.Event,
        log: Any,
        *,
        polling: PollPolicy,
        timeouts: TimeoutPolicy,
        position_tolerance_mm: float,
        orientation_tolerance_deg: float,
    ) -> None:
        self._channel, self.stop_event = channel, stop_event
        #: Every command write passes here: never after close() or a stop request began.
        self.gate = CommandGate(stop_event)
        self._log = log
        #: Set for a robot of a Fleet: its waits' polls run on the fleet's event loop.
        self.shared_driver: SharedDriver | None = None
        #: Reads the robot's project speed now (%, None: not published), where the
        #: profile has one: a move at its derived deadline asks once whether it was
        #: lowered since the plan.
        self.project_speed: Callable[[], float | None] | None = None
        #: How waits poll (``interval_s``: the nominal pace of every wait).
        self.polling = polling
        self.timeouts, self.position_tolerance_mm = timeouts, position_tolerance_mm
        self.orientation_tolerance_deg = orientation_tolerance_deg
        #: Set by ``Robot.close()`` when it begins: another caller's wait for a withdraw's
        #: answer ends then (its command is stopped instead), so close() never waits
        #: on it for longer than a request.
        self.closing = threading.Event()
        # One caller at a time gives a command up (a wait, close(), the exit hook).
        self._abandon_lock = threading.Lock()
        #: The command given up whose cancel record (tmflow), after its Stop, could not be
        #: written (the retry policy gave up; the link down, the withdraw and the Stop
        #: failed too): owed, its give-up done again first by the next call
        #: (:meth:`settle_owed`) or by ``close()``. Meanwhile ``silence`` (the Robot's
        #: heartbeat's stop): the robot program sees this master gone, expires the command.
        self.owed: Motion | None = None
        self.silence: Callable[[], None] = lambda: None
        #: Called once a command with a copy of its frame still in the network (resent)
        #: ended: the Robot's heartbeat's, beating with a new session (returned), so that
        #: the program takes that copy as another master's, even after a controller restart.
        self.renew: Callable[[], int] = lambda: channel.session

    def start(self, ticket: Ticket, plan: Plan, register: Callable[[Motion], None]) -> Motion:
        """Send a planned command once (:meth:`send`) and return its handle.

        ``register`` records the handle as the robot's outstanding command, under the
        gate's lock before the first byte is written. Whatever escapes the write, the
        command is given up safely first (:class:`_Following`).
        """
        motion = Motion(self, ticket, plan)
        with _Following(self, motion):
            self.send(ticket, functools.partial(register, motion))
        if self._log.is_enabled_for(logging.INFO):  # its fields built only when logged
            command = ticket.command
            self._log.info(
                "robot.command_sent",
                command=command.kind.value,
                target=None if command.target is None else command.target.as_list(),
                speed=command.speed,
                seq=ticket.seq or None,
                expected_s=round(plan.expected_s, 3),
                timeout_s=round(plan.timeout_s, 3),
            )
        return motion

    def send(self, ticket: Ticket, register: Callable[[], None]) -> None:
        """Write a command once; after a failed write, find out whether it landed.

        Each write passes the gate: refused (:class:`StopRequestedError`, nothing
        written) once the robot's ``close()`` or a stop request began; ``register`` records the
        command as outstanding under the same lock, before its first byte is sent.

        A command is written again only where the protocol makes a duplicate harmless
        (a sequence number the program takes at most once). On a clear-on-accept profile
        the master watches for the late write for ``timeouts.in_flight_s`` and carries on
        if it lands; otherwise the command is withdrawn and the error says so.
        """
        send = functools.partial(self._channel.send, ticket)
        try:
            self.gate.write(register, send)
            return
        except (ConnectionLostError, ResponseTimeoutError) as exc:
            self._log.warning(
                "robot.command_write_failed", error=str(exc), command=ticket.command.kind.value
            )
            failure: TMMasterError = exc
        self._channel.transport.connect()  # the transport's retry policy rides out a short outage
        if self._channel.write_landed(ticket):
            self._log.info("robot.command_write_landed", command=ticket.command.kind.value)
            return
        if self._channel.duplicate_safe:
            # Whether or not the gate admits a copy: the first frame may still be in the
            # network, so the command ends with a new session (_Following).
            ticket.resent = True

            def resending() -> None:  # logged once the gate admits the copy, under its lock
                self._log.warning(
                    "robot.command_resent",
                    command=ticket.command.kind.value,
                    seq=ticket.seq,
                    reason="same sequence number: the program takes it at most once",
                )

            try:
                self.gate.write(resending, send)  # the same ticket: registered already
                return
            except (ConnectionLostError, ResponseTimeoutError) as exc:
                failure = exc
            self._channel.transport.connect()
            if self._channel.write_landed(ticket):
                return
        else:
            deadline = time.monotonic() + self.timeouts.in_flight_s
            poller = Poller(self.polling.interval_s, self.stop_event, deadline=deadline)
            while time.monotonic() < deadline:
                poller.sleep()
                if self._channel.write_landed(ticket):
                    self._log.warning(
                        "robot.command_write_landed_late", command=ticket.command.kind.value
                    )
                    return
        raise CommandStateUnknownError(
            f"the {ticket.command.kind.value} command write got no answer and did not show up in"
            " the robot's registers; it was not written again and has been withdrawn"
        ) from failure

    def stop(self) -> None:
        """Stop the arm now (the channel retries a stop: it is idempotent)."""
        self._channel.stop()
        self._log.warning("robot.stop_sent")

    def abandon(
        self,
        motion: Motion,
        reason: BaseException,
        *,
        deadline: float | None = None,
        closer: bool = False,
    ) -> bool:
        """Make sure a command the master gives up on can never start later.

        Not yet acknowledged: withdraw it (if the robot took it meanwhile, it is running).
        Running: stop the arm, unless the robot stopped itself (fault, e-stop, refusal).
        Every step is best effort and logged; none of them raises a tmmaster error.

        One caller at a time does the work (a wait, ``close()`` on another thread, the
        exit hook): the others wait for it. The command counts as given up safely only
        once its withdraw or stop was delivered or definitively failed: a caller cut
        short (a second Ctrl-C, an exception) leaves it to the next one. In the main
        thread, Ctrl-C is held back until the work is done (``_sigint.deferred``).

        Args:
            motion: the command given up on.
            reason: why (a robot fault means the robot stopped itself).
            deadline: a ``time.monotonic()`` bound on this caller's wait for a
                withdraw's answer and, but for the closer, on waiting for another
                caller's clean-up; None waits as long as that takes (its requests and
                the answer are bounded).
            closer: True for ``Robot.close()`` (and the exit hook): it polls the command
                once first (:meth:`_finished`); its wait for the withdraw's answer is not
                ended by the close itself, only by ``deadline``. Any other caller's wait
                ends when a close begins, and the command is stopped; so the closer waits
                for that caller's clean-up, the give-up being attempted even past
                ``deadline``.

        Returns:
            True when the command can no longer run: never written, already finished,
            withdrawn, stopped by the robot itself, or a stop delivered. False when that
            could not be confirmed (the withdraw and the stop failed, the profile has no
            stop, or another caller was still at it at ``deadline``).
        """
        # -1: no bound. The closer always waits: the close ended the other's answer wait.
        wait_s = -1.0 if deadline is None or closer else max(deadline - time.monotonic(), 0.0)
        if not self._abandon_lock.acquire(timeout=wait_s):
            return False
        try:
            # An article Stop owed here that another Robot of this process delivered since
            # is not sent again (it would halt that Robot's next move): the arm stopped.
            theirs = motion.stop_delivered and not self._channel.duplicate_safe
            if motion._settled is not None and (motion is not self.owed or theirs):
                return motion._settled
            if self._finished(motion, look=closer):
                return True  # nothing left to withdraw or stop
            motion._given_up = reason
            motion.phase = MovePhase.FAILED
            if not motion.ticket.written:
                motion._settled = True  # refused before any byte was sent
                return True
            with deferred():
                motion.stop_delivered = self.owed = None  # what this attempt finds
                confirmed = self._withdraw_or_stop(
                    motion, reason, until=deadline, interruptible=not closer
                )
                # Recorded inside the section: a Ctrl-C held back is raised after it.
                motion._settled = confirmed
                if motion.stop_delivered is False and not self._channel.duplicate_safe:
                    self.owed = motion  # no cancel record (article): the Stop itself is owed
                if self.owed is not None:
                    self.silence()  # no beat: the program expires the command
            return confirmed
        finally:
            self._abandon_lock.release()

    def _finished(self, motion: Motion, *, look: bool) -> bool:
        """Whether the robot finished the command; ``look``: poll one not yet known done
        once first, a failed poll aside (``close()``, as :meth:`Motion.cancel`: a move
        that finished unwatched is neither stopped nor said withdrawn)."""
        if look and motion.phase in (MovePhase.SENT, MovePhase.RUNNING):
            with contextlib.suppress(TMMasterError):  # no pose read: not for a report here
                self._apply(motion, self._channel.poll(motion.ticket))
        return motion.done or motion.ticket.finished

    def settle_owed(self) -> None:
        """Before anything else is sent: deliver the give-up still :attr:`owed`, if any,
        then a Stop another Robot left owed on this robot (its own first).

        Raises:
            CommandStateUnknownError: it could not be delivered this time either; it stays
                owed, and each later call tries it again first.
        """
        while (motion := self.owed or _STOPS_OWED.get(self._robot())) and not self.gate.closed:
            self.owed = motion  # a closed Robot's Stop owed on this robot, too
            given_up = ConnectionLostError("given up, the link down")
            if not self.abandon(motion, given_up) and self.owed:
                raise CommandStateUnknownError(
                    f"command {motion.ticket.seq} was given up, and its withdraw or stop is"
                    " still owed (the link is down?): nothing else is sent to the robot until"
                    " it is done"
                )
            self.owed = None
            self._owed_no_more(motion)

    def _owed_no_more(self, motion: Motion) -> None:
        """Strike ``motion``'s Stop off the process's debts; another Robot's stays owed."""
        if _STOPS_OWED.get(robot := self._robot()) is motion:
            del _STOPS_OWED[robot]

    def _robot(self) -> tuple[str, int, int]:
        """Which robot this follower commands: its link's address, port and unit id."""
        return self._channel.transport.endpoint

    def _withdraw_or_stop(
        self, motion: Motion, reason: BaseException, *, until: float | None, interruptible: bool
    ) -> bool:
        """:meth:`abandon`'s work: withdraw a command not yet taken, stop a running one."""
        ticket = motion.ticket
        running, confirmed = ticket.acknowledged, True
        if not running and not ticket.withdrawn:
            try:
                running = self._withdraw(ticket, until=until, interruptible=interruptible)
                ticket.withdrawn = motion.withdrawn = not running
            except TMMasterError as exc:
                # Not known whether the robot took it: stop, which is harmless if it did not;
                # at once where the withdraw's read was lost (article reads it once).
                running, motion.withdrawn = True, False
                self._log.error(
                    "robot.withdraw_failed", command=motion.command.kind.value, error=str(exc)
                )
            else:
                self._log.warning(
                    "robot.command_withdrawn" if not running else "robot.withdraw_too_late",
                    command=motion.command.kind.value,
                    reason=type(reason).__name__,
                )
        if running and not self._ended_by_robot(ticket, reason):
            if not self._channel.can_stop:
                return False  # running, and this profile cannot stop it
            try:
                self.stop()
                motion.stop_delivered = True
                self._owed_no_more(motion)  # delivered
            except TMMasterError as exc:
                motion.stop_delivered = confirmed = False
                self._log.error("robot.stop_failed", error=str(exc))
                if not is_transient(exc):
                    self._owed_no_more(motion)  # refused: this Robot's alone
                elif not self._channel.duplicate_safe:
                    _STOPS_OWED[self._robot()] = motion  # the link down: the process owes it
            try:
                # After the Stop, never delaying it; whatever became of it: the program
                # ends the command on this record even where the robot refuses Stop.
                self._channel.cancel(ticket)
            except TMMasterError as exc:
                self.owed = motion  # the record is owed: written first once the link is back
                self._log.error("robot.cancel_failed", error=str(exc))
        return confirmed

    def _ended_by_robot(self, ticket: Ticket, reason: BaseException) -> bool:
        """Whether the robot ended a command it took itself, so that no Stop is needed:
        refused it, started its program again under it, or faulted where Play cannot
        resume the move (a paused TMflow project could: it is stopped)."""
        if ticket.restarted or isinstance(reason, CommandRejectedError):
            return True
        if not isinstance(reason, RobotFaultError | EmergencyStopError):
            return False
        try:
            return not self._channel.may_resume()
        except TMMasterError:
            return False  # not known: the Stop is harmless

    def _withdraw(
        self, ticket: Ticket, *, until: float | None = None, interruptible: bool = True
    ) -> bool:
        """Withdraw ``ticket`` and wait for the robot's answer; True if it was taken after all.

        A program that answers withdraws (tmflow's cancel record) is waited for, bounded
        by ``ack_timeout_s`` and by ``until``: "withdrawn" is reported only once the
        program consumed the cancel or cannot take the command any more. A stop request
        does not end this wait (a stop request is what withdraws); the close of the
        robot does when ``interruptible`` (every caller but ``close()`` itself), and the
        caller then stops the command as for an unanswered cancel.

        Raises:
            CommandStateUnknownError: no answer within the bound, or the robot closing
                first (the caller stops).
        """
        if (outcome := self._channel.withdraw(ticket)) is not None:
            return outcome
        deadline = time.monotonic() + self.timeouts.ack_timeout_s
        within = f"within {self.timeouts.ack_timeout_s:g} s"
        if until is not None and until < deadline:
            deadline, within = until, "before the close's timeout"
        # The close's event, not the stop event: a stop request (already set when a
        # stop request gave the command up) must not cut short the withdraw it asks for.
        poller = Poller(
            self.polling.interval_s, self.closing if interruptible else None, deadline=deadline
        )
        while True:
            try:
                poller.sleep()
            except StopRequestedError as exc:
                raise CommandStateUnknownError(
                    f"the robot connection began to close before the robot program answered"
                    f" the cancel of command {ticket.seq}"
                ) from exc
            if (outcome := self._channel.withdraw_outcome(ticket)) is not None:
                return outcome
            if time.monotonic() >= deadline:
                raise CommandStateUnknownError(
                    f"the robot program did not answer the cancel of command {ticket.seq} {within}"
                )

    def poll(self, motion: Motion, retry: bool = True) -> None:
        """Poll the command once for a report, with the pose; raises the typed error when
        the robot failed it. ``retry=False``: the poll's reads are made once (not retried)."""
        polled_pose = motion.last_pose
        self._apply(motion, self._channel.poll(motion.ticket, retry))
        if motion.last_pose is polled_pose and not motion.done:
            # This profile's poll does not carry the pose: read it for the report (as the
            # poll's reads: cancel()'s once, not waiting out the retries while the arm runs).
            motion.last_pose = self._channel.read_pose(retry)

    def _apply(self, motion: Motion, observation: Observation, until: float = float("inf")) -> None:
        """Act on what a poll saw: raise the robot's failure, note the acknowledgement, finish."""
        if observation.pose is not None:
            motion.last_pose = observation.pose
        if observation.failure is not None:
            motion.phase = MovePhase.FAILED
            self._log.error(
                "robot.command_failed",
                command=motion.command.kind.value,
                error=str(observation.failure),
            )
            if observation.failure.pose is None:
                observation.failure.pose = self._pose_or(motion.last_pose)
            raise observation.failure
        if observation.acknowledged:
            self._note_acknowledged(motion)
        if observation.done:
            self._finish(motion, observation, until)

    def _note_acknowledged(self, motion: Motion) -> None:
        """The robot took the command: RUNNING (from the thread, or a Fleet's loop)."""
        if motion.phase is not MovePhase.SENT:
            return
        motion.phase = MovePhase.RUNNING
        ticket = motion.ticket
        if self._log.is_enabled_for(logging.INFO):  # its fields built only when logged
            self._log.info(
                "robot.command_acknowledged",
                command=motion.command.kind.value,
                ack_s=round((ticket.acknowledged_at or time.monotonic()) - ticket.sent_at, 4),
            )

    def wait(self, motion: Motion, timeout_s: float | None) -> None:
        """Poll until the command is done; raises on failure, timeout or stop request."""
        follow = FollowState(
            motion,
            timeout_s,
            stop_event=self.stop_event,
            polling=self.polling,
            timeouts=self.timeouts,
        )
        shared, speed_checked = self.shared_driver, False
        follow.on_acknowledged = functools.partial(self._note_acknowledged, motion)
        while True:
            observation = None if shared is None else shared(follow)
            if observation is None:
                # This thread polls: no shared driver, or it handed this poll back (a
                # stop request, a failed or busy link: the transport's retries apply).
                follow.poller.sleep_until(follow.due())
                follow.poll_started = time.monotonic()
                observation = self._channel.poll(motion.ticket)
            self._apply(motion, observation, follow.deadline())
            if motion.done:
                return
            overdue = follow.overdue(time.monotonic())
            if overdue is Overdue.ACK:
                self._ack_timed_out(motion)
            elif overdue is Overdue.MOTION:
                if not speed_checked and self._project_slowed(motion, follow):
                    speed_checked = True
                    continue
                self._motion_timed_out(motion, follow)

    def _project_slowed(self, motion: Motion, follow: FollowState) -> bool:
        """At a derived deadline: True when the project speed was lowered since the plan,
        the move's budget then grown by as much (the move takes that much longer)."""
        reread = self.project_speed
        if reread is None or not follow.scales_with_pace:
            return False
        try:
            percent = reread()
        except TMMasterError:
            return False  # not known: the deadline stands
        planned = motion.project_speed_percent
        if percent is None or percent >= planned:
            return False
        factor = planned / percent
        follow.budget *= factor
        motion.expected_s *= factor
        motion.project_speed_percent = percent
        self._log.warning(
            "robot.project_speed_lowered", planned=planned, now=percent, budget_s=follow.budget
        )
        return True

    def _pose_or(self, fallback: Pose | None) -> Pose | None:
        """The current pose for an error report, read once (a Stop may follow: not after
        the retries); the fallback if it cannot be read."""
        try:
            return self._channel.read_pose(retry=False)
        except TMMasterError:
            return fallback

    def _finish(self, motion: Motion, polled: Observation, until: float = float("inf")) -> None:
        motion.reported_finished_at = time.monotonic()
        if motion.target is not None:
            self._arrived(motion, polled, min(until, motion.reported_finished_at + SETTLE_S))
        motion.phase = MovePhase.DONE
        motion.finished_at = time.monotonic()
        if self._log.is_enabled_for(logging.INFO):  # its fields built only when logged
            self._log.info(
                "robot.command_done",
                command=motion.command.kind.value,
                duration_s=round(motion.finished_at - motion.ticket.sent_at, 4),
                expected_s=round(motion.expected_s, 3),
            )

    def _arrived(self, motion: Motion, polled: Observation, deadline: float) -> None:
        """Check that the arm of a move the robot reported finished is at its target.

        The poll that saw it finished read the pose (article: in the same snapshot;
        tmflow: right after it, with the joints). Pose registers can trail the done flag
        by a few ticks: a pose that misses is read again each robot tick, and the move is
        done once two reads in a row are at the target, and within half the tolerances of
        each other (the arm holds still there: a robot that reports done while its arm
        still moves is not believed for it). A miss at ``deadline`` (the first read's,
        when past) is a RobotError, as is a read there that does not hold still; a read
        past it that first finds the arm at the target has one more read, a robot tick
        later (a master slow to read its robot, on a loaded machine, is not failed for
        its own lateness). A stop request ends the wait.
        """
        pose, joints = polled.pose, polled.joints
        if pose is None:
            pose, joints, _ = self._channel.read_plan()
        # held: the last read's pose; hit: it was at the target (the done poll's counts alone)
        # Paced by robot ticks, also past the deadline (the last read's: one tick later).
        poller, held, hit = Poller(TICK_S, self.stop_event), pose, True
        mm, deg = self.position_tolerance_mm / 2, self.orientation_tolerance_deg / 2
        while True:
            motion.last_pose, miss = pose, self._miss(motion, pose, joints)
            if (still := pose.is_close(held, mm=mm, deg=deg)) and miss is None and hit:
                return
            motion.phase = MovePhase.FAILED  # DONE once seen held at the target
            # Not finished while seen moving: if the move fails here, abandon stops the arm.
            motion.ticket.finished &= still
            # Past the deadline, a read that first finds the arm at the target has the
            # next one to show it holds still (the master may be the slow one).
            if time.monotonic() >= deadline and (miss or hit):
                self._channel.after_done = None  # a failed move's state is not reused
                miss = miss or f"the TCP at {pose} did not hold still at the target"
                raise RobotError(f"robot reported the move finished but {miss}", pose=pose)
            held, hit = pose, miss is None
            poller.sleep()
            pose, joints, _ = self._channel.read_plan()

    def _miss(self, motion: Motion, pose: Pose, joints: tuple[float, ...] | None) -> str | None:
        """How the arm misses the move's target; None: within the tolerances. A joint
        move's target TCP is the model's forward kinematics: its joints decide where
        published (another branch reaches the same TCP with other joints)."""
        wanted, target, deg = motion.command.joints, motion.target, self.orientation_tolerance_deg
        assert target is not None
        if wanted is None or joints is None:
            off = pose.distance_to(target)
            close = pose.is_close(target, mm=self.position_tolerance_mm, deg=deg)
            return None if close else f"the TCP is at {pose}, {off:.2f} mm from the target {target}"
        off = max(abs(a - b) for a, b in zip(joints, wanted, strict=True))
        got, aim = [round(q, 2) for q in joints], [round(q, 2) for q in wanted]
        return None if off <= deg else f"its joints are {got}, {off:.2f} deg from the target {aim}"

    def _ack_timed_out(self, motion: Motion) -> None:
        ticket = motion.ticket
        try:
            taken = self._withdraw(ticket)
        except CommandStateUnknownError as exc:
            # Not known whether the program will take it: the clean-up that follows
            # (abandon) withdraws again, and stops the project if still unanswered.
            raise self._unacknowledged(motion, f", nor answer its cancel: {exc}") from exc
        if taken:
            # The robot took it just as we gave up: it is executing our command.
            ticket.acknowledged, ticket.acknowledged_at = True, time.monotonic()
            motion.phase = MovePhase.RUNNING
            self._log.warning("robot.late_acknowledgement", command=motion.command.kind.value)
            return
        ticket.withdrawn = motion.withdrawn = True
        hint = "; the robot program's heartbeat did not change: is the TMflow project running?"
        hint = hint if heartbeat_stalled(ticket) else ""
        raise self._unacknowledged(motion, f"; the command was withdrawn{hint}")

    def _unacknowledged(self, motion: Motion, outcome: str) -> AcknowledgeTimeoutError:
        """Not taken in time: the motion failed (logged); the error to raise, ``outcome``
        saying what became of the command."""
        motion.phase = MovePhase.FAILED
        self._log.error("robot.acknowledge_timeout", command=motion.command.kind.value)
        return AcknowledgeTimeoutError(
            f"the robot did not acknowledge the {motion.command.kind.value} command within"
            f" {self.timeouts.ack_timeout_s:g} s{outcome}",
            pose=motion.last_pose,
        )

    def _motion_timed_out(self, motion: Motion, follow: FollowState) -> None:
        motion.phase = MovePhase.FAILED
        budget = follow.applied_budget()  # the bound actually applied, grown or not
        pose = self._pose_or(motion.last_pose)
        self._log.error(
            "robot.motion_timeout",
            timeout_s=round(budget, 3),
            pose=None if pose is None else pose.as_list(),
        )
        # The stop follows in abandon(), as for every running move the master gives up on.
        raise MotionTimeoutError(
            f"move to {motion.target} did not finish within {budget:.2f} s"
            f" (expected {motion.expected_s:.2f} s){follow.describe_stall()}; last pose {pose}",
            pose=pose,
        )
