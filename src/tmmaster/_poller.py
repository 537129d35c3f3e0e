"""The one pacing loop every wait in tmmaster uses."""

from __future__ import annotations

import math
import threading
import time

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

    def sleep(self) -> None:
        """Sleep until the next poll is due (no drift: deadlines advance by the interval)."""
        self.check()
        self._next += self.interval_s
        delay = self._next - time.monotonic()
        if delay < 0:  # a slow poll: don't try to catch up with a burst of reads
            self._next = time.monotonic()
            return
        if self._stop is not None:
            if self._stop.wait(delay):
                raise StopRequestedError("stop requested")
        else:
            time.sleep(delay)
