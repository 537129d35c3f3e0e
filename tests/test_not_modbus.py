"""A port that is not a Modbus TCP server: said at once, in one line, never retried.

A loopback listener answers each request as a test says: an HTTP error page, garbage,
a frame with a wrong protocol id or an impossible length, an answer under a transaction
id that was never sent, or nothing at all. The first five are a ``NotModbusError``
naming host and port within one request timeout; a listener that accepts and never
answers fails on the first request's timeout, without the retry policy's storm. Nothing
of pymodbus's logging reaches stderr.
"""

from __future__ import annotations

import asyncio
import selectors
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

import pytest

from tmmaster import (
    ConnectError,
    ModbusTransport,
    NotModbusError,
    ResponseTimeoutError,
    RetryPolicy,
    Robot,
    TimeoutPolicy,
    TransportError,
)
from tmmaster._registers import Table
from tmmaster._transport import AsyncLink
from tmmaster.pickplace.__main__ import EXIT_CONNECTION, main

#: The request timeout of every link here, s; each failure must come within BOUND_S.
TIMEOUT_S = 0.3
BOUND_S = 1.5

#: What a listener sends for one request (its raw bytes); None: nothing.
Reply = Callable[[bytes], bytes | None]


def input_answer(request: bytes, *, tid: int | None = None, protocol: int = 0) -> bytes:
    """A well-formed FC4 answer of zeros to an FC4 ``request`` (or one of its header fields)."""
    request_tid, _, _, unit, _, _, count = struct.unpack(">HHHBBHH", request[:12])
    pdu = bytes([4, 2 * count]) + bytes(2 * count)
    return (
        struct.pack(">HHHB", request_tid if tid is None else tid, protocol, len(pdu) + 1, unit)
        + pdu
    )


def http(_request: bytes) -> bytes:
    return b"HTTP/1.0 400 Bad Request\r\n\r\n"


def garbage(_request: bytes) -> bytes:
    return bytes(range(0x21, 0x7F)) * 2


def wrong_protocol(request: bytes) -> bytes:
    return input_answer(request, protocol=5)


def impossible_length(request: bytes) -> bytes:
    tid = struct.unpack(">H", request[:2])[0]
    return struct.pack(">HHHB", tid, 0, 0, 1) + bytes([4, 2, 0, 0])


def another_transaction(request: bytes) -> bytes:
    tid = struct.unpack(">H", request[:2])[0]
    return input_answer(request, tid=(tid + 100) % 0x10000)


def silent(_request: bytes) -> None:
    return None


def silent_at_7001(request: bytes) -> bytes | None:
    """Answers every read but those of address 7001 (it takes them and says nothing)."""
    return None if struct.unpack(">H", request[8:10])[0] == 7001 else input_answer(request)


class Listener:
    """A loopback TCP server on a thread of its own; it answers each request by ``reply``.

    ``close_after`` closes a connection after each reply (an HTTP/1.0 server). Every
    connection is closed, and the thread joined, on exit.
    """

    def __init__(self, reply: Reply, *, close_after: bool = False) -> None:
        self.reply = reply
        self.close_after = close_after
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port: int = self.server.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="not-modbus-listener")

    def __enter__(self) -> Listener:
        self._thread.start()
        return self

    def __exit__(
        self,
        _type: type[BaseException] | None,
        _value: BaseException | None,
        _traceback: TracebackType | None,
    ) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def _serve(self) -> None:
        with selectors.DefaultSelector() as selector:
            selector.register(self.server, selectors.EVENT_READ)
            try:
                while not self._stop.is_set():
                    for key, _ in selector.select(timeout=0.02):
                        self._ready(selector, key.fileobj)  # type: ignore[arg-type]
            finally:
                for key in list(selector.get_map().values()):
                    selector.unregister(key.fileobj)
                    key.fileobj.close()  # type: ignore[union-attr]

    def _ready(self, selector: selectors.BaseSelector, sock: socket.socket) -> None:
        if sock is self.server:
            connection, _ = sock.accept()
            selector.register(connection, selectors.EVENT_READ)
            return
        request = sock.recv(4096)
        answer = self.reply(request) if request else None
        if answer is not None:
            sock.sendall(answer)
        if not request or (answer is not None and self.close_after):
            selector.unregister(sock)
            sock.close()


def link(port: int) -> ModbusTransport:
    """A transport with the default retry policy (10 s budget) and a short request timeout."""
    return ModbusTransport("127.0.0.1", port, timeout=TIMEOUT_S, retry=RetryPolicy(), name="robot")


NOT_MODBUS = [
    pytest.param(http, "protocol id 21584", id="http"),
    pytest.param(garbage, "protocol id", id="garbage"),
    pytest.param(wrong_protocol, "protocol id 5", id="wrong protocol id"),
    pytest.param(impossible_length, "length", id="impossible length"),
    pytest.param(another_transaction, "transaction id", id="transaction id never sent"),
]


