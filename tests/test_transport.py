"""Transport on real loopback TCP against an independent pymodbus server."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator

import pytest

from modbus_test_server import TestServer
from tmmaster import ModbusTransport
from tmmaster._exceptions import (
    ConnectError,
    DeviceBusyError,
    DeviceFailureError,
    IllegalAddressError,
    IllegalFunctionError,
    IllegalValueError,
    ModbusExceptionError,
    ResponseTimeoutError,
    TransportError,
    ValueOutOfRangeError,
)
from tmmaster._profiles import robot_profile
from tmmaster._registers import TARGET_FIELDS, Role, Table
from tmmaster._retry import RetryPolicy
from tmmaster._transport import ConnectionState, plan_reads

FAST_RETRY = RetryPolicy(attempts=6, total_time_s=5, initial_backoff_s=0.02, max_backoff_s=0.2)


@pytest.fixture
def server() -> Iterator[TestServer]:
    with TestServer() as srv:
        yield srv


@pytest.fixture
def transport(server: TestServer) -> Iterator[ModbusTransport]:
    t = ModbusTransport("127.0.0.1", server.port, timeout=0.5, retry=FAST_RETRY, name="test")
    t.connect()
    yield t
    t.close()


#: The answer timeout of ``quick_transport``: tests that wait for timeouts use it.
QUICK_TIMEOUT_S = 0.25


@pytest.fixture
def quick_transport(server: TestServer) -> Iterator[ModbusTransport]:
    """Like ``transport``, with a 0.25 s answer timeout (tests that wait for timeouts)."""
    t = ModbusTransport(
        "127.0.0.1", server.port, timeout=QUICK_TIMEOUT_S, retry=FAST_RETRY, name="test"
    )
    t.connect()
    yield t
    t.close()


def test_status_and_pose_are_one_read_request(
    server: TestServer, transport: ModbusTransport
) -> None:
    profile = robot_profile("article")
    fields = [*profile.role(Role.STATUS), *profile.role(Role.POSE)]
    server.knobs.requests.clear()
    values = transport.read_fields(fields, max_gap=profile.max_read_gap)
    assert set(values) == {f.name for f in fields}
    assert [(r.function_code, r.address, r.count) for r in server.knobs.requests] == [(3, 0, 22)]
    assert transport.stats.requests_by_function == {3: 1}


def test_without_gap_merging_blocks_are_separate() -> None:
    profile = robot_profile("article")
    fields = [*profile.role(Role.STATUS), *profile.role(Role.POSE)]
    assert [(b.address, b.count) for b in plan_reads(fields)] == [(0, 2), (3, 1), (16, 6)]


def test_command_block_is_one_fc16_write(server: TestServer, transport: ModbusTransport) -> None:
    profile = robot_profile("article")
    target = [300, -200, 200, 180, 0, 90]
    values = [(profile.field(n), v) for n, v in zip(TARGET_FIELDS, target, strict=True)]
    values += [(profile.field("speed"), 30), (profile.field("command"), 1)]
    server.knobs.requests.clear()
    transport.write_fields(values, retry=False)
    assert len(server.knobs.requests) == 1
    request = server.knobs.requests[0]
    assert (request.function_code, request.address, request.count) == (16, 0x0200, 8)
    assert request.values == [30000, (-20000) & 0xFFFF, 20000, 18000, 0, 9000, 30, 1]
    assert transport.read_fields(profile.role(Role.COMMAND))["target_y"] == -200


def test_out_of_range_value_sends_nothing(server: TestServer, transport: ModbusTransport) -> None:
    profile = robot_profile("article")
    server.knobs.requests.clear()
    with pytest.raises(ValueOutOfRangeError, match="target_x: value 400"):
        transport.write_fields(
            [(profile.field("target_y"), 0), (profile.field("target_x"), 400)], retry=False
        )
    assert server.knobs.requests == []
    assert transport.stats.requests == 0


@pytest.mark.parametrize(
    ("code", "error"),
    [
        (1, IllegalFunctionError),
        (2, IllegalAddressError),
        (3, IllegalValueError),
        (4, DeviceFailureError),
        (6, DeviceBusyError),
        (10, ModbusExceptionError),
    ],
)
def test_exception_responses_become_typed_errors(
    server: TestServer, transport: ModbusTransport, code: int, error: type[ModbusExceptionError]
) -> None:
    server.knobs.exception = (100, 109, code)
    with pytest.raises(error) as info:
        transport.read_block(Table.HOLDING, 105, 2, retry=code != 6)
    assert type(info.value) is error
    assert info.value.code == code
    assert isinstance(info.value, TransportError)
    # Outside the range the device still answers.
    assert transport.read_block(Table.HOLDING, 0, 2) == [0, 0]


@pytest.mark.parametrize("code", [5, 11])
def test_a_gateways_no_answer_is_a_response_timeout(
    server: TestServer, transport: ModbusTransport, code: int
) -> None:
    """Code 5, "acknowledge: accepted, done later", and 11, a gateway's "target device
    failed to respond": the request may still take effect, so it is no refusal but a
    timeout (tests/test_hunt7_exception_answers.py)."""
    server.knobs.exception = (100, 109, code)
    with pytest.raises(ResponseTimeoutError, match=f"Modbus exception {code}"):
        transport.read_block(Table.HOLDING, 105, 2, retry=False)
    assert transport.read_block(Table.HOLDING, 0, 2) == [0, 0]


def test_reconnects_after_the_server_restarts(
    server: TestServer, transport: ModbusTransport
) -> None:
    transport.write_block(Table.HOLDING, 0, [7], retry=True)
    server.stop()
    server.start()  # same port, fresh state
    assert transport.read_block(Table.HOLDING, 0, 1) == [0]
    # The loss is seen when the server closes the link, or by the next request (then
    # retried): either way one reconnect.
    assert transport.stats.reconnects == 1
    assert transport.state is ConnectionState.CONNECTED


def test_a_late_answered_command_write_reaches_the_device_exactly_once(
    server: TestServer, quick_transport: ModbusTransport
) -> None:
    transport = quick_transport
    server.knobs.write_delay_s = 0.5  # answer 0.25 s after the client's 0.25 s timeout
    server.knobs.requests.clear()
    with pytest.raises(ResponseTimeoutError) as info:
        transport.write_block(Table.HOLDING, 0x0207, [1], retry=False)
    assert isinstance(info.value, TimeoutError)
    time.sleep(0.4)  # past the late answer (0.25 s from now): let it and any resend surface
    writes = [r for r in server.knobs.requests if r.function_code == 16]
    assert len(writes) == 1
    assert transport.stats.retries == 0


def test_idempotent_writes_are_retried(
    server: TestServer, quick_transport: ModbusTransport
) -> None:
    transport = quick_transport
    transport.retry = RetryPolicy(attempts=2, initial_backoff_s=0.02)  # one retry shows it
    # The device has answered once: a silence after that is an outage, and retried (a
    # link that never answered is not: test_not_modbus.py).
    transport.read_block(Table.HOLDING, 0, 1)
    # Each answer comes 0.2 s after its attempt's 0.25 s timeout; the first one lands
    # while the retry waits for its own.
    server.knobs.write_delay_s = 0.45
    with pytest.raises(ResponseTimeoutError):
        transport.write_block(Table.HOLDING, 0, [1], retry=True)
    # Each of our attempts is one request: never multiplied by pymodbus's own retries.
    writes = [r for r in server.knobs.requests if r.function_code == 16]
    assert len(writes) == transport.stats.retries + 1 >= 2


def test_connect_failure_is_a_connect_error() -> None:
    from modbus_test_server import free_port

    t = ModbusTransport(
        "127.0.0.1", free_port(), timeout=0.2, retry=RetryPolicy(attempts=2, initial_backoff_s=0.01)
    )
    with pytest.raises(ConnectError) as info:
        t.connect()
    assert isinstance(info.value, ConnectionError)
    # Nothing listens there: a first connection refused is not retried (test_addresses.py).
    assert t.stats.retries == 0
    t.close()


def test_close_twice_and_refuse_after_close(transport: ModbusTransport) -> None:
    transport.close()
    transport.close()
    assert transport.state is ConnectionState.CLOSED
    with pytest.raises(ConnectError, match="closed"):
        transport.read_block(Table.HOLDING, 0, 1)


def test_counts_bytes_per_modbus_framing(server: TestServer, transport: ModbusTransport) -> None:
    transport.read_block(Table.HOLDING, 0, 10)
    # Request: 7-byte MBAP + 5-byte PDU. Response: MBAP + fc + byte count + 20 data bytes.
    assert transport.stats.bytes_sent == 12
    assert transport.stats.bytes_received == 7 + 2 + 20


def test_an_fc2_answer_with_zero_data_bytes_is_a_transport_error() -> None:
    # A device (or a proxy) that answers FC2 with a byte count of 0: never a bare ValueError.
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    port = listener.getsockname()[1]

    def answer_empty() -> None:
        conn, _ = listener.accept()
        with conn:
            request = conn.recv(260)
            conn.sendall(request[:2] + b"\x00\x00\x00\x03" + request[6:7] + b"\x02\x00")
            conn.recv(260)  # until the master drops the link

    server = threading.Thread(target=answer_empty)
    server.start()
    try:
        link = ModbusTransport("127.0.0.1", port, timeout=0.5, retry=RetryPolicy(attempts=1))
        with link, pytest.raises(TransportError):
            link.read_block(Table.DISCRETE_INPUT, 7201, 1)
    finally:
        server.join(5)
        listener.close()
