"""The one pacing loop every wait in tmmaster uses."""

from __future__ import annotations

import math
import threading
import time
from typing import Annotated, ClassVar

from pydantic import BeforeValidator

from ._checks import Bounds, Policy, bounded
from ._exceptions import ConfigError, StopRequestedError


class Poller:
    """Paces a wait: one poll per interval on a monotonic clock, every wait interruptible.

    A stop event, when given, ends the wait: :meth:`sleep` raises
    :class:`StopRequestedError` as soon as the event is set (``Event.wait`` wakes at
    once), so a stop request never turns a wait into a busy loop of requests.

    A deadline, when given, is the wait's own: no sleep lasts past it, so the poll
    after the last sleep happens at the deadline, not up to an interval later. Past
    it, a sleep returns at once: the caller's loop checks the deadline after each
    poll and ends the wait.

    Args:
        interval_s: Seconds between two polls (> 0).
        stop_event: Ends every sleep when set; None: nothing ends them early.
        deadline: A ``time.monotonic()`` value no sleep lasts past; None: no bound.

    Raises:
        ConfigError: An interval that is not a finite number > 0, or a deadline that is
            not a finite number.
    """

    def __init__(
        self,
        interval_s: float,
        stop_event: threading.Event | None = None,
        *,
        deadline: float | None = None,
    ) -> None:
        if not (isinstance(interval_s, int | float) and math.isfinite(interval_s)) or (
            interval_s <= 0
        ):
            raise ConfigError(f"poll interval must be a finite number > 0 s, got {interval_s!r}")
        if deadline is not None and not (
            isinstance(deadline, int | float) and math.isfinite(deadline)
        ):
            raise ConfigError(f"deadline must be a finite time.monotonic() value, got {deadline!r}")
        #: Seconds between two polls.
        self.interval_s = interval_s
        #: No sleep lasts past this ``time.monotonic()`` value (None: no bound).
        self.deadline = deadline
        self._next = time.monotonic()
        self._stop = stop_event

    def check(self) -> None:
        """Raise :class:`StopRequestedError` if a stop was requested.

        Raises:
            StopRequestedError: The stop event is set.
        """
        if self._stop is not None and self._stop.is_set():
            raise StopRequestedError("stop requested")

    def sleep_until(self, when: float) -> None:
        """Sleep until the monotonic time ``when``, or the deadline if that comes first.

        At once if that moment has passed.

        Args:
            when: A ``time.monotonic()`` value.

        Raises:
            StopRequestedError: The stop event is set, before or during the sleep.
        """
        self.check()
        if self.deadline is not None and self.deadline < when:
            when = self.deadline
        delay = when - time.monotonic()
        if delay <= 0:
            return
        if self._stop is None:
            time.sleep(delay)
        elif self._stop.wait(delay):
            raise StopRequestedError("stop requested")

    def sleep(self) -> None:
        """Sleep until the next poll is due (no drift: polls advance by the interval).

        Never past the deadline: the last sleep of a wait ends at it.

        Raises:
            StopRequestedError: The stop event is set, before or during the sleep.
        """
        self._next += self.interval_s
        now = time.monotonic()
        if self._next < now:  # a slow poll: don't try to catch up with a burst of reads
            self._next = now
        self.sleep_until(self._next)


#: The range of a wait's nominal poll interval (``PollPolicy.interval_s``), s.
INTERVAL_BOUNDS = Bounds(0.001, 5.0, "s")


class PollPolicy(Policy):
    """How a robot polls its waits: the nominal pace, dense where an answer is due.

    ``Robot(host, polling=PollPolicy(interval_s=0.02))``: every wait reads the robot's
    status at most ``interval_s`` apart (its nominal pace).

    ``predictive`` (the default): the master knows when the robot should acknowledge a
    command (its next control tick after the write) and when a move should end (its
    start + the model's expected time, at the pace the polls observe). It polls about
    every 10 ms in those short windows and spaces the polls in between (:class:`MotionSchedule`).
    A robot faster than the model is seen within one nominal interval.

    An invalid value is a :class:`~tmmaster.ConfigError` naming the field
    (``polling.interval_s must be a number in [0.001, 5] s, got 10``).
    """

    #: The Robot argument that takes it: its fields are named ``polling.<field>`` in errors.
    argument: ClassVar[str] = "polling"

    #: Seconds between two status reads of a wait (its nominal pace), 0.001 to 5.
    interval_s: Annotated[
        float, BeforeValidator(bounded("polling.interval_s", INTERVAL_BOUNDS))
    ] = 0.05
    #: False: poll every nominal interval, nothing else.
    predictive: bool = True


