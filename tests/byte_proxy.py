"""A Modbus TCP proxy that plays faults on bytes, not frames: the network between frames.

:class:`fault_proxy.FaultProxy` forwards and withholds whole MBAP frames. Real networks
(gateways, Wi-Fi bridges, serial-to-TCP converters) deliver a frame in pieces, and a
connection can break between any two of its bytes. A :class:`Piece` rule, on the
``nth`` request (``on="request"``) or answer (``on="answer"``, matched by its request's
function code and address) that matches, does one of:

``split``  send the frame in segments cut at these byte offsets (negative: from the
           end), each after the previous one and a pause: ``pause_s``, or until
           ``release`` is set, or (``until_client``) until the client does its next
           thing on that connection: sends a byte or closes it. TCP keeps order: the
           frames after it wait too. A tail held this way is still delivered after the
           client closed (a TCP stack sends what it queued before its FIN).
``cut``    send this many bytes of the frame (negative: from the end), then close the
           connection both ways: the robot gets a partial request, or the master a
           partial answer, and then the end of the stream.
``glue``   (answers) send the answer in one segment with a copy of it (a gateway that
           retransmits what it sent), so that two frames reach the master in one read.

The proxy logs what it saw: every request with its connection's number (``seen``), and
the connections the client closed (``client_closed``), so a test can tell a request sent
on a fresh connection from one on the connection a fault hit.
"""

from __future__ import annotations

import contextlib
import itertools
import select
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Literal

from fault_proxy import _ADDRESSED, _frames, counted_match


@dataclass
class Piece:
    """On the ``nth`` matching request or answer: split it, cut the link inside it, or glue."""

    on: Literal["request", "answer"]
    action: Literal["split", "cut", "glue"]
    function_code: int | None = None
    address: int | None = None
    nth: int = 1
    times: int = 1
    #: ``split``: the byte offsets where segments start (negative: from the end).
    at: tuple[int, ...] = ()
    #: ``cut``: the bytes delivered before the connection closes (negative: from the end).
    keep: int = 0
    #: ``split``: the pause before each later segment, s (when neither below is given).
    pause_s: float = 0.0
    #: ``split``: each later segment waits for this event instead.
    release: threading.Event | None = None
    #: ``split``: each later segment waits until the client sends a byte or closes.
    until_client: bool = False
    #: Set once the rule has played (the first segment sent, or the cut made).
    played: threading.Event = field(default_factory=threading.Event)
    _seen: int = field(default=0, repr=False)

    def matches(self, on: str, function_code: int, address: int | None) -> bool:
        """Count a matching request or answer; True when this one is to be played."""
        return on == self.on and counted_match(self, function_code, address)


@dataclass(frozen=True)
class Request:
    """A request the proxy received: on which connection (0, 1, ...), what, what it played."""

    connection: int
    function_code: int
    address: int | None
    action: str


def _key(frame: bytes) -> tuple[int, int, int | None]:
    tid = struct.unpack(">H", frame[0:2])[0]
    pdu = frame[7:]
    function_code = pdu[0] if pdu else 0
    address = None
    if function_code in _ADDRESSED and len(pdu) >= 3:
        address = struct.unpack(">H", pdu[1:3])[0]
    return tid, function_code, address


def _offset(frame: bytes, at: int) -> int:
    return max(0, min(len(frame), at if at >= 0 else len(frame) + at))


