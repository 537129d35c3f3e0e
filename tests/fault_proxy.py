"""A fault-injecting Modbus TCP proxy: the hostile network between a master and a slave.

The proxy listens on 127.0.0.1, opens one upstream connection to the slave for every
client connection, parses MBAP frames, and plays scripted faults on matching requests:

``delay``         hold the request ``delay_s`` before forwarding it (and everything after
                  it on that connection: TCP keeps order)
``hold``          forward the request ``delay_s`` later *even if the client has given up and
                  closed the connection meanwhile* (a frame stuck in the network); with
                  ``release`` (an event), when the test sets it instead
``drop_request``  never forward the request (the master times out)
``drop_answer``   forward the request, swallow the answer (executed, but the master
                  cannot know)
``close_after``   forward the request, then close the client's connection instead of
                  relaying the answer
``duplicate_answer`` forward the request, relay its answer twice (a buggy gateway)
``duplicate_request`` forward the request, and a copy of it ``delay_s`` later or when
                  ``release`` is set (a gateway that retries a request on its own)
``stale_answer``  forward the request, relay the answer the previous identical request
                  (function, address, count) got, under this request's transaction id: a
                  gateway serving a cache one poll behind (the first is relayed as is)
``foreign_tid``   forward the request, relay its answer under a transaction id never sent
``foreign_unit``  forward the request, relay its answer from another unit id
``delay_answer``  forward the request at once, relay its answer ``delay_s`` later, or when
                  ``release`` is set (and every answer after it: TCP keeps order)
``outage``        (``FaultProxy.outage``) close every connection and refuse new ones for a
                  while, like a slave whose server restarts

With ``exception`` (a Modbus exception code) a rule answers the request with that
exception, as a Modbus TCP gateway does: ``drop_request`` answers it instead of
forwarding (not executed); ``drop_answer`` forwards it and answers the exception in
place of the real answer (executed, e.g. code 4 after the device applied the write);
``delay_answer`` relays the exception in place of the answer, late; ``hold`` answers
the exception at once and still delivers the frame later (a gateway
that gave up waiting, code 11, while its frame to the device is stuck on its way).
``hold`` with ``answer_now`` answers a write as done at once and delivers it later (a
store-and-forward gateway that acknowledges writes itself).

Everything runs on the proxy's own threads; :meth:`FaultProxy.close` joins them and
closes every socket, so the suite's leak check holds.
"""

from __future__ import annotations

import contextlib
import select
import socket
import struct
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, Literal

Action = Literal[
    "delay",
    "hold",
    "drop_request",
    "drop_answer",
    "close_after",
    "duplicate_answer",
    "delay_answer",
    "foreign_tid",
    "foreign_unit",
    "duplicate_request",
    "stale_answer",
]

#: Function codes whose PDU starts with a starting address.
_ADDRESSED = {1, 2, 3, 4, 5, 6, 15, 16, 23}


@dataclass
class Rule:
    """Play ``action`` on the ``nth`` request matching ``function_code`` / ``address``."""

    action: Action
    function_code: int | None = None
    address: int | None = None
    nth: int = 1
    delay_s: float = 0.0
    #: How many times the rule fires (after ``nth - 1`` matching requests went through).
    times: int = 1
    #: ``hold`` only: deliver when this is set (not after ``delay_s``), so that a test
    #: lets the frame land at a point of its own scenario rather than at a time.
    release: threading.Event | None = None
    #: ``drop_request``, ``drop_answer``, ``hold``: answer the client with this Modbus
    #: exception code (see the module's docstring).
    exception: int | None = None
    #: ``hold`` of a write: answer it at once as done (a store-and-forward gateway that
    #: acknowledges writes itself), while the frame is still held.
    answer_now: bool = False
    _seen: int = field(default=0, repr=False)

    def matches(self, function_code: int, address: int | None) -> bool:
        """Count a matching request; True when this one is to be faulted."""
        return counted_match(self, function_code, address)


