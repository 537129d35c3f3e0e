"""The one retry policy: exponential backoff with jitter, bounded by attempts and time.

Only transient transport failures are retried (a connection lost or not opened in
time, a response timeout, a busy device). A failure that cannot succeed on a later
attempt is raised at once (its ``retryable`` is False): a closed link; on a link never
connected yet a refused connection or a host name that does not resolve (the transport
decides, :meth:`Transport._connect_once`); a device that answers in something other
than Modbus TCP (:class:`NotModbusError`); and a response timeout on a link whose device
has never answered (:func:`~tmmaster._transport.no_answer_error`). pymodbus's own retries are
switched off by the transport, so retries never multiply and no write is resent behind
the caller's back.

The defaults ride out an outage of about 5 s (a switch rebooting, the robot's Modbus
server restarting): the backoff grows to 1.5 s, so the attempts are spread over the
whole 10 s budget instead of being spent in the first second. A sleep between
attempts ends at once when the caller's stop event is set.
"""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Callable
from typing import Annotated, TypeVar

from pydantic import BaseModel, ConfigDict, Field

from ._exceptions import (
    ConnectError,
    ConnectionLostError,
    DeviceBusyError,
    ResponseTimeoutError,
    StopRequestedError,
    TransportError,
)
from ._logging import get_logger

T = TypeVar("T")

#: Failures worth another attempt: the request may succeed once the link is back.
TRANSIENT_ERRORS: tuple[type[TransportError], ...] = (
    ConnectError,
    ConnectionLostError,
    ResponseTimeoutError,
    DeviceBusyError,
)

_log = get_logger("tmmaster.transport")


def is_transient(error: BaseException) -> bool:
    """Whether another attempt may succeed: a transient error not marked ``retryable`` False."""
    return isinstance(error, TRANSIENT_ERRORS) and getattr(error, "retryable", True)


class RetryPolicy(BaseModel):
    """How often and how long to retry a request that failed transiently."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: Total attempts, the first one included (1 = never retry).
    attempts: Annotated[int, Field(ge=1, le=100)] = 12
    #: No attempt starts once this much time has passed since the first one, in seconds.
    total_time_s: Annotated[float, Field(gt=0)] = 10.0
    #: The wait before the second attempt, s; it doubles for each further one.
    initial_backoff_s: Annotated[float, Field(ge=0)] = 0.1
    #: The longest wait between two attempts, s.
    max_backoff_s: Annotated[float, Field(ge=0)] = 1.5
    #: Up to this much random time is added to each wait, s.
    jitter_s: Annotated[float, Field(ge=0)] = 0.1

    def call(
        self,
        operation: str,
        fn: Callable[[], T],
        *,
        on_retry: Callable[[BaseException], None] | None = None,
        interrupt: threading.Event | None = None,
        until: Callable[[], float | None] | None = None,
    ) -> T:
        """Run ``fn``, retrying transient errors; the last error propagates unchanged.

        With ``interrupt``, a sleep between attempts ends as soon as the event is set and
        :class:`StopRequestedError` is raised instead of another attempt.

        Args:
            operation: What is tried, for the log's retry events.
            fn: One attempt.
            on_retry: Called with each failure that is retried.
            interrupt: Ends the waits between attempts when set.
            until: Read before each wait: a ``time.monotonic()`` past which no attempt
                starts (a clean-up's deadline, set while a request retries), or None.

        Returns:
            What ``fn`` returned.

        Raises:
            StopRequestedError: ``interrupt`` was set during a wait.
        """
        # The first attempt runs outside tenacity: the retry machinery is entered only
        # after a transient failure, so a healthy link pays nothing for it.
        started = time.monotonic()
        try:
            return fn()
        except TRANSIENT_ERRORS as exc:
            # A closed link, a first connection refused or unresolved: no attempt can help.
            if self.attempts == 1 or not is_transient(exc):
                raise
            first_error: BaseException = exc
        import tenacity  # here, not at import: only a transient failure needs it

        def retrying_after(error: BaseException | None, attempt: int, delay_s: float) -> None:
            """Attempt ``attempt`` failed with ``error``: say so, count it, wait ``delay_s``."""
            _log.warning(
                "transport.retry",
                operation=operation,
                attempt=attempt,
                delay_s=round(delay_s, 3),
                error=str(error),
                error_type=type(error).__name__,
            )
            if on_retry is not None and error is not None:
                on_retry(error)

        def before_sleep(state: tenacity.RetryCallState) -> None:
            error = state.outcome.exception() if state.outcome else None
            retrying_after(error, state.attempt_number + 1, state.upcoming_sleep)

        def past_bounds(wait_s: float) -> bool:
            """Whether an attempt after ``wait_s`` would start past a bound."""
            at = time.monotonic() + wait_s
            limit = None if until is None else until()
            return at - started >= self.total_time_s or (limit is not None and at >= limit)

        first_wait_s = self.initial_backoff_s + random.uniform(0, self.jitter_s)
        if past_bounds(first_wait_s):
            raise first_error
        retrying_after(first_error, 1, first_wait_s)
        _sleeper(interrupt)(first_wait_s)
        retrying = tenacity.Retrying(
            # Attempts 2..n: the same bounds as one policy, counted from the first attempt.
            stop=lambda state: (
                state.attempt_number >= self.attempts - 1 or past_bounds(state.upcoming_sleep)
            ),
            # Composed from the two long-stable strategies: wait_exponential_jitter's
            # parameters were renamed in tenacity 9.2. Doubling continues from attempt 2.
            wait=tenacity.wait_exponential(
                multiplier=self.initial_backoff_s * 2, max=self.max_backoff_s
            )
            + tenacity.wait_random(0, self.jitter_s),
            retry=tenacity.retry_if_exception(is_transient),
            before_sleep=before_sleep,
            sleep=_sleeper(interrupt),
            reraise=True,
        )
        return retrying(fn)


def _sleeper(interrupt: threading.Event | None) -> Callable[[float], None]:
    """A sleep between attempts that a stop request cuts short."""
    if interrupt is None:
        return time.sleep

    def sleep(seconds: float) -> None:
        if interrupt.wait(seconds):
            raise StopRequestedError("stop requested while waiting to retry a request")

    return sleep


NO_RETRY = RetryPolicy(attempts=1)
