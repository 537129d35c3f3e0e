"""ModbusTransport (a blocking caller's link on the default driver) against a scripted slave.

Each request goes to the driver's event loop, is sent there once on the AsyncLink and
answered only under the request's transaction id and from its unit id; after any failure
the link is closed, so a late answer can never be read as a later request's. These are
the guarantees of the raw-socket link the transport used to have, kept on the one link.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
import threading
import time

import pytest

from scripted_slave import (
    Answer,
    SlaveThread,
    answer_in_parts,
    answer_with,
    close_connection,
    frame,
    never_answer,
    registers,
)
from tmmaster import (
    ConfigError,
    ConnectionLostError,
    IllegalAddressError,
    ModbusTransport,
    NotModbusError,
    ResponseTimeoutError,
    TransportError,
    ValueOutOfRangeError,
    _fleet,
)
from tmmaster._fleet import LoopTransport
from tmmaster._registers import RegisterField, Role, Table
from tmmaster._retry import RetryPolicy
from tmmaster._transport import ConnectionState

TIMEOUT_S = 0.2


@pytest.fixture
def slave() -> type[SlaveThread]:
    """The scripted slave."""
    return SlaveThread


def link(port: int, *, attempts: int = 1) -> ModbusTransport:
    """A transport to the scripted slave, retrying reads ``attempts`` times in all."""
    policy = RetryPolicy(
        attempts=attempts, total_time_s=5, initial_backoff_s=0.01, max_backoff_s=0.01
    )
    return ModbusTransport("127.0.0.1", port, timeout=TIMEOUT_S, retry=policy, name="slave")


def test_a_late_answer_is_dropped_not_taken_for_the_next_read(slave: type[SlaveThread]) -> None:
    # The late answer is sent once the read gave up, whatever a loaded machine's timers do.
    gave_up, sent = threading.Event(), threading.Event()

    async def late(tid: int, _request: bytes, writer: asyncio.StreamWriter) -> None:
        await asyncio.to_thread(gave_up.wait, 10)
        writer.write(frame(tid, registers(111, 111)))
        with contextlib.suppress(ConnectionError):  # into the link the master closed
            await writer.drain()
        sent.set()

    with slave([late, answer_with(registers(222, 222))]) as s, link(s.port) as t:
        with pytest.raises(ResponseTimeoutError, match=r"no answer to read holding .* 0\.2 s"):
            t.read_block(Table.HOLDING, 0, 2)
        assert t.state is ConnectionState.DISCONNECTED  # the late answer's stream is gone
        gave_up.set()
        assert sent.wait(10)
        assert t.read_block(Table.HOLDING, 0, 2) == [222, 222]
        assert t.stats.reconnects == 1


@pytest.mark.parametrize(
    ("foreign", "error"),
    [
        # An id never sent on this connection: no Modbus server answers so.
        (answer_with(registers(1, 2), tid_offset=7), NotModbusError),
        (answer_with(registers(1, 2), unit=7), ResponseTimeoutError),
    ],
    ids=["another transaction id", "another unit id"],
)
def test_a_foreign_answer_is_not_taken(
    slave: type[SlaveThread], foreign: Answer, error: type[Exception]
) -> None:
    with slave([foreign]) as s, link(s.port) as t, pytest.raises(error):
        t.read_block(Table.HOLDING, 0, 2)


def test_the_own_answer_after_a_foreign_one_is_taken(slave: type[SlaveThread]) -> None:
    async def foreign_then_own(tid: int, request: bytes, writer: asyncio.StreamWriter) -> None:
        await answer_with(registers(9, 9), tid_offset=3)(tid, request, writer)
        await answer_with(registers(9, 9), unit=5)(tid, request, writer)
        await answer_with(registers(1, 2), after_s=0.02)(tid, request, writer)

    with slave([foreign_then_own]) as s, link(s.port) as t:
        assert t.read_block(Table.HOLDING, 0, 2) == [1, 2]


def test_an_answer_of_another_function_is_an_error(slave: type[SlaveThread]) -> None:
    fc4 = struct.pack(">BB2H", 4, 4, 1, 2)  # input registers, to a holding read
    with slave([answer_with(fc4)]) as s, link(s.port) as t:
        with pytest.raises(TransportError, match="another function"):
            t.read_block(Table.HOLDING, 0, 2)
        assert t.state is ConnectionState.DISCONNECTED


def test_a_short_answer_is_an_error(slave: type[SlaveThread]) -> None:
    with (
        slave([answer_with(registers(1, 2))]) as s,
        link(s.port) as t,
        pytest.raises(ResponseTimeoutError, match="short answer"),
    ):
        t.read_block(Table.HOLDING, 0, 3)


def test_an_exception_answer_is_the_typed_refusal(slave: type[SlaveThread]) -> None:
    with slave([answer_with(bytes([0x83, 2]))]) as s, link(s.port) as t:
        with pytest.raises(IllegalAddressError, match="device refused") as caught:
            t.read_block(Table.HOLDING, 0, 2)
        assert caught.value.code == 2
        assert t.state is ConnectionState.CONNECTED  # the device answered: the link is fine


def test_an_undecodable_answer_is_an_error_and_drops_the_link(slave: type[SlaveThread]) -> None:
    with slave([answer_with(bytes([0x41, 0, 0]))]) as s, link(s.port) as t:
        with pytest.raises(TransportError, match="malformed answer"):
            t.read_block(Table.HOLDING, 0, 2)
        assert t.state is ConnectionState.DISCONNECTED


def test_a_connection_closed_instead_of_an_answer_is_connection_lost(
    slave: type[SlaveThread],
) -> None:
    with slave([close_connection]) as s, link(s.port) as t:
        with pytest.raises(ConnectionLostError, match="connection lost during read holding"):
            t.read_block(Table.HOLDING, 0, 2)
        assert t.state is ConnectionState.DISCONNECTED


def test_a_read_is_retried_on_a_fresh_connection(slave: type[SlaveThread]) -> None:
    with (
        slave([close_connection, answer_with(registers(4, 5))]) as s,
        link(s.port, attempts=2) as t,
    ):
        assert t.read_block(Table.HOLDING, 0, 2) == [4, 5]
        assert t.stats.retries == 1
        assert t.stats.reconnects == 1


def test_a_command_write_is_never_resent(slave: type[SlaveThread]) -> None:
    with slave([never_answer, answer_with(registers(0, 0))]) as s, link(s.port, attempts=3) as t:
        with pytest.raises(ResponseTimeoutError):
            t.write_block(Table.HOLDING, 9000, [1, 2], retry=False)
        assert len(s.server.requests) == 1  # sent once: the slave saw one request
        assert s.server.requests[0][0] == 16


def test_an_answer_in_segments_is_put_together(slave: type[SlaveThread]) -> None:
    coils = bytes([1, 1, 0b101])
    split = answer_in_parts(registers(7, 8), cuts=(3, 9), pause_s=0.01)
    with slave([split, answer_with(coils)]) as s, link(s.port) as t:
        assert t.read_block(Table.HOLDING, 0, 2) == [7, 8]
        assert t.read_block(Table.COIL, 0, 3) == [1, 0, 1]


def test_a_trickled_answer_is_bounded_by_one_deadline(slave: type[SlaveThread]) -> None:
    # Each segment comes within the timeout of the last, the whole answer after 0.4 s:
    # the wait is bounded from the request, not restarted by every segment.
    trickle = answer_in_parts(registers(7, 8), cuts=(2, 4, 6, 8), pause_s=0.1)
    with slave([trickle]) as s, link(s.port) as t, pytest.raises(ResponseTimeoutError):
        t.read_block(Table.HOLDING, 0, 2)


def test_a_silent_device_times_out_and_the_next_read_works(slave: type[SlaveThread]) -> None:
    with slave([never_answer, answer_with(registers(3, 4))]) as s, link(s.port) as t:
        with pytest.raises(ResponseTimeoutError, match=r"within 0\.2 s"):
            t.read_block(Table.HOLDING, 0, 2)
        assert t.read_block(Table.HOLDING, 0, 2) == [3, 4]


def test_an_interrupted_request_drops_the_link(
    slave: type[SlaveThread], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Ctrl-C while an answer is awaited: the answer may still come, so the link goes.
    real_wait = _fleet._Latch.wait
    waits: list[object] = []

    def interrupted(latch: _fleet._Latch[object], bound: float) -> object:
        waits.append(latch)
        if len(waits) > 1:
            return real_wait(latch, bound)  # closing the link afterwards: not interrupted
        deadline = time.monotonic() + 2
        while not s.server.requests and time.monotonic() < deadline:
            time.sleep(0.005)  # the slave has the request (and its connection a handler)
        raise KeyboardInterrupt

    with slave([answer_with(registers(1, 2), after_s=0.05)]) as s, link(s.port) as t:
        with monkeypatch.context() as patch:
            patch.setattr(_fleet._Latch, "wait", interrupted)
            with pytest.raises(KeyboardInterrupt):
                t.read_block(Table.HOLDING, 0, 2)
        assert t.state is ConnectionState.DISCONNECTED


@pytest.mark.parametrize(
    ("table", "address", "words", "error"),
    [
        (Table.HOLDING, 9000, [1, 70000], ValueOutOfRangeError),  # not a 16-bit word
        (Table.HOLDING, 9000, [-1], ValueOutOfRangeError),
        (Table.HOLDING, 9000, [0] * 124, ConfigError),  # FC16 carries at most 123
        (Table.HOLDING, 65535, [1, 2], ConfigError),  # past the last address
        (Table.INPUT, 7000, [1], ConfigError),  # a read-only table
    ],
)
def test_a_write_no_request_can_carry_sends_nothing(
    slave: type[SlaveThread], table: Table, address: int, words: list[int], error: type[Exception]
) -> None:
    with slave([]) as s, link(s.port) as t:
        with pytest.raises(error):
            t.write_block(table, address, words, retry=False)
        assert t.stats.requests == 0
    assert s.server.requests == []


@pytest.mark.parametrize(
    ("table", "address", "count"),
    [
        (Table.HOLDING, 0, 126),
        (Table.COIL, 0, 2001),
        (Table.INPUT, 65530, 7),
        (Table.HOLDING, 0, 0),
    ],
)
def test_a_read_no_request_can_carry_sends_nothing(
    slave: type[SlaveThread], table: Table, address: int, count: int
) -> None:
    with slave([]) as s, link(s.port) as t:
        with pytest.raises(ConfigError, match="one request carries"):
            t.read_block(table, address, count)
        assert t.stats.requests == 0
    assert s.server.requests == []


def two_blocks() -> list[RegisterField]:
    """Two holding fields far apart: two read requests (holding 0 and holding 10)."""
    return [
        RegisterField(
            name="first", role=Role.STATUS, table=Table.HOLDING, address=0, type="uint16"
        ),
        RegisterField(
            name="second", role=Role.STATUS, table=Table.HOLDING, address=10, type="uint16"
        ),
    ]


def test_a_read_of_several_blocks_is_one_hand_over_to_the_loop(
    slave: type[SlaveThread], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Each block is still its own request, sent once, one after the other; the calling
    # thread hands the whole read to the loop once (not once per request).
    script = [answer_with(registers(7)), answer_with(registers(8))]
    with slave(script) as s, link(s.port) as t:
        monkeypatch.setattr(LoopTransport, "_exchange", refuse_per_request_hand_over)
        assert t.read_fields(two_blocks()) == {"first": 7, "second": 8}
        assert t.stats.requests == 2
        assert [pdu[:3] for pdu in s.server.requests] == [bytes([3, 0, 0]), bytes([3, 0, 10])]


def refuse_per_request_hand_over(*_args: object) -> list[int]:
    raise AssertionError("a request was handed to the loop on its own")


def test_a_block_that_fails_is_retried_alone_its_failure_its_first_attempt(
    slave: type[SlaveThread],
) -> None:
    script = [answer_with(registers(7)), close_connection, answer_with(registers(8))]
    with slave(script) as s, link(s.port, attempts=2) as t:
        assert t.read_fields(two_blocks()) == {"first": 7, "second": 8}
        assert t.stats.retries == 1  # the failed chained read was the first of two attempts
        assert t.stats.reconnects == 1
        assert len(s.server.requests) == 3  # the first block is not read again


def test_a_block_that_fails_without_retries_fails_the_read(slave: type[SlaveThread]) -> None:
    script = [answer_with(registers(7)), close_connection, answer_with(registers(8))]
    with slave(script) as s, link(s.port, attempts=1) as t:
        with pytest.raises(ConnectionLostError, match="read holding 10"):
            t.read_fields(two_blocks())
        assert t.stats.retries == 0
        assert len(s.server.requests) == 2


def test_a_link_the_device_closes_between_requests_is_reopened_before_the_next(
    slave: type[SlaveThread],
) -> None:
    # The close is seen when it happens: the next request goes on a fresh connection
    # instead of failing on the dead one (no retry needed, none allowed here).
    async def answer_then_close(tid: int, request: bytes, writer: asyncio.StreamWriter) -> None:
        await answer_with(registers(1, 2))(tid, request, writer)
        writer.close()

    with slave([answer_then_close, answer_with(registers(3, 4))]) as s, link(s.port) as t:
        assert t.read_block(Table.HOLDING, 0, 2) == [1, 2]
        deadline = time.monotonic() + 2
        while t.state is not ConnectionState.DISCONNECTED and time.monotonic() < deadline:
            time.sleep(0.005)
        assert t.state is ConnectionState.DISCONNECTED
        assert t.read_block(Table.HOLDING, 0, 2) == [3, 4]
        assert (t.stats.reconnects, t.stats.retries, t.stats.errors) == (1, 0, 0)