def counted_match(rule: Any, function_code: int, address: int | None) -> bool:
    """Whether ``rule`` (its ``function_code``, ``address``, ``nth``, ``times`` and its
    count ``_seen``) plays on this request: a matching one is counted, and the ``nth``
    and later ones play, ``times`` in all."""
    if rule.times <= 0:
        return False
    if rule.function_code is not None and function_code != rule.function_code:
        return False
    if rule.address is not None and address != rule.address:
        return False
    rule._seen += 1
    if rule._seen < rule.nth:
        return False
    rule.times -= 1
    return True


@dataclass(frozen=True)
class Seen:
    """One request as the proxy saw it."""

    time: float
    function_code: int
    address: int | None
    action: str


def _recv_exact(sock: socket.socket, count: int) -> bytes | None:
    data = b""
    while len(data) < count:
        try:
            chunk = sock.recv(count - len(data))
        except OSError:
            return None
        if not chunk:
            return None
        data += chunk
    return data


def _frames(sock: socket.socket) -> Iterator[bytes]:
    """Whole MBAP frames from ``sock`` until it closes."""
    while True:
        header = _recv_exact(sock, 7)
        if header is None:
            return
        (length,) = struct.unpack(">H", header[4:6])
        body = _recv_exact(sock, max(length - 1, 0))
        if body is None:
            return
        yield header + body


def exception_answer(request: bytes, code: int) -> bytes:
    """The exception answer (function code | 0x80, ``code``) to ``request``."""
    tid, _protocol, _length, unit, function_code = struct.unpack(">HHHBB", request[:8])
    return struct.pack(">HHHBBB", tid, 0, 3, unit, function_code | 0x80, code)


def write_answer(request: bytes) -> bytes:
    """The normal answer to a write request (FC 5, 6, 15, 16): its first four fields."""
    tid, _protocol, _length, unit = struct.unpack(">HHHB", request[:7])
    return struct.pack(">HHHB", tid, 0, 6, unit) + request[7:12]


def _rewritten(answer: bytes, action: str) -> bytes:
    """``answer`` under a transaction id 0x7000 away (``foreign_tid``) or from unit id
    ``unit + 1`` (``foreign_unit``)."""
    tid, _protocol, _length, unit = struct.unpack(">HHHB", answer[:7])
    if action == "foreign_tid":
        return struct.pack(">H", (tid + 0x7000) % 0x10000 or 1) + answer[2:]
    return answer[:6] + bytes([(unit + 1) % 256]) + answer[7:]


def _parse(frame: bytes) -> tuple[int, int, int | None]:
    """(transaction id, function code, address or None) of a request frame."""
    tid = struct.unpack(">H", frame[0:2])[0]
    pdu = frame[7:]
    function_code = pdu[0] if pdu else 0
    address = (
        struct.unpack(">H", pdu[1:3])[0] if function_code in _ADDRESSED and len(pdu) >= 3 else None
    )
    return tid, function_code, address


