"""The one pacing loop every wait in tmmaster uses."""

from __future__ import annotations

import math
import threading
import time
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

from ._exceptions import ConfigError, StopRequestedError


class Poller:
    """Paces a wait: one poll per interval on a monotonic clock, every wait interruptible.

    A stop event, when given, ends the wait: :meth:`sleep` raises
    :class:`StopRequestedError` as soon as the event is set (``Event.wait`` wakes at
    once), so a stop request never turns a wait into a busy loop of requests.
    """

    def __init__(self, interval_s: float, stop_event: threading.Event | None = None) -> None:
        if not (isinstance(interval_s, int | float) and math.isfinite(interval_s)) or (
            interval_s <= 0
        ):
            raise ConfigError(f"poll interval must be a finite number > 0 s, got {interval_s!r}")
        self.interval_s = interval_s
        self._next = time.monotonic()
        self._stop = stop_event

    def check(self) -> None:
        """Raise :class:`StopRequestedError` if a stop was requested."""
        if self._stop is not None and self._stop.is_set():
            raise StopRequestedError("stop requested")

    def sleep_until(self, when: float) -> None:
        """Sleep until the monotonic time ``when`` (at once if it has passed)."""
        self.check()
        delay = when - time.monotonic()
        if delay <= 0:
            return
        if self._stop is not None:
            if self._stop.wait(delay):
                raise StopRequestedError("stop requested")
        else:
            time.sleep(delay)

    def sleep(self) -> None:
        """Sleep until the next poll is due (no drift: deadlines advance by the interval)."""
        self._next += self.interval_s
        now = time.monotonic()
        if self._next < now:  # a slow poll: don't try to catch up with a burst of reads
            self._next = now
        self.sleep_until(self._next)


class PollPolicy(BaseModel):
    """Predictive polling of a move: nominal pace, dense where something is expected.

    The master knows when the robot should acknowledge (its next control tick after the
    write) and when the move should end (acknowledgement + expected time). It polls
    densely in a short window at those moments and spaces the polls in between so that
    a move costs no more requests than polling at the nominal interval would.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

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
    #: The next command's checks may use the registers read by the poll that saw the
    #: previous command finished instead of reading them again, if that poll began at most
    #: this long ago (seconds) on the same connection with nothing written since; 0: the
    #: checks always read again. The default is one TM control tick (50 Hz).
    reuse_done_read_s: Annotated[float, Field(ge=0, le=0.1)] = 0.02


class MotionSchedule:
    """When to poll a move next, from its send time, acknowledgement and expected time."""

    def __init__(self, policy: PollPolicy, nominal_s: float, sent_at: float) -> None:
        self._policy = policy
        self._nominal = nominal_s
        self._sent_at = sent_at
        self._end: float | None = None
        self._window = 0.0
        self._early = 0.0
        self._mid_interval = nominal_s

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
        n, d, cap = self._nominal, p.dense_interval_s, self._nominal * p.max_stretch
        # A move may cost no more polls than nominal polling over the same time. The
        # polls saved by stretching the middle (at most to ``cap``) pay for the dense
        # window around the end; this is the widest window they can pay for (two polls
        # are kept in reserve for the rounding at the window's edges).
        denominator = 2 / d - 1 / cap - 1 / n
        if denominator <= 0:
            return
        affordable = (expected_s * (1 / n - 1 / cap) - 2) / denominator
        # The window also opens earlier by the acknowledgement's uncertainty, at most one
        # dense interval: paid by one of the two polls kept in reserve above.
        early = 0.0 if since is None else min(max(at - since, 0.0), d, expected_s / 4)
        window = min(p.completion_window_s, expected_s / 2, affordable)
        if window < d:
            return  # too short a move to afford a dense window: nominal pace
        middle = (expected_s + window) / n - 2 * window / d - 2
        span = expected_s - early - window
        if middle < 1 or span <= 0:
            return
        self._end = at + expected_s
        self._window = window
        self._early = early
        self._mid_interval = min(span / middle, cap)

    @property
    def window_s(self) -> float:
        """Half-width of the dense window around the expected end (0 when there is none)."""
        return self._window if self._end is not None else 0.0

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
        if self._end is None:
            return now + nominal
        start = self._end - self._early - self._window / 2
        stop = self._end + 1.5 * self._window
        if now < start:
            return min(now + self._mid_interval, start)
        if now < stop:
            return now + p.dense_interval_s
        return now + nominal
