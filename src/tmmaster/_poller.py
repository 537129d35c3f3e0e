"""The one pacing loop every wait in tmmaster uses."""

from __future__ import annotations

import math
import threading
import time
from typing import Annotated, ClassVar

from pydantic import BeforeValidator, Field

from ._checks import Bounds, Policy, bounded
from ._exceptions import ConfigError, StopRequestedError
from ._robot_models import trapezoid_progress


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
        if self._stop is not None:
            if self._stop.wait(delay):
                raise StopRequestedError("stop requested")
        else:
            time.sleep(delay)

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
    """How a robot polls its waits: the nominal pace, dense where something is expected.

    ``Robot(host, polling=PollPolicy(interval_s=0.02))``: every wait reads the robot's
    status at most ``interval_s`` apart (its nominal pace).

    The master knows when the robot should acknowledge (its next control tick after the
    write) and when the move should end (acknowledgement + expected time). It polls
    densely in a short window at those moments and spaces the polls in between so that
    a move costs no more requests than polling at the nominal interval would.

    The prediction is the arm model's, and a robot may differ from it: the polls are
    spaced only until the earliest moment the move could plausibly end (a robot
    ``1 / earliest_end_fraction`` times faster than the model), never more sparsely
    than the nominal interval after that, and the predicted end moves with the progress
    each poll observes. A finish the model did not predict is seen within one nominal
    interval.

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
    #: Interval inside the dense windows, in seconds.
    dense_interval_s: Annotated[float, Field(gt=0, le=1)] = 0.008
    #: Half-width of the window around the expected end of a move, in seconds. The
    #: window opens half of this before the expected end and closes 1.5 times this after
    #: it: a robot reports the end at its next control tick, and never early.
    completion_window_s: Annotated[float, Field(gt=0, le=5)] = 0.05
    #: First poll after the write: about one robot control tick (TM: 50 Hz), in seconds.
    ack_delay_s: Annotated[float, Field(gt=0, le=1)] = 0.021
    #: How long to keep polling densely after ``ack_delay_s`` for the acknowledgement.
    ack_window_s: Annotated[float, Field(ge=0, le=1)] = 0.02
    #: Never space the polls in the middle of a move by more than this many nominal intervals.
    max_stretch: Annotated[float, Field(ge=1, le=10)] = 3.0
    #: The earliest a move may end, as a fraction of its expected time (0.5: a robot
    #: twice as fast as the model): polls are never spaced beyond the nominal interval
    #: from then on. 0 never spaces them; 1 trusts the model's time.
    earliest_end_fraction: Annotated[float, Field(ge=0, le=1)] = 0.5
    #: The next command's checks may use the registers read by the poll that saw the
    #: previous command finished instead of reading them again, if that poll began at most
    #: this long ago (seconds) on the same connection with nothing written since; 0: the
    #: checks always read again. The default is one TM control tick (50 Hz).
    reuse_done_read_s: Annotated[float, Field(ge=0, le=0.1)] = 0.02


#: How far an observed pace may move the predicted end: a robot between 4 times faster
#: and 4 times slower than the model; beyond that the observation is not trusted.
_PACE_LIMITS = (0.25, 4.0)
#: How many times the model's budget a move's wait may grow to (the slowest pace trusted).
PACE_LIMIT = _PACE_LIMITS[1]
#: Polls a move's schedule keeps in reserve for the rounding at the dense window's edges.
_RESERVE = 2.0
#: Observed progress used to re-predict the end: not the ramps' first and last few per
#: cent, where a pose's rounding weighs more than the progress.
_PROGRESS_USED = (0.05, 0.95)


class MotionSchedule:
    """When to poll a move next, from its send time, acknowledgement and expected time.

    ``accel_s``: the move's acceleration time by the model (the progress of a move
    follows a trapezoid profile), used to read the robot's pace from the progress a
    poll observes (:meth:`observed`).
    """

    def __init__(
        self, policy: PollPolicy, nominal_s: float, sent_at: float, *, accel_s: float = 0.0
    ) -> None:
        self._policy = policy
        self._nominal = nominal_s
        self._sent_at = sent_at
        self._accel = max(accel_s, 0.0)
        self._acked_at = 0.0
        self._expected = 0.0
        #: No poll spaced beyond the nominal interval from this moment (monotonic s).
        self._earliest = math.inf
        #: Half-width of the dense window around the predicted end; 0: no window.
        self._window = 0.0
        self._early = 0.0
        #: How much earlier than seen the robot may have taken the command (at most a tick).
        self._took_early = 0.0
        self._mid_interval = nominal_s
        self._observations = 0
        self._pace = 1.0
        #: When the move is predicted to end: the model's, then the observed pace's.
        self._predicted = 0.0

    def acknowledged(self, at: float, expected_s: float, *, since: float | None = None) -> None:
        """Anchor the completion window: the move should end at ``at + expected_s``.

        ``since``: the latest moment the command was seen not yet taken (the start of
        the last poll that saw it pending, else the write). The robot took it between
        ``since`` and ``at``, so it may report the end as early as ``since +
        expected_s``: the window opens that much earlier, as far as the polls saved in
        the middle of the move can pay for it.
        """
        p = self._policy
        if not p.predictive or expected_s <= 0:
            return
        # The window also opens earlier by the acknowledgement's uncertainty, at most one
        # dense interval: paid by one of the two polls kept in reserve in _plan.
        doubt = 0.0 if since is None else max(at - since, 0.0)
        self._early = min(doubt, p.dense_interval_s, expected_s / 4)
        self._took_early = min(doubt, p.ack_delay_s)
        self._acked_at, self._expected = at, expected_s
        self._predicted = at + expected_s
        self._earliest = at - self._early + expected_s * p.earliest_end_fraction
        self._plan(at)

    def observed(self, at: float, fraction: float | None) -> None:
        """Re-predict the end from the progress a poll observed.

        Args:
            at: when the poll began (``time.monotonic()``).
            fraction: how much of the move's path the robot had covered (0..1), None
                when the poll could not tell.
        """
        if fraction is None or self._expected <= 0:
            return
        self._observations += 1
        low, high = _PROGRESS_USED
        if not low < fraction < high:
            return
        elapsed = at - self._acked_at
        if elapsed <= 0:
            return
        # A robot k times slower than the model covers the model's profile k times
        # slower: the progress seen at ``elapsed`` is the model's at ``elapsed / k``.
        model_elapsed = _elapsed_at(fraction, self._expected, self._accel)
        if model_elapsed <= 0:
            return
        pace = min(max(elapsed / model_elapsed, _PACE_LIMITS[0]), _PACE_LIMITS[1])
        self._pace = pace
        end = self._acked_at + self._expected * pace
        # A new prediction within a quarter of the window (a dense interval at least)
        # of the last one moves nothing: a pose's rounding, not the robot's pace.
        if abs(end - self._predicted) < max(self._policy.dense_interval_s, self._window / 4):
            return
        self._predicted = end
        # The robot's own pace now says when it could end at the earliest; never later
        # than the model's end, so a robot that speeds up again (a speed override raised
        # mid-move) is still seen within one nominal interval from then on.
        remaining = max(end - at, 0.0)
        self._earliest = min(
            at + remaining * self._policy.earliest_end_fraction,
            self._acked_at + self._expected,
        )
        if not self._window:
            # The polls already spaced paid for a window: it moves with the end.
            self._plan(at)

    def _plan(self, start: float) -> None:
        """Window and middle pace for the move's predicted end, seen from ``start``.

        A move may cost no more polls than nominal polling over the same time: the polls
        saved by spacing the middle (at most to ``max_stretch`` nominal intervals, and
        only before the earliest plausible end) pay for the dense window around the
        end. The widest window they can pay for is taken; two polls are kept in reserve
        for the rounding at the window's edges.
        """
        p = self._policy
        n, d, cap = self._nominal, p.dense_interval_s, self._nominal * p.max_stretch
        end = self._predicted
        span = end - start
        window = min(p.completion_window_s, span / 2)
        while window >= d:
            opens = end - self._early - window / 2
            closes = end + 1.5 * window
            stretchable = max(min(self._earliest, opens) - start, 0.0)
            nominal = max(opens - max(self._earliest, start), 0.0)
            spare = (closes - start) / n - nominal / n - (2 * window + self._early) / d - _RESERVE
            if spare >= stretchable / cap and (spare > 0 or stretchable == 0):
                self._window = window
                if stretchable > 0:
                    self._mid_interval = min(max(stretchable / spare, n), cap)
                return
            window *= 0.8
        self._window = 0.0

    def wants_observation(self, at: float) -> bool:
        """True when the poll at ``at`` should read the pose: a third and two thirds in.

        Only a move with a dense window gains from it: the progress seen on the way
        moves the window to where the robot's own pace puts the end, and the second
        look corrects the first (read early, in the ramp, it weighs a pose's rounding
        and the model's profile more).
        """
        if self._observations >= 2 or not self._window:
            return False
        share = (self._observations + 1) / 3
        return at >= self._acked_at + (self._predicted - self._acked_at) * share

    @property
    def window_s(self) -> float:
        """Half-width of the dense window around the expected end (0 when there is none)."""
        return self._window

    @property
    def pace(self) -> float:
        """How many times slower than the model the robot moves, as last observed (1: as
        predicted or not observed; 0.25..4)."""
        return self._pace

    @property
    def expected_end(self) -> float | None:
        """When the move is predicted to end (monotonic s), None before the acknowledgement."""
        if self._expected <= 0:
            return None
        return self._predicted

    def next_poll(self, now: float, *, acknowledged: bool) -> float:
        """The monotonic time of the next poll (never earlier than ``now``)."""
        p, nominal = self._policy, self._nominal
        if not p.predictive:
            return now + nominal
        if not acknowledged:
            first = self._sent_at + p.ack_delay_s
            if now < first:
                return first
            if now < first + p.ack_window_s:
                return now + p.dense_interval_s
            return now + nominal
        if not self._window:
            if self._expected > 0:
                # No window the budget pays for (a short move): spaced as a longer move's
                # middle until the earliest plausible end, nominal from then on, and
                # shifted so that one poll falls a robot tick after the predicted end,
                # where a robot on the model reports it.
                seen = self._predicted + p.ack_delay_s
                # The robot took the command up to a tick before the poll that saw it
                # taken: a poll that much earlier sees the end when it took it early.
                first = seen - self._took_early if self._took_early > p.dense_interval_s else seen
                if now < self._earliest:
                    # A poll a nominal interval past the earliest end sees an end there.
                    return min(now + nominal * p.max_stretch, self._earliest + nominal, first)
                return self._toward(now, (first, seen))
            return now + nominal
        opens = self._predicted - self._early - self._window / 2
        closes = self._predicted + 1.5 * self._window
        if now < opens:
            if now < self._earliest:
                return min(now + self._mid_interval, self._earliest, opens)
            return min(now + nominal, opens)
        if now < closes:
            return now + p.dense_interval_s
        # A window narrower than a robot tick closes before a robot on the model reports
        # the end at its next tick: one poll there, as for a short move.
        return self._toward(now, (self._predicted + p.ack_delay_s,))

    def _toward(self, now: float, marks: tuple[float, ...]) -> float:
        """The nominal pace, shortened to land on the first of ``marks`` still ahead."""
        step = now + self._nominal
        return next((min(step, mark) for mark in marks if now < mark), step)


def _elapsed_at(fraction: float, total: float, accel_time: float) -> float:
    """When a trapezoid move of ``total`` s has covered ``fraction`` of its path (bisection)."""
    low, high = 0.0, total
    for _ in range(40):
        middle = (low + high) / 2
        if trapezoid_progress(middle, total, accel_time) < fraction:
            low = middle
        else:
            high = middle
    return (low + high) / 2