class _Link:
    """One client connection and its upstream connection."""

    def __init__(self, proxy: FaultProxy, client: socket.socket) -> None:
        self.proxy = proxy
        self.client = client
        self.upstream = socket.create_connection((proxy.target_host, proxy.target_port), timeout=2)
        self.upstream.settimeout(None)
        self._send_lock = threading.Lock()
        self._client_lock = threading.Lock()
        #: Answers not relayed, by transaction id: what the client gets instead (or nothing).
        self._swallow: dict[int, bytes | None] = {}
        self._duplicate: set[int] = set()
        #: Answers relayed with their header rewritten, by transaction id: the action.
        self._foreign: dict[int, str] = {}
        #: stale_answer: the request's key by transaction id, and each key's last answer.
        self._stale: dict[int, bytes] = {}
        self._cache: dict[bytes, bytes] = {}
        #: Answers relayed late, by transaction id: (delay, release, what is relayed instead).
        self._late: dict[int, tuple[float, threading.Event | None, bytes | None]] = {}
        self._close_on_answer: set[int] = set()
        self._holds = 0
        self._holds_done = threading.Condition()
        pumps = [
            threading.Thread(target=self._client_to_upstream, name="proxy-c2u", daemon=True),
            threading.Thread(target=self._upstream_to_client, name="proxy-u2c", daemon=True),
        ]
        self.threads = list(pumps)  # hold threads are appended as they start
        for pump in pumps:
            pump.start()

    def _forward(self, frame: bytes) -> None:
        with self._send_lock, contextlib.suppress(OSError):
            self.upstream.sendall(frame)

    def _to_client(self, frame: bytes) -> None:
        with self._client_lock, contextlib.suppress(OSError):
            self.client.sendall(frame)

    def _client_to_upstream(self) -> None:
        for frame in _frames(self.client):
            tid, function_code, address = _parse(frame)
            rule = self.proxy._match(function_code, address)
            action = rule.action if rule is not None else "pass"
            refusal = None
            if rule is not None and rule.exception is not None:
                refusal = exception_answer(frame, rule.exception)
            self.proxy._note(function_code, address, action)
            if rule is None:
                self._forward(frame)
            elif rule.action == "delay":
                if self.proxy._stopping.wait(rule.delay_s):
                    break
                self._forward(frame)
            elif rule.action == "hold":
                if refusal is not None or rule.answer_now:
                    self._to_client(refusal or write_answer(frame))
                self._hold(frame, rule.delay_s, rule.release)
            elif rule.action == "drop_request":
                if refusal is not None:
                    self._to_client(refusal)
                continue
            elif rule.action == "drop_answer":
                self._swallow[tid] = refusal
                self._forward(frame)
            elif rule.action == "delay_answer":
                self._late[tid] = (rule.delay_s, rule.release, refusal)
                self._forward(frame)
            elif rule.action in ("foreign_tid", "foreign_unit"):
                self._foreign[tid] = rule.action
                self._forward(frame)
            elif rule.action == "stale_answer":
                self._stale[tid] = frame[7:]  # function, address, count (and values)
                self._forward(frame)
            elif rule.action == "duplicate_request":
                self._forward(frame)
                self._hold(frame, rule.delay_s, rule.release)  # the copy's answer is relayed too
            elif rule.action == "duplicate_answer":
                self._duplicate.add(tid)
                self._forward(frame)
            else:  # close_after
                self._close_on_answer.add(tid)
                self._forward(frame)
        self._shut_client()
        # Keep the upstream connection while a held frame still has to go through it.
        with self._holds_done:
            self._holds_done.wait_for(lambda: self._holds == 0 or self.proxy._stopping.is_set())
        with contextlib.suppress(OSError):
            self.upstream.shutdown(socket.SHUT_RDWR)

    @property
    def holds(self) -> int:
        """Held frames not delivered yet."""
        with self._holds_done:
            return self._holds

    def _hold(self, frame: bytes, delay_s: float, release: threading.Event | None) -> None:
        with self._holds_done:
            self._holds += 1

        def deliver() -> None:
            if self._wait(delay_s, release):
                self._forward(frame)
            with self._holds_done:
                self._holds -= 1
                self._holds_done.notify_all()

        thread = threading.Thread(target=deliver, name="proxy-hold", daemon=True)
        self.threads.append(thread)
        thread.start()

    def _upstream_to_client(self) -> None:
        for frame in _frames(self.upstream):
            tid = struct.unpack(">H", frame[0:2])[0]
            if tid in self._late:
                delay_s, release, refusal = self._late.pop(tid)
                if not self._wait(delay_s, release):
                    break
                frame = frame if refusal is None else refusal
            if tid in self._swallow:
                if (refusal := self._swallow.pop(tid)) is not None:
                    self._to_client(refusal)
                continue
            if tid in self._close_on_answer:
                self._close_on_answer.discard(tid)
                self._shut_client()
                continue
            if tid in self._foreign:
                frame = _rewritten(frame, self._foreign.pop(tid))
            if tid in self._stale:
                key = self._stale.pop(tid)
                cached, self._cache[key] = self._cache.get(key), frame
                frame = frame if cached is None else frame[:2] + cached[2:]
            self._to_client(frame)
            if tid in self._duplicate:
                self._duplicate.discard(tid)
                self._to_client(frame)
        self._shut_client()

    def _wait(self, delay_s: float, release: threading.Event | None) -> bool:
        """Wait ``delay_s`` or for ``release``; False when the proxy closes first."""
        if release is None:
            return not self.proxy._stopping.wait(delay_s)
        while not release.wait(0.005):
            if self.proxy._stopping.is_set():
                return False
        return True

    def _shut_client(self) -> None:
        with contextlib.suppress(OSError):
            self.client.shutdown(socket.SHUT_RDWR)

    def close(self) -> None:
        self._shut_client()
        with self._holds_done:
            self._holds_done.notify_all()
        with contextlib.suppress(OSError):
            self.upstream.shutdown(socket.SHUT_RDWR)
        for t in list(self.threads):
            t.join(timeout=5)
        self.client.close()
        self.upstream.close()