class _Conn:
    """One client connection and its own upstream connection, each way a thread."""

    def __init__(self, proxy: BytePiecesProxy, client: socket.socket, number: int) -> None:
        self.proxy, self.client, self.number = proxy, client, number
        self.upstream = socket.create_connection((proxy.target_host, proxy.target_port), timeout=2)
        self.upstream.settimeout(None)
        #: The (function code, address) of each request by transaction id, for its answer.
        self.asked: dict[int, tuple[int, int | None]] = {}
        self.client_closed = threading.Event()
        #: Requests received on this connection so far.
        self.requests = 0
        self.threads = [
            threading.Thread(target=self._requests, name="byteproxy-c2u", daemon=True),
            threading.Thread(target=self._answers, name="byteproxy-u2c", daemon=True),
        ]
        for thread in self.threads:
            thread.start()

    def _requests(self) -> None:
        for frame in _frames(self.client):
            tid, function_code, address = _key(frame)
            self.asked[tid] = (function_code, address)
            self.requests += 1
            rule = self.proxy._match("request", function_code, address)
            self.proxy._note(self, function_code, address, rule)
            if not self._play(rule, frame, self.upstream, self.client):
                break
        self.client_closed.set()
        self.proxy._closed_by_client(self.number)
        self._shut(self.client)
        self._shut(self.upstream, how=socket.SHUT_WR)  # the robot sees the FIN after the bytes

    def _answers(self) -> None:
        for frame in _frames(self.upstream):
            tid = struct.unpack(">H", frame[0:2])[0]
            function_code, address = self.asked.get(tid, (-1, None))
            rule = self.proxy._match("answer", function_code, address)
            if not self._play(rule, frame, self.client, self.upstream):
                break
        self._shut(self.client)

    def _play(
        self, rule: Piece | None, frame: bytes, to: socket.socket, other: socket.socket
    ) -> bool:
        """Send ``frame`` to ``to`` as ``rule`` says; False when the connection is cut."""
        if rule is None:
            return self._send(to, frame)
        if rule.action == "glue":
            rule.played.set()
            return self._send(to, frame + frame)
        if rule.action == "cut":
            self._send(to, frame[: _offset(frame, rule.keep)])
            rule.played.set()
            self._shut(to)
            self._shut(other)
            return False
        cuts = sorted({_offset(frame, at) for at in rule.at} - {0, len(frame)})
        bounds = [0, *cuts, len(frame)]
        for index, (start, end) in enumerate(itertools.pairwise(bounds)):
            if index and not self._pause(rule):
                return False
            self._send(to, frame[start:end])
            if not index:
                rule.played.set()
        return True

    def _pause(self, rule: Piece) -> bool:
        """Wait before a later segment; False when the proxy closes first."""
        stopping = self.proxy._stopping
        if rule.until_client:
            before = self.requests
            while not stopping.is_set():
                if self.client_closed.is_set() or self.requests > before:
                    return True
                with contextlib.suppress(OSError, ValueError):
                    ready, _, _ = select.select([self.client], [], [], 0.005)
                    if ready:
                        return True
            return False
        if rule.release is None:
            return not stopping.wait(rule.pause_s)
        while not rule.release.wait(0.005):
            if stopping.is_set():
                return False
        return True

    @staticmethod
    def _send(to: socket.socket, data: bytes) -> bool:
        try:
            to.sendall(data)
        except OSError:
            return False
        return True

    @staticmethod
    def _shut(sock: socket.socket, how: int = socket.SHUT_RDWR) -> None:
        with contextlib.suppress(OSError):
            sock.shutdown(how)

    def close(self) -> None:
        self._shut(self.client)
        self._shut(self.upstream)
        for thread in self.threads:
            thread.join(timeout=5)
        self.client.close()
        self.upstream.close()


class BytePiecesProxy:
    """A Modbus TCP proxy on 127.0.0.1 in front of ``target_port`` that plays byte faults."""

    def __init__(self, target_port: int, *, target_host: str = "127.0.0.1") -> None:
        self.target_host, self.target_port = target_host, target_port
        self._lock = threading.Lock()
        self._rules: list[Piece] = []
        self._conns: list[_Conn] = []
        self._seen: list[Request] = []
        self._client_closed: list[int] = []
        self._stopping = threading.Event()
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind(("127.0.0.1", 0))
        self._listener.listen(16)
        self.port: int = self._listener.getsockname()[1]
        self._acceptor = threading.Thread(target=self._accept, name="byteproxy-accept")
        self._acceptor.daemon = True
        self._acceptor.start()

    def add(self, rule: Piece) -> Piece:
        """Arm a rule; returns it (``played`` says when it has)."""
        with self._lock:
            self._rules.append(rule)
        return rule

    @property
    def seen(self) -> list[Request]:
        """Every request received, in order, with its connection's number."""
        with self._lock:
            return list(self._seen)

    @property
    def client_closed(self) -> list[int]:
        """The connections the client closed (or that a cut closed), by number."""
        with self._lock:
            return list(self._client_closed)

    def _match(self, on: str, function_code: int, address: int | None) -> Piece | None:
        with self._lock:
            return next((r for r in self._rules if r.matches(on, function_code, address)), None)

    def _note(
        self, conn: _Conn, function_code: int, address: int | None, rule: Piece | None
    ) -> None:
        action = "pass" if rule is None else rule.action
        with self._lock:
            self._seen.append(Request(conn.number, function_code, address, action))

    def _closed_by_client(self, number: int) -> None:
        with self._lock:
            self._client_closed.append(number)

    def _accept(self) -> None:
        while not self._stopping.is_set():
            ready, _, _ = select.select([self._listener], [], [], 0.02)
            if not ready:
                continue
            try:
                client, _ = self._listener.accept()
            except OSError:
                continue
            try:
                with self._lock:
                    number = len(self._conns)
                conn = _Conn(self, client, number)
            except OSError:
                client.close()
                continue
            with self._lock:
                self._conns.append(conn)

    def wait_closed(self, number: int, timeout: float = 5.0) -> bool:
        """Wait until the client closed connection ``number``; True if it did."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if number in self.client_closed:
                return True
            time.sleep(0.005)
        return False

    def close(self) -> None:
        """Stop, close every socket and join every thread (safe twice)."""
        if self._stopping.is_set():
            return
        self._stopping.set()
        self._acceptor.join(timeout=5)
        self._listener.close()
        with self._lock:
            conns, self._conns = self._conns, []
        for conn in conns:
            conn.close()

    def __enter__(self) -> BytePiecesProxy:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
