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
from ._poller import MotionSchedule, Poller, PollPolicy
from ._pose import Pose
from ._status import MovePhase


class FollowedMotion(Protocol):
    """What a wait needs of a :class:`~tmmaster.Motion`."""

    phase: MovePhase
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
        "ack_deadline",
        "budget",
        "motion",
        "poll_started",
        "poller",
        "scales_with_pace",
        "schedule",
        "stop_event",
    )

    def __init__(
        self,
        motion: FollowedMotion,
        timeout_s: float | None,
        *,
        stop_event: threading.Event,
        poll_interval_s: float,
        polling: PollPolicy,
        ack_timeout_s: float,
    ) -> None:
        ticket = motion.ticket
        self.motion = motion
        #: The motion's time budget from its acknowledgement, s.
        self.budget = timeout_s if timeout_s is not None else motion.timeout_s
        #: True when the budget was derived from the model's expected time (no timeout
        #: given): it then grows with the pace the polls observe.
        self.scales_with_pace = timeout_s is None and motion.timeout_from_model
        self.stop_event = stop_event
        self.poller = Poller(poll_interval_s, stop_event)
        self.schedule = MotionSchedule(
            polling, poll_interval_s, ticket.sent_at, accel_s=motion.accel_s
        )
        self.ack_deadline = ticket.sent_at + ack_timeout_s
        #: ``time.monotonic()`` at the start of the last poll (the wait's start before one).
        self.poll_started = time.monotonic()
        self._anchored = False
        self._observed: Pose | None = None

    def due(self) -> float:
        """The monotonic time of the next poll.

        The prediction follows what the polls observe: each new pose the robot reported
        moves the predicted end by the pace it shows (:meth:`MotionSchedule.observed`).
        """
        motion = self.motion
        ticket = motion.ticket
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
            self.schedule.observed(self.poll_started, motion.path_fraction(pose))
        due = self.schedule.next_poll(self.poll_started, acknowledged=ticket.acknowledged)
        # A profile whose poll carries no pose reads it once, where it tells the most.
        ticket.observe_pose = self.schedule.wants_observation(due)
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
        if motion.phase is MovePhase.RUNNING:
            ticket = motion.ticket
            started = ticket.acknowledged_at or ticket.sent_at
            budget = self.budget
            if self.scales_with_pace:
                # A robot slower than the model (a reduced project speed) that the polls
                # see progressing steadily is not stalled: its budget grows with the pace
                # observed (at most 4 times). A stalled arm shows no progress, and keeps
                # the model's budget.
                budget *= max(self.schedule.pace, 1.0)
            return started + budget
        return math.inf

    def overdue(self, now: float) -> Overdue | None:
        """The deadline that passed: acknowledgement (while sent), motion (while running)."""
        if now < self.deadline():
            return None
        return Overdue.ACK if self.motion.phase is MovePhase.SENT else Overdue.MOTION

    def settled(self, observation: Observation, now: float) -> bool:
        """True when a poll's result needs the waiting thread (anything but "poll again")."""
        if observation.failure is not None or observation.done:
            return True
        if observation.acknowledged and self.motion.phase is MovePhase.SENT:
            return True  # the thread notes it (and the schedule anchors on it)
        return self.overdue(now) is not None


#: A driver that polls a wait for the robot's thread (a Fleet's event loop): it returns
#: the first observation the thread must act on, or None to hand the next poll back.
SharedDriver = Callable[[FollowState], Observation | None]