class FaultProxy:
    """A Modbus TCP proxy on 127.0.0.1 in front of ``target_port`` that plays faults."""

    def __init__(self, target_port: int, *, target_host: str = "127.0.0.1") -> None:
        self.target_host = target_host
        self.target_port = target_port
        self._lock = threading.Lock()
        self._rules: list[Rule] = []
        self._links: list[_Link] = []
        self._seen: list[Seen] = []
        self._stopping = threading.Event()
        self._refusing_until = 0.0
        self._listener = self._listen(0)
        self.port: int = self._listener.getsockname()[1]
        self._acceptor = threading.Thread(
            target=self._accept_loop, name="proxy-accept", daemon=True
        )
        self._acceptor.start()

    # -- scripting -----------------------------------------------------------------------

    def add(self, rule: Rule) -> Rule:
        """Arm a fault rule; returns it (its ``times`` says whether it has fired)."""
        with self._lock:
            self._rules.append(rule)
        return rule

    def clear(self) -> None:
        """Disarm every rule."""
        with self._lock:
            self._rules.clear()

    def outage(self, seconds: float) -> None:
        """Close every connection now and refuse new ones for ``seconds``."""
        with self._lock:
            self._refusing_until = time.monotonic() + seconds
            links, self._links = self._links, []
        for link in links:
            link.close()

    @property
    def accepting(self) -> bool:
        """True once an ``outage`` is over: a connection made now is taken, not refused."""
        with self._lock:
            return time.monotonic() >= self._refusing_until

    def wait_held(self, timeout: float = 5.0) -> None:
        """Block until every held frame has been delivered (or ``timeout`` passed)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                links = list(self._links)
            if all(link.holds == 0 for link in links):
                return
            time.sleep(0.01)

    def played(self, action: Action) -> bool:
        """True once a request received has met a rule with ``action`` (e.g. "hold")."""
        return any(s.action == action for s in self.seen)

    @property
    def seen(self) -> list[Seen]:
        """Every request the proxy received, with the action it played."""
        with self._lock:
            return list(self._seen)

    # -- internals -----------------------------------------------------------------------

    def _listen(self, port: int) -> socket.socket:
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", port))
        listener.listen(16)
        return listener

    def _match(self, function_code: int, address: int | None) -> Rule | None:
        with self._lock:
            for rule in self._rules:
                if rule.matches(function_code, address):
                    return rule
        return None

    def _note(self, function_code: int, address: int | None, action: str) -> None:
        with self._lock:
            self._seen.append(Seen(time.monotonic(), function_code, address, action))

    def _accept_loop(self) -> None:
        while not self._stopping.is_set():
            ready, _, _ = select.select([self._listener], [], [], 0.02)
            if not ready:
                continue
            try:
                client, _ = self._listener.accept()
            except OSError:
                continue
            if time.monotonic() < self._refusing_until:
                # Refused: a reset, as from a host whose server is down.
                client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                client.close()
                continue
            try:
                link = _Link(self, client)
            except OSError:
                client.close()
                continue
            with self._lock:
                self._links.append(link)

    def close(self) -> None:
        """Stop forwarding, close every socket and join every thread (safe twice)."""
        if self._stopping.is_set():
            return
        self._stopping.set()
        self._acceptor.join(timeout=5)
        self._listener.close()
        with self._lock:
            links, self._links = self._links, []
        for link in links:
            link.close()

    def __enter__(self) -> FaultProxy:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