@pytest.mark.parametrize(("reply", "reason"), NOT_MODBUS)
def test_an_answer_that_is_not_modbus_is_said_at_once_and_not_retried(
    reply: Reply,
    reason: str,
    capfd: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    with Listener(reply, close_after=reply is http) as server, link(server.port) as t:
        started = time.monotonic()
        with pytest.raises(NotModbusError) as caught:
            t.read_block(Table.INPUT, 7001, 36)
        elapsed = time.monotonic() - started
        assert t.stats.retries == 0
    message = str(caught.value)
    assert f"127.0.0.1:{server.port}" in message
    assert "not a Modbus TCP server" in message
    assert reason in message
    assert (caught.value.host, caught.value.port) == ("127.0.0.1", server.port)
    assert isinstance(caught.value, ConnectError | TransportError)
    assert caught.value.retryable is False
    assert elapsed < BOUND_S  # the bound is the feature: one request timeout, not 10 s
    assert not [r for r in caplog.records if r.name.startswith("pymodbus")]
    assert "pymodbus" not in capfd.readouterr().err.lower()


def test_a_robot_on_an_http_port_is_not_modbus_within_one_request_timeout(
    capfd: pytest.CaptureFixture[str],
) -> None:
    with Listener(http, close_after=True) as server:
        robot = Robot("127.0.0.1", server.port, timeouts=TimeoutPolicy(request_s=TIMEOUT_S))
        started = time.monotonic()
        with pytest.raises(NotModbusError, match=f"127.0.0.1:{server.port} is not a Modbus"):
            robot.connect()
        assert time.monotonic() - started < BOUND_S
    err = capfd.readouterr().err
    assert "Invalid Modbus protocol id" not in err
    assert "Repeating" not in err


def test_a_silent_listener_fails_on_the_first_request_and_a_link_that_answered_retries() -> None:
    # The rule: a link that has never received an answer is not retried past its first
    # request's timeout (nothing there speaks Modbus to us). Once it has answered, a
    # timeout is an outage and the retry policy rides it out as before.
    policy = RetryPolicy(attempts=2, total_time_s=5, initial_backoff_s=0.01, max_backoff_s=0.01)
    with (
        Listener(silent_at_7001) as server,
        ModbusTransport("127.0.0.1", server.port, timeout=TIMEOUT_S, retry=policy) as t,
    ):
        started = time.monotonic()
        with pytest.raises(ResponseTimeoutError) as caught:
            t.read_block(Table.INPUT, 7001, 36)
        assert time.monotonic() - started < BOUND_S
        assert t.stats.retries == 0
        assert caught.value.retryable is False  # type: ignore[attr-defined]
        message = str(caught.value)
        assert f"127.0.0.1:{server.port}" in message
        assert "never answered" in message
        assert "within 0.3 s" in message

        assert t.read_block(Table.INPUT, 7100, 2) == [0, 0]  # it answers other reads
        with pytest.raises(ResponseTimeoutError, match=r"within 0\.3 s$"):
            t.read_block(Table.INPUT, 7001, 36)
        assert t.stats.retries == 1  # retried: the link has answered before


def test_a_robot_on_a_silent_listener_fails_within_its_first_request_timeout() -> None:
    with Listener(silent) as server:
        robot = Robot("127.0.0.1", server.port, timeouts=TimeoutPolicy(request_s=TIMEOUT_S))
        started = time.monotonic()
        with pytest.raises(ResponseTimeoutError, match="never answered"):
            robot.connect()
        assert time.monotonic() - started < BOUND_S
        assert robot.stats.retries == 0


def test_an_async_link_says_not_modbus() -> None:
    async def body(port: int) -> None:
        link = AsyncLink("127.0.0.1", port, device_id=1, timeout=TIMEOUT_S, name="robot")
        await link.connect()
        try:
            with pytest.raises(NotModbusError, match=f"127.0.0.1:{port} is not a Modbus"):
                await link.read_block(Table.INPUT, 7001, 36, "read input 7001+36")
        finally:
            link.close()

    with Listener(http) as server:
        asyncio.run(body(server.port))


def pickplace(port: int, tmp_path: Path) -> int:
    config = tmp_path / "cell.toml"
    config.write_text(f"[timeouts]\nrequest_s = {TIMEOUT_S}\n")
    return main(["--host", "127.0.0.1", "--port", str(port), "--config", str(config)])


def test_pickplace_on_an_http_port_says_not_modbus_in_one_line(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    with Listener(http, close_after=True) as server:
        started = time.monotonic()
        assert pickplace(server.port, tmp_path) == EXIT_CONNECTION
        assert time.monotonic() - started < BOUND_S
    lines = capfd.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"pickplace: robot at 127.0.0.1:{server.port} is not a Modbus TCP")
    assert lines[0].endswith(f"[exit {EXIT_CONNECTION}]")


def test_pickplace_on_a_silent_listener_fails_in_one_line_without_retries(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    with Listener(silent) as server:
        started = time.monotonic()
        assert pickplace(server.port, tmp_path) == EXIT_CONNECTION
        assert time.monotonic() - started < BOUND_S
    lines = capfd.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines  # no transport.retry warnings
    assert f"127.0.0.1:{server.port}" in lines[0]
    assert "never answered" in lines[0]


def test_pymodbus_logging_reaches_no_stderr_unless_asked() -> None:
    # Python prints a record no handler takes on stderr (logging.lastResort): pymodbus
    # logs under "pymodbus" without a handler of its own. pytest's own handlers hide
    # that in-process, so a fresh interpreter shows it.
    probe = (
        "import logging, tmmaster._transport; "
        "from pymodbus.logging import Log; "
        "Log.error('Invalid Modbus protocol id: {}', 21584); "
        "logging.basicConfig(); "
        "Log.error('asked for: {}', 1)"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=30, check=True
    )
    assert "Invalid Modbus protocol id" not in done.stderr
    assert "asked for: 1" in done.stderr  # an application that configures logging sees it
