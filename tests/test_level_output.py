"""A level output's watch for a late frame of ours is bounded, whatever the output reads.

``LevelOutput`` is what ``robot.io.set_do`` and the article's gripper register write
through. After an unanswered write of one value, a write of the other value reads the
output back until the late frame has landed and been undone, or until the retry
policy's total time has passed. An output that never reads the value written (another
writer, a device that resets it) must not keep the call, or its writes, going past
that horizon.
"""

from __future__ import annotations

import itertools
import threading
import time
from types import SimpleNamespace
from typing import Any, cast

import pytest

from tmmaster import ResponseTimeoutError, RetryPolicy, StopRequestedError
from tmmaster._codec import Value
from tmmaster._io import LevelOutput
from tmmaster._registers import Table
from tmmaster._transport import Transport

HORIZON_S = 0.3


class FakeLink:
    """A link whose first write goes unanswered and whose output always reads ``found``."""

    #: Each fake is a robot of its own: none shares another's doubts.
    _robots = itertools.count()

    def __init__(self, found: Value, stop: threading.Event | None = None) -> None:
        self.endpoint = ("fake", next(self._robots), 1)
        self.retry = RetryPolicy(attempts=2, total_time_s=HORIZON_S, initial_backoff_s=0)
        self.stats = SimpleNamespace(retries=0)
        self.interrupt = stop
        self.found = found
        self.sent: list[Value] = []
        self.reads = 0

    def write_block(self, table: Table, address: int, words: list[int], **_: Any) -> None:
        self.sent.append(bool(words[0]))
        if len(self.sent) == 1:
            raise ResponseTimeoutError("no answer")  # its frame may still land

    def read_block(self, table: Table, address: int, count: int, **_: Any) -> list[int]:
        self.reads += 1
        return [int(self.found)]


def output_reading(found: Value, *, stop: threading.Event | None = None) -> tuple[LevelOutput, Any]:
    """An output whose first write goes unanswered and which then always reads ``found``."""
    link = FakeLink(found, stop)
    late: list[tuple[Value, Value]] = []
    output = LevelOutput(
        "test DO 0",
        Table.COIL,
        0,
        cast(Transport, link),
        lambda attempt: attempt(),
        lambda *, found, wanted: late.append((found, wanted)),
    )
    link.late = late  # type: ignore[attr-defined]
    return output, link


def test_a_watch_against_an_output_that_never_holds_the_value_ends_at_its_horizon() -> None:
    output, link = output_reading(False)
    output.set(False)  # unanswered, then retried and answered: False may still land
    finished = threading.Event()

    def close() -> None:
        output.set(True)  # the output keeps reading False
        finished.set()

    started = time.monotonic()
    worker = threading.Thread(target=close, daemon=True)
    worker.start()
    assert finished.wait(HORIZON_S + 5.0), "the watch went on past its horizon"
    worker.join()
    assert time.monotonic() - started < HORIZON_S + 5.0
    # Every read that found False was answered by one write of True, each paced by the
    # watch's interval: a bounded number, not a busy loop.
    writes_of_true = link.sent.count(True)
    assert 1 <= writes_of_true <= HORIZON_S / 0.02 + 3
    assert len(link.late) == writes_of_true - 1


def test_a_watch_ends_at_a_stop_request_saying_what_may_still_land() -> None:
    stop = threading.Event()
    output, _link = output_reading(False, stop=stop)
    output.set(False)
    threading.Timer(0.05, stop.set).start()
    with pytest.raises(StopRequestedError, match="could still land"):
        output.set(True)


def test_without_a_doubt_a_write_reads_nothing_back() -> None:
    link = FakeLink(True)
    link.sent.append(True)  # the first write was answered
    output = LevelOutput(
        "test DO 1", Table.COIL, 1, cast(Transport, link), lambda a: a(), lambda **_: None
    )
    output.set(True)
    output.set(False)
    assert link.reads == 0
