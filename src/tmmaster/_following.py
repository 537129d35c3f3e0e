"""One wait on one motion, between polls: its schedule and deadlines, without I/O.

The robot's thread (``_robot.py``) and a Fleet's event loop (``_fleet.py``) both poll
a wait by this state, so when to poll and when to stop polling are written once.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from enum import Enum
from typing import Protocol

from ._channels import Observation, Ticket
from ._planning import TimeoutPolicy
from ._poller import PACE_LIMIT, MotionSchedule, Poller, PollPolicy
from ._pose import Pose
from ._status import MovePhase

#: How far the arm must move between two polls' poses for the wait to count it as
#: progress: above a reported pose's rounding (0.001 mm on Techman's table, 0.1 mm on
#: the article's), far below any real move's travel in a poll interval.
PROGRESS_MM = 0.1
#: The same for the orientation alone (a move that only turns the tool), deg.
PROGRESS_DEG = 0.1
#: Within this of its target (mm) an arm is arriving, never stalled: one slower than the
#: model creeps into its target by less than PROGRESS_MM a poll, as slowly as it is
#: slow, then reports done at its next tick.
ARRIVING_MM = 1.0
#: The same for the orientation, deg.
ARRIVING_DEG = 1.0
#: The shortest stall window a short move's budget sets, s (``stall_s`` set lower wins):
#: a reported pose can stand still for a few status cycles while the arm moves (a
#: controller or network hiccup, a robot's host paused), never a stall that short.
STALL_FLOOR_S = 0.5


class FollowedMotion(Protocol):
    """What a wait needs of a :class:`~tmmaster.Motion`."""

    phase: MovePhase
    #: Where the move started, when known.
    start: Pose | None
    #: The TCP target (None for a gripper command).
    target: Pose | None
    expected_s: float
    timeout_s: float
    last_pose: Pose | None
    #: The move's acceleration time by the arm model, s (0: not a move).
    accel_s: float
    #: True when ``timeout_s`` was derived from the model's expected time.
    timeout_from_model: bool

    def path_fraction(self, pose: Pose) -> float | None:
        """How much of the move's path the robot covered at ``pose`` (None: cannot tell)."""
        ...

    @property
    def ticket(self) -> Ticket:
        """The channel's record of the command."""
        ...


class Overdue(Enum):
    """Which deadline of a wait passed (:meth:`FollowState.overdue`)."""

    ACK = "ack"
    MOTION = "motion"


