"""The one pacing loop every wait in tmmaster uses."""

from __future__ import annotations

import threading
import time

from ._exceptions import ConfigError


class Poller:
    """Paces a wait: one poll per interval on a monotonic clock, every wait bounded."""

    def __init__(self, interval_s: float, stop_event: threading.Event | None = None) -> None:
        if interval_s <= 0:
            raise ConfigError(f"poll interval must be > 0 s, got {interval_s}")
        self.interval_s = interval_s
        self._next = time.monotonic()
        self._stop = stop_event

    def sleep(self) -> None:
        """Sleep until the next poll is due (no drift: deadlines advance by the interval)."""
        self._next += self.interval_s
        delay = self._next - time.monotonic()
        if delay < 0:  # a slow poll: don't try to catch up with a burst of reads
            self._next = time.monotonic()
            return
        if self._stop is not None:
            self._stop.wait(delay)
        else:
            time.sleep(delay)