#: A robot's control tick (TM: 50 Hz), s: it takes a command and reports an end at one.
TICK_S = 0.02
#: The first poll after a write: just after the robot's next tick, s.
ACK_DELAY_S = TICK_S + 0.001
#: The widest window polled densely, s: what a robot on the model needs, one tick and
#: the acknowledgement's doubt (at most ``ACK_DELAY_S``).
_WIDEST_WINDOW_S = TICK_S + ACK_DELAY_S
#: The interval where an answer is due (the acknowledgement, a move's end), s: four
#: polls cover the widest window, and an end is seen early enough to write the next
#: command before the robot's next tick.
DENSE_S = _WIDEST_WINDOW_S / 4
#: A move's middle is polled at most this many nominal intervals apart.
STRETCH = 3.0
#: The earliest a move may end, as a fraction of the time left by the model (0.5: a
#: robot twice as fast): polls are never further apart than the nominal interval after it.
EARLIEST_FRACTION = 0.5
#: How far an observed pace may move the predicted end: a robot between 4 times faster
#: and 20 times slower than the model, as at a project speed of 5 %, where TMflow starts
#: a trial run and the operator raises or lowers it while the arm moves (TMflow 2.24,
#: 4.4 step 10, p. 49; 4.5 table 4, p. 53); beyond that the observation is not trusted.
_PACE_LIMITS = (0.25, 20.0)
#: How many times the model's budget a move's wait may grow to (the slowest pace trusted).
PACE_LIMIT = _PACE_LIMITS[1]
#: Observed progress used to re-predict the end: not the first few per cent, where a
#: pose's rounding weighs more than the progress; past the last few, only as a loose
#: bound (the robot is past the first, not yet at its end).
_PROGRESS_USED = (0.05, 0.95)