class FollowState:
    """One wait on one motion between polls: when to poll next, and when to stop polling.

    No I/O: the robot's thread consults it between its own polls, and a
    :class:`~tmmaster.Fleet`'s event loop between the polls it runs for the thread
    (:meth:`settled` says when the thread must take over). The schedule counts from
    the start of the last poll, not its end (no drift): in a dense window a poll
    follows the last one's start by the dense interval, whatever the poll's own
    requests took. A poll that took longer than its interval is followed at once:
    never more than one poll per interval.
    """

    __slots__ = (
        "_anchored",
        "_observed",
        "_progress_pose",
        "ack_deadline",
        "budget",
        "last_progress_at",
        "motion",
        "on_acknowledged",
        "poll_started",
        "poller",
        "scales_with_pace",
        "schedule",
        "stall_s",
        "stop_event",
    )

    def __init__(
        self,
        motion: FollowedMotion,
        timeout_s: float | None,
        *,
        stop_event: threading.Event,
        polling: PollPolicy,
        timeouts: TimeoutPolicy,
    ) -> None:
        ticket = motion.ticket
        self.motion = motion
        #: The motion's time budget from its acknowledgement, s.
        self.budget = timeout_s if timeout_s is not None else motion.timeout_s
        #: True when the budget was derived from the model's expected time (no timeout
        #: given): it then grows with the pace the polls observe.
        self.scales_with_pace = timeout_s is None and motion.timeout_from_model
        self.stop_event = stop_event
        self.poller = Poller(polling.interval_s, stop_event)
        self.schedule = MotionSchedule(polling, ticket.sent_at, accel_s=motion.accel_s)
        self.ack_deadline = ticket.sent_at + timeouts.ack_timeout_s
        #: ``time.monotonic()`` at the start of the last poll (the wait's start before one).
        self.poll_started = time.monotonic()
        self._anchored = False
        self._observed: Pose | None = None
        #: How long a move whose budget grew with its pace may show no progress, s.
        self.stall_s = timeouts.stall_s
        #: ``time.monotonic()`` of the poll that last saw the arm move (None: not yet).
        self.last_progress_at: float | None = None
        self._progress_pose: Pose | None = motion.start
        #: Notes the acknowledgement where the poll saw it (the command path's, so that a
        #: Fleet's loop polls on to the end instead of handing the thread each step);
        #: None: :meth:`settled` hands the acknowledgement to the waiting thread.
        self.on_acknowledged: Callable[[], None] | None = None

    def due(self) -> float:
        """The monotonic time of the next poll.

        The prediction follows what the polls observe: each new pose the robot reported
        moves the predicted end by the pace it shows (:meth:`MotionSchedule.observed`).
        """
        self._take_in_last_poll()
        motion, ticket = self.motion, self.motion.ticket
        due = self.schedule.next_poll(self.poll_started, acknowledged=ticket.acknowledged)
        # A profile whose poll carries no pose reads it once, where it tells the most;
        # and at every poll from a stall's bound before the model's budget ends, where
        # only progress seen keeps the wait going.
        ticket.observe_pose = due >= self.schedule.observation_due() or (
            self.scales_with_pace
            and motion.phase is MovePhase.RUNNING
            and due >= self._model_deadline() - self.stall_window()
        )
        # Never past the wait's deadline: a long interval (or a stretched one in the
        # middle of a move) ends there, and the poll at the deadline tells.
        return min(due, self.deadline())

    def deadline(self) -> float:
        """When the wait's current deadline passes (``time.monotonic()``).

        The acknowledgement's while the command is sent, the motion's while it runs,
        infinity otherwise.
        """
        motion = self.motion
        if motion.phase is MovePhase.SENT:
            return self.ack_deadline
        running = motion.phase is MovePhase.RUNNING
        return self._started() + self.applied_budget() if running else math.inf

    def applied_budget(self) -> float:
        """The motion's budget in force now, from its acknowledgement, s.

        The given (or model's) budget, grown with the pace the polls observe (a robot
        slower than the model, a reduced project speed: at most 20 times) only as far as
        the arm keeps moving: past the model's budget, a poll must see progress at
        least every :meth:`stall_window`. An arm that stops is a stall, raised at the
        model's budget when it stopped before it, else a window after its last progress.
        """
        if not self.scales_with_pace:
            return self.budget
        grown = self.budget * max(self.schedule.pace, 1.0)
        if self.last_progress_at is None:
            return self.budget
        moving_until = max(self._model_deadline(), self.last_progress_at + self.stall_window())
        return min(grown, moving_until - self._started())

    def stall_window(self) -> float:
        """How long the arm may show no progress past the model's budget, s.

        ``stall_s``, or a quarter of the budget for a short move but at least
        :data:`STALL_FLOOR_S`: a stall that began before the model's budget ended is
        raised when it ends.
        """
        return min(self.stall_s, max(self.budget / 4, STALL_FLOOR_S))

    def longest_budget(self) -> float:
        """The most :meth:`applied_budget` can grow to, s (a bound for whoever waits on it)."""
        return self.budget * PACE_LIMIT if self.scales_with_pace else self.budget

    def _started(self) -> float:
        return self.motion.ticket.acknowledged_at or self.motion.ticket.sent_at

    def _model_deadline(self) -> float:
        return self._started() + self.budget

    def _note_progress(self, pose: Pose) -> None:
        """Count ``pose`` as progress when the arm moved measurably since the last, or is
        arriving at its target.

        Where the model gauges the path, the move must be that much farther along it: a
        report that wobbles by a tenth of a millimetre (a calibrated arm's) around an
        arm that stands still makes no new farthest point at every poll.
        """
        last, motion = self._progress_pose, self.motion
        start, target = motion.start, motion.target
        arriving = target is not None and pose.is_close(target, mm=ARRIVING_MM, deg=ARRIVING_DEG)
        if last is not None and not arriving:
            now, then = motion.path_fraction(pose), motion.path_fraction(last)
            moved = pose.distance_to(last), pose.rotation_to(last)
            if now is not None and then is not None and start is not None and target is not None:
                gain = now - then
                moved = gain * start.distance_to(target), gain * start.rotation_to(target)
            if moved[0] < PROGRESS_MM and moved[1] < PROGRESS_DEG:
                return
        self._progress_pose = pose
        if last is not None:
            self.last_progress_at = self.poll_started

    def describe_stall(self) -> str:
        """Why the motion's deadline passed, for its timeout's message."""
        if not self.scales_with_pace or self.applied_budget() >= self.budget * max(
            self.schedule.pace, 1.0
        ):
            return ""
        if self.last_progress_at is None:
            return "; no progress seen since the acknowledgement"
        idle = time.monotonic() - self.last_progress_at
        return f"; no progress seen for {idle:.2f} s (a stall)"

    def _take_in_last_poll(self) -> None:
        """Anchor the schedule on the acknowledgement, and count the last poll's pose (its
        progress, the pace it shows) once."""
        motion, ticket = self.motion, self.motion.ticket
        if ticket.acknowledged and not self._anchored:
            self.schedule.acknowledged(
                ticket.acknowledged_at or ticket.sent_at,
                motion.expected_s,
                since=ticket.pending_seen_at or ticket.sent_at,
            )
            self._anchored = True
        pose = motion.last_pose
        if self._anchored and pose is not None and pose is not self._observed:
            self._observed = pose
            self._note_progress(pose)
            self.schedule.observed(self.poll_started, motion.path_fraction(pose))

    def overdue(self, now: float) -> Overdue | None:
        """The deadline that passed: acknowledgement (while sent), motion (while running).

        The last poll counts first: at a deadline, its pose may show the arm still moving.
        """
        self._take_in_last_poll()
        if now < self.deadline():
            return None
        return Overdue.ACK if self.motion.phase is MovePhase.SENT else Overdue.MOTION

    def settled(self, observation: Observation, now: float) -> bool:
        """True when a poll's result needs the waiting thread (anything but "poll again")."""
        if observation.failure is not None or observation.done:
            return True
        if observation.acknowledged and self.motion.phase is MovePhase.SENT:
            if self.on_acknowledged is None:
                return True  # the thread notes it (and the schedule anchors on it)
            self.on_acknowledged()  # RUNNING: the motion's deadline applies from here
        return self.overdue(now) is not None


#: A driver that polls a wait for the robot's thread (a Fleet's event loop): it returns
#: the first observation the thread must act on, or None to hand the next poll back.
SharedDriver = Callable[[FollowState], Observation | None]