class MotionSchedule:
    """When to poll a move next, from its send time, acknowledgement and expected time.

    The robot took the command between ``since`` (the last moment it was seen pending)
    and the acknowledgement, and moves at a pace (times the model's time) known to lie
    in a range: 1 by the model, then what the poses the polls read allow. The end falls
    between the earliest start at the lowest pace and the latest start at the highest
    pace, and is reported at the robot's next tick: the polls are dense (``DENSE_S``)
    over exactly that window, nominal from the earliest plausible end to it, and spaced
    (``STRETCH``) before. Nothing here decides that a move ended: only a poll does.

    ``accel_s``: the move's acceleration time by the model (the progress of a move
    follows a trapezoid profile), used to read the robot's pace from the progress a
    poll observes (:meth:`observed`).
    """

    def __init__(self, policy: PollPolicy, sent_at: float, *, accel_s: float = 0.0) -> None:
        self._predictive = policy.predictive
        self._nominal = policy.interval_s
        self._sent_at = sent_at
        self._accel = max(accel_s, 0.0)
        self._acked_at = 0.0
        #: The earliest moment the robot may have taken the command.
        self._took_from = 0.0
        self._expected = 0.0
        #: No poll spaced beyond the nominal interval from this moment (monotonic s).
        self._earliest = math.inf
        self._observations = 0
        #: The robot's pace (times the model's time): its lowest and highest plausible value.
        self._paces = (1.0, 1.0)

    def acknowledged(self, at: float, expected_s: float, *, since: float | None = None) -> None:
        """Anchor the end window: the move should end ``expected_s`` after it started.

        ``since``: the latest moment the command was seen not yet taken (the start of
        the last poll that saw it pending, else the write). The robot took it between
        ``since`` (at most a tick before ``at``) and ``at``.
        """
        if not self._predictive or expected_s <= 0:
            return
        doubt = 0.0 if since is None else min(max(at - since, 0.0), ACK_DELAY_S)
        self._acked_at, self._took_from, self._expected = at, at - doubt, expected_s
        self._earliest = self._took_from + expected_s * EARLIEST_FRACTION

    def observed(self, at: float, fraction: float | None) -> None:
        """Narrow the robot's pace, and so the end window, by the progress a poll observed.

        The robot was at ``fraction`` of its path at its last tick before ``at``, and
        started between the earliest take and the acknowledgement: that bounds its pace.
        A bound that agrees with the range known so far narrows it; one that does not
        (a robot that changed its pace) replaces it.

        Args:
            at: when the poll began (``time.monotonic()``).
            fraction: how much of the move's path the robot had covered (0..1), None
                when the poll could not tell.
        """
        low, high = _PROGRESS_USED
        if fraction is None or self._expected <= 0 or fraction <= low:
            return  # nothing seen yet, or not yet out of the ramp: a look still due
        self._observations += 1
        # A robot k times slower than the model covers the model's profile k times
        # slower: the progress seen is the model's at ``elapsed / k``. Braking (past
        # ``high``), a pose bounds the pace only loosely: by ``high`` and by the end.
        model_elapsed = _elapsed_at(min(fraction, high), self._expected, self._accel)
        least, most = _PACE_LIMITS
        slow = min(max((at - self._took_from) / model_elapsed, least), most)
        model_elapsed = self._expected if fraction >= high else model_elapsed
        fast = min(max((at - TICK_S - self._acked_at) / model_elapsed, least), slow)
        lowest, highest = self._paces
        overlap = fast <= highest and lowest <= slow
        self._paces = (max(lowest, fast), min(highest, slow)) if overlap else (fast, slow)
        # The earliest plausible end from here: the rest of the move twice as fast, never
        # later than the model's end (a robot that speeds up again is seen in time).
        opens = self.window()[0]
        self._earliest = min(
            at + max(opens - at, 0.0) * EARLIEST_FRACTION, self._acked_at + self._expected
        )

    def window(self) -> tuple[float, float]:
        """From when to when the robot may report the end (monotonic s; both 0 before
        the acknowledgement)."""
        if self._expected <= 0:
            return (0.0, 0.0)
        lowest, highest = self._paces
        opens = self._took_from + self._expected * lowest
        closes = self._acked_at + self._expected * highest + TICK_S
        # A pace known only roughly (one look, early in the move) would make a window
        # too wide to poll densely: its middle, the nominal pace either side.
        spare = max(closes - opens - _WIDEST_WINDOW_S, 0.0) / 2
        return opens + spare, closes - spare

    def observation_due(self) -> float:
        """When the next poll should read the pose (infinity: none should): a third and
        two thirds into the move.

        The progress seen on the way narrows the robot's pace, and with it the window
        where it reports the end; the second look corrects the first (read early, in
        the ramp, it weighs a pose's rounding and the model's profile more).
        """
        end = self.expected_end
        if self._observations >= 2 or end is None:
            return math.inf
        return self._acked_at + (end - self._acked_at) * (self._observations + 1) / 3

    @property
    def pace(self) -> float:
        """How many times slower than the model the robot moves, at the most (1: as
        predicted or not observed; 0.25..4)."""
        return self._paces[1]

    @property
    def expected_end(self) -> float | None:
        """When the move ends at the latest start and highest pace (monotonic s), None
        before the acknowledgement."""
        return None if self._expected <= 0 else self._acked_at + self._expected * self._paces[1]

    def next_poll(self, now: float, *, acknowledged: bool) -> float:
        """The monotonic time of the next poll (never earlier than ``now``)."""
        nominal = self._nominal
        if not self._predictive:
            return now + nominal
        dense = min(DENSE_S, nominal)
        if not acknowledged:
            first = self._sent_at + ACK_DELAY_S
            return first if now < first else now + (dense if now < first + TICK_S else nominal)
        if self._expected <= 0:
            return now + nominal
        opens, closes = self.window()
        # The robot reports the end after the window opens: the first poll there comes
        # a dense interval after it.
        first = opens + dense
        if now < self._earliest:
            # A poll a nominal interval past the earliest end sees an end there; one
            # where a look at the pose is due moves the window with the robot's pace.
            look = self.observation_due()
            return min(
                now + nominal * STRETCH,
                self._earliest + nominal,
                first,
                look if look > now + nominal else first,
            )
        if now < opens:
            return min(now + nominal, first)
        return now + (dense if now < closes else nominal)


def _elapsed_at(fraction: float, total: float, accel_time: float) -> float:
    """When a trapezoid move of ``total`` s has covered ``fraction`` (0..1) of its path.

    The inverse of :func:`~tmmaster._robot_models.trapezoid_progress`.
    """
    ramp = min(accel_time, total / 2.0)
    if ramp <= 0:
        return fraction * total
    top = 1.0 / (total - ramp)  # the top speed, in path per second
    ramp_part = 0.5 * top * ramp
    if fraction < ramp_part:
        return math.sqrt(2.0 * fraction * ramp / top)
    if fraction <= 1.0 - ramp_part:
        return ramp + (fraction - ramp_part) / top
    return total - math.sqrt(2.0 * (1.0 - fraction) * ramp / top)
