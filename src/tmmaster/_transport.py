"""The one module that speaks Modbus client-side: frames, answers, one link.

:class:`AsyncLink` is the one Modbus TCP link: an asyncio protocol on a driver's event
loop (``_fleet.py``: a :class:`~tmmaster.Fleet`'s, or the process's default driver's),
whose request frames are packed here, as are the common answers (reads, FC16 writes),
the others decoded by pymodbus' socket framer and PDU classes. Each request is
sent once and answered only under its own transaction id and from its unit id; after
any failure the link is closed, so a late answer can never be read as a later
request's. :class:`Transport` is what every robot-side transport shares: state,
counters, field plans and the :class:`RetryPolicy`.

Reads, and writes the caller declares idempotent, retry and reconnect. A write that
triggers a command is sent exactly once: if it fails, the caller must read the
device's state back to learn whether the command arrived. Nothing is retried after an
answer that is not Modbus TCP (:class:`NotModbusError`, checked on each frame's header
before pymodbus' framer sees it), nor a timeout on a link whose device has never
answered anything (:func:`no_answer_error`).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import ipaddress
import socket
import struct
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from enum import StrEnum
from typing import Any, Self, TypeVar, cast

from pymodbus import ModbusException
from pymodbus.framer import FramerSocket
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU

from ._address import is_ip_address
from ._codec import Decoder, Value, decoder, encoder
from ._error_root import TMMasterError
from ._exceptions import (
    MODBUS_EXCEPTIONS,
    ConfigError,
    ConnectError,
    ConnectionLostError,
    ConnectRefusedError,
    HostNotFoundError,
    ModbusExceptionError,
    NotModbusError,
    ResponseTimeoutError,
    TransportClosedError,
    TransportError,
    ValueOutOfRangeError,
)
from ._logging import get_logger
from ._registers import Access, RegisterField, Table
from ._retry import NO_RETRY, RetryPolicy

T = TypeVar("T")

_log = get_logger("tmmaster.transport")

#: Protocol limits of one request (Modbus application protocol spec, 6.1 - 6.12).
MAX_READ_REGISTERS = 125
MAX_READ_BITS = 2000
MAX_WRITE_REGISTERS = 123
MAX_WRITE_BITS = 1968

#: The read function code of each table.
READ_FUNCTION: dict[Table, int] = {
    Table.COIL: 1,
    Table.DISCRETE_INPUT: 2,
    Table.HOLDING: 3,
    Table.INPUT: 4,
}


def request_limit(table: Table, *, write: bool) -> int:
    """The most registers (or bits) of ``table`` one read or write request may carry."""
    if write:
        return MAX_WRITE_BITS if table.is_bit else MAX_WRITE_REGISTERS
    return MAX_READ_BITS if table.is_bit else MAX_READ_REGISTERS


def check_request(table: Table, address: int, count: int, *, write: bool) -> None:
    """Refuse, before any I/O, a block one Modbus request cannot carry."""
    limit = request_limit(table, write=write)
    if not (address >= 0 and 1 <= count <= limit and address + count <= 0x10000):
        unit = "bits" if table.is_bit else "registers"
        raise ConfigError(
            f"{table.value} {address}+{count}: one request carries 1-{limit} {unit}"
            " within addresses 0-65535"
        )


def describe_read(table: Table, address: int, count: int) -> str:
    """How a read is named in errors and logs, e.g. ``read holding 9100+6``."""
    return f"read {table.value} {address}+{count}"


#: Modbus function codes that write (FC05, FC06, FC15, FC16).
_WRITE_CODES = frozenset({5, 6, 15, 16})

#: How long a request of the robot's thread lets a waiting heartbeat go first, s at most
#: (see Transport.let_in).
_LET_IN_S = 0.05


class ConnectionState(StrEnum):
    """Where a transport's connection stands."""

    NEW = "new"
    CONNECTED = "connected"
    DISCONNECTED = "disconnected"  # lost; the next request reconnects
    CLOSED = "closed"  # closed by the user; further requests are refused


@dataclass
class TransportStats:
    """Counters of one transport, for run reports and benchmarks."""

    #: Requests sent (retries included).
    requests: int = 0
    #: Retries of failed requests and connects.
    retries: int = 0
    #: Connections opened again after a lost link.
    reconnects: int = 0
    #: Failed requests (exception answers included).
    errors: int = 0
    #: Bytes sent (Modbus TCP frames).
    bytes_sent: int = 0
    #: Bytes received.
    bytes_received: int = 0
    #: Requests by Modbus function code.
    requests_by_function: dict[int, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """A plain-dict copy, for JSON reports.

        Returns:
            The counters by name (``requests_by_function`` sorted by code).
        """
        by_function = dict(sorted(self.requests_by_function.items()))
        return {**asdict(self), "requests_by_function": by_function}


@dataclass(frozen=True)
class Block:
    """A contiguous address range of one table, read or written in one request."""

    table: Table
    address: int
    count: int
    fields: tuple[RegisterField, ...]


@dataclass(frozen=True)
class ReadPlan:
    """The blocks to read for a set of fields, with each field's decoder: built once."""

    blocks: tuple[Block, ...]
    #: Per block: (field name, offset in the block, decoder) for every field in it.
    slots: tuple[tuple[tuple[str, int, Decoder], ...], ...]

    @classmethod
    def build(cls, fields: Iterable[RegisterField], *, max_gap: int = 0) -> ReadPlan:
        """Plan the reads of ``fields`` (see :func:`plan_reads`)."""
        blocks = tuple(plan_reads(fields, max_gap=max_gap))
        slots = tuple(
            tuple((f.name, f.address - block.address, decoder(f)) for f in block.fields)
            for block in blocks
        )
        return cls(blocks, slots)

    def decode(self, answers: Sequence[Sequence[int]]) -> dict[str, Value]:
        """Each field's value by name, from the words read for each block in turn."""
        return {
            name: decode(words, offset)
            for words, slots in zip(answers, self.slots, strict=True)
            for name, offset, decode in slots
        }


def plan_reads(fields: Iterable[RegisterField], *, max_gap: int = 0) -> list[Block]:
    """Group fields into as few contiguous blocks as the protocol limits allow."""
    blocks: list[Block] = []
    by_table: dict[Table, list[RegisterField]] = {}
    for f in fields:
        by_table.setdefault(f.table, []).append(f)
    for table in Table:
        ordered = sorted(by_table.get(table, []), key=lambda f: f.address)
        limit = request_limit(table, write=False)
        current: list[RegisterField] = []
        for f in ordered:
            if current:
                start = current[0].address
                end = max(c.end for c in current)
                if f.address - end - 1 <= max_gap and f.end - start + 1 <= limit:
                    current.append(f)
                    continue
                blocks.append(_block(table, current))
            current = [f]
        if current:
            blocks.append(_block(table, current))
    return blocks


def _block(table: Table, fields: list[RegisterField]) -> Block:
    start = fields[0].address
    return Block(table, start, max(f.end for f in fields) - start + 1, tuple(fields))


#: A field with the words its value encodes to.
Encoded = tuple[RegisterField, list[int]]


def encode_writes(values: Iterable[tuple[RegisterField, Value]]) -> list[Encoded]:
    """Encode every value (each field must be writable); raises before anything is sent."""
    encoded: list[Encoded] = []
    for f, value in values:
        if f.access is Access.READ:  # not f.access.writable, without a call per field
            raise ConfigError(f"{f.name}: field is read-only ({f.table.value} {f.address})")
        encoded.append((f, encoder(f)(value)))
    return encoded


#: Write layouts by the identities of their fields, in the order given: the blocks and,
#: for each, the positions of its fields' words. Each entry holds its fields, so their
#: ids cannot be reused while it lives. Bounded: ad-hoc writes are not kept forever.
_WRITE_LAYOUTS: dict[
    tuple[int, ...], tuple[tuple[RegisterField, ...], list[tuple[Block, tuple[int, ...]]]]
] = {}
_MAX_WRITE_LAYOUTS = 256


def group_writes(encoded: Sequence[Encoded]) -> list[tuple[Block, list[int]]]:
    """Group already encoded fields into as few write blocks as the protocol allows.

    The grouping depends on the fields alone (table, address, width): it is worked out
    once per field sequence and reused, each block's words taken in the same order.
    """
    fields = tuple(f for f, _ in encoded)
    key = tuple(map(id, fields))
    entry = _WRITE_LAYOUTS.get(key)
    if entry is None or entry[0] != fields:
        # Each field's "words" are its position: the blocks list the positions they take.
        grouped = _group_writes([(f, [i]) for i, f in enumerate(fields)])
        layout = [(block, tuple(positions)) for block, positions in grouped]
        if len(_WRITE_LAYOUTS) >= _MAX_WRITE_LAYOUTS:
            _WRITE_LAYOUTS.clear()
        _WRITE_LAYOUTS[key] = entry = (fields, layout)
    return [(block, [w for i in positions for w in encoded[i][1]]) for block, positions in entry[1]]


def _group_writes(encoded: Sequence[Encoded]) -> list[tuple[Block, list[int]]]:
    # Table is a StrEnum: its members order as their values, without a .value lookup.
    groups: list[list[Encoded]] = []
    for f, words in sorted(encoded, key=lambda item: (item[0].table, item[0].address)):
        first, last = (groups[-1][0][0], groups[-1][-1][0]) if groups else (f, f)
        fits = f.end - first.address + 1 <= request_limit(f.table, write=True)
        if not groups or last.table is not f.table or f.address != last.end + 1 or not fits:
            groups.append([])
        groups[-1].append((f, words))
    return [
        (_block(g[0][0].table, [f for f, _ in g]), [w for _, ws in g for w in ws]) for g in groups
    ]


class Transport(ABC):
    """A device link, what the layers above (channels, grippers, the robot) talk to.

    :class:`~tmmaster.ModbusTransport` (Modbus TCP, an :class:`AsyncLink` on a driver's
    event loop) is the default; ``tmmaster.sim.MemoryTransport`` talks to an in-process
    simulator without sockets. This class holds everything but the link: state,
    counters, retries, read plans and encoding, and so every rule about when a request
    may be retried, once. A subclass supplies the link: :meth:`_open_link`,
    :meth:`_close_link`, :meth:`_link_open` and :meth:`_exchange` (one request, failures
    already mapped to :class:`TransportError` subclasses).

    Args:
        host: The device's address.
        port: Its Modbus TCP port.
        device_id: The Modbus unit id of every request.
        timeout: Bound of one request, s.
        retry: How failed requests and connects are retried; None: ``RetryPolicy()``.
        name: The link's name in messages and logs.
    """

    def __init__(
        self,
        host: str,
        port: int,
        *,
        device_id: int,
        timeout: float,
        retry: RetryPolicy | None,
        name: str,
    ) -> None:
        #: The device's address.
        self.host = host
        #: Its Modbus TCP port.
        self.port = port
        #: The Modbus unit id of every request.
        self.device_id = device_id
        #: Bound of one request, s.
        self.timeout = timeout
        #: How failed requests and connects are retried.
        self.retry = retry if retry is not None else RetryPolicy()
        #: The link's name in messages and logs.
        self.name = name
        #: When set, sleeps between retry attempts of interruptible requests end at once.
        self.interrupt: threading.Event | None = None
        #: Request, retry, reconnect and byte counters.
        self.stats = TransportStats()
        # Not the counters above (a user may reset those): see the epoch property.
        self._epoch = 0
        self._state = ConnectionState.NEW
        self._lock = threading.RLock()
        # Cleared while a heartbeat waits for the link: the robot's thread lets it in
        # before its next request. Locks are not fair: a thread requesting back to back
        # held the lock at every look, no beat got in, and the robot program expired the
        # live master's command.
        self._free_turn = threading.Event()
        self._free_turn.set()
        # Set by bound_retries(): no retry past this time (a clean-up under a budget).
        self._retry_deadline: float | None = None
        # Read plans by the identity of the fields asked for: a status poll reads the same
        # field objects every time, so its plan is computed once. The plan holds the
        # fields, so their ids cannot be reused while the entry lives.
        self._plans: dict[tuple[int, tuple[int, ...]], tuple[ReadPlan, tuple[object, ...]]] = {}
        self._tuple_plans: dict[tuple[int, int], tuple[ReadPlan, object]] = {}
        # Per read block (table, address, count): its description and function code.
        self._reads: dict[tuple[Table, int, int], tuple[str, int]] = {}
        self._log = _log.bind(device=name, host=host, port=port, device_id=device_id)

    @functools.cached_property
    def endpoint(self) -> tuple[str, int, int]:
        """The device as the process keys what it owes it: (address, port, unit id).

        The address the host resolves to, the same however it is spelled ("localhost",
        "127.0.0.1" and "::1" are all this machine's 127.0.0.1; a name, the lowest of its
        addresses, IPv4 first, whatever order the resolver gives them in): what one Robot
        left unsettled on the robot (an owed Stop, a late output frame, a gripper's late
        stop) is then honoured by a Robot that names it otherwise. A host that does not
        resolve is its own key.
        """
        with contextlib.suppress(OSError, UnicodeError, ValueError):
            ip = ipaddress.ip_address(min(socket.getaddrinfo(self.host, self.port))[4][0])
            return "127.0.0.1" if ip.is_loopback else str(ip), self.port, self.device_id
        return self.host, self.port, self.device_id

    # -- the link (subclasses) ----------------------------------------------------

    @abstractmethod
    def _link_open(self) -> bool:
        """True while the link can carry a request."""

    @abstractmethod
    def _open_link(self) -> None:
        """Open the link once; raise :class:`ConnectError` when it cannot be opened."""

    @abstractmethod
    def _close_link(self) -> None:
        """Close the link (safe when already closed)."""

    @abstractmethod
    def _exchange(
        self, what: str, function_code: int, address: int, count: int, values: list[int] | None
    ) -> list[int]:
        """Send one request once and return the words (bits as 0/1) of its answer.

        Raise :class:`ConnectionLostError`, :class:`ResponseTimeoutError`,
        :class:`ModbusExceptionError` (and subclasses) or :class:`TransportError`.
        """

    # -- connection --------------------------------------------------------

    @property
    def state(self) -> ConnectionState:
        """Current connection state."""
        return self._state

    @property
    def epoch(self) -> int:
        """Changes whenever the link may have changed or missed a register: a write sent,
        a failed request, a retry, a connect, a close. Two equal epochs: not one of these
        in between (what a read taken at the first one may be trusted for)."""
        return self._epoch

    def connect(self) -> None:
        """Open the connection, retrying per the policy; raises :class:`ConnectError`."""
        self._run(f"connect {self.name}", self._connect_once, retry=True, interruptible=True)

    def close(self) -> None:
        """Close the connection; safe to call more than once."""
        with self._lock:
            if self._state is ConnectionState.CLOSED:
                return
            self._close_link()
            self._epoch += 1
            self._state = ConnectionState.CLOSED
            self._log.debug("transport.closed")

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _refuse_if_closed(self) -> None:
        if self._state is ConnectionState.CLOSED:
            raise TransportClosedError(f"{self.name}: transport is closed")

    def _connect_once(self) -> None:
        if self._link_open():
            return
        # Lost (a subclass's state may say so of a link the device closed between two
        # requests): opening it again is a reconnect, an outage the retry policy rides out.
        reconnect = self.state is ConnectionState.DISCONNECTED
        try:
            self._open_link()
        except (ConnectRefusedError, HostNotFoundError) as exc:
            # Never connected yet: nothing listens there, or no such name; a later
            # attempt would fail the same way. Once the link has been up, the same
            # failure is an outage (a server restarting, a resolver away): retried.
            if not reconnect:
                exc.retryable = False
            raise
        self._epoch += 1
        if reconnect:
            self.stats.reconnects += 1
            self._log.info("transport.reconnected")
        else:
            self._log.debug("transport.connected")
        self._state = ConnectionState.CONNECTED

    def _drop(self) -> None:
        # After a failure the stream may still carry a late answer to the failed
        # request; a fresh connection guarantees it can't be taken for the next one.
        self._close_link()
        if self._state is not ConnectionState.CLOSED:
            self._state = ConnectionState.DISCONNECTED

    def _on_retry(self, _error: BaseException) -> None:
        self._epoch += 1
        self.stats.retries += 1

    # -- raw requests --------------------------------------------------------

    def _execute(
        self, what: str, function_code: int, address: int, count: int, values: list[int] | None
    ) -> list[int]:
        """Send one request once; count it, and drop the link after a link failure."""
        self._refuse_if_closed()
        self._connect_once()
        self._count_request(function_code)
        try:
            return self._exchange(what, function_code, address, count, values)
        except BaseException as exc:
            self._request_failed(exc)
            raise

    def _count_request(self, function_code: int) -> None:
        """Count a request about to be sent (every link's requests are counted here)."""
        if function_code in _WRITE_CODES:
            self._epoch += 1
        self.stats.requests += 1
        by_function = self.stats.requests_by_function
        by_function[function_code] = by_function.get(function_code, 0) + 1

    def _request_failed(self, error: BaseException) -> None:
        """After a request failed: count it, and drop the link unless the device answered."""
        self._epoch += 1
        if isinstance(error, ModbusExceptionError):
            self.stats.errors += 1  # the device answered: the link is fine
            return
        if isinstance(error, TransportError):
            self.stats.errors += 1
        # A link failure, or an interruption mid-request (KeyboardInterrupt, a cancelled
        # task): the request's answer may still come on this stream.
        self._drop()

    def write_when_free(
        self, address: int, words: list[int], *, wait_s: float
    ) -> BaseException | bool | None:
        """Write holding registers in one FC16 request, sent once, once the link is free.

        For a write that is no command (the master's heartbeat): it never reconnects a
        dropped link (the robot's thread does), is never retried, and is not counted as
        one of the link's requests. The lock is waited for at most ``wait_s``: a robot
        polling densely holds it most of the time, and a write that only tried it missed
        beat after beat.

        Args:
            address: The first holding register.
            words: The words.
            wait_s: How long to wait for the link's lock, s.

        Returns:
            None when answered; True when the link stayed busy or is down (nothing
            sent); the error when the write failed.
        """
        with self.let_in():
            if not self._lock.acquire(timeout=wait_s):
                return True
        try:
            if self.state is not ConnectionState.CONNECTED or not self._link_open():
                return True
            what = f"write holding {address}+{len(words)} (heartbeat)"
            try:
                self._exchange(what, 16, address, len(words), words)
            except TMMasterError as exc:
                self._request_failed(exc)
                return exc
            return None
        finally:
            self._lock.release()

    def _yield_turn(self, interruptible: bool) -> None:
        """Before a request of the robot's thread: let a waiting heartbeat go first.

        Bounded (50 ms): a request nested in one that holds the lock (a failed block's
        retry) waits that long at most, and the beat then waits for the lock as usual.
        Never before a clean-up (``interruptible=False``: a Stop, a withdraw's cancel
        record and its reads, a Play/Pause press; a press's status polls do wait): a
        Stop must not queue behind a beat on a slow link.
        """
        if interruptible and not self._free_turn.is_set():
            self._free_turn.wait(_LET_IN_S)

    @contextlib.contextmanager
    def let_in(self) -> Iterator[None]:
        """While inside: the robot's thread waits (up to 50 ms) before each new request.

        For a write that must get a turn on a busy link (the heartbeat): it takes the lock
        between two of the thread's requests instead of racing the thread for it.

        Yields:
            Nothing: the block inside is the waiting write's turn.
        """
        self._free_turn.clear()
        try:
            yield
        finally:
            self._free_turn.set()

    def hold(self) -> bool:
        """Take the link's lock if it is free, never waiting for it.

        For a reader that must never wait for the robot's thread (a driver's loop, a
        StatusMonitor's worker): the thread may hold the lock for a whole retried request.

        Returns:
            True if taken (give it back with :meth:`release`).
        """
        return self._lock.acquire(blocking=False)

    def release(self) -> None:
        """Give back the lock :meth:`hold` took."""
        self._lock.release()

    def bound_retries(self, deadline: float) -> None:
        """From now on, retry no request past ``deadline`` (``time.monotonic()``), not even
        one already retrying.

        For a clean-up under a time budget (``Robot.close(timeout_s=...)``): the
        withdraw or stop still gets its first attempt, and its retries end in time.

        Args:
            deadline: The ``time.monotonic()`` after which no retry starts.
        """
        self._retry_deadline = deadline

    def _run(self, what: str, fn: Callable[[], T], *, retry: bool, interruptible: bool) -> T:
        self._yield_turn(interruptible)
        with self._lock:
            self._refuse_if_closed()
            return (self.retry if retry else NO_RETRY).call(
                what,
                fn,
                on_retry=self._on_retry,
                interrupt=self.interrupt if interruptible else None,
                until=self._retry_until,
            )

    def _retry_until(self) -> float | None:
        return self._retry_deadline  # read at each retry: a close may set it meanwhile

    def read_block(
        self,
        table: Table,
        address: int,
        count: int,
        *,
        retry: bool = True,
        interruptible: bool = True,
    ) -> list[int]:
        """Read ``count`` words (or bits as 0/1) from ``address`` in one request.

        Args:
            table: The Modbus table.
            address: The first address.
            count: How many registers (or bits).
            retry: Retry a failed read per the retry policy.
            interruptible: A stop request (``interrupt``) ends the waits between
                retries.

        Returns:
            ``count`` words (bits as 0/1).

        Raises:
            TransportError: The read failed (a subclass says how).
        """
        what, function_code = self._read_request(table, address, count)
        once = functools.partial(self._read_once, what, function_code, address, count)
        return self._run(what, once, retry=retry, interruptible=interruptible)

    def _read_once(self, what: str, function_code: int, address: int, count: int) -> list[int]:
        """One attempt of a read: one request, sent once, whose answer has ``count`` words."""
        words = self._execute(what, function_code, address, count, None)
        if len(words) != count:
            raise ResponseTimeoutError(f"{self.name}: short answer to {what}")
        return words

    def _read_request(self, table: Table, address: int, count: int) -> tuple[str, int]:
        """A read's description and function code, checked against the protocol's limits once."""
        key = (table, address, count)
        known = self._reads.get(key)
        if known is None:
            check_request(table, address, count, write=False)
            known = (describe_read(table, address, count), READ_FUNCTION[table])
            if len(self._reads) < 256:  # bounded, like the read plans
                self._reads[key] = known
        return known

    def write_block(
        self,
        table: Table,
        address: int,
        words: Sequence[int],
        *,
        retry: bool,
        interruptible: bool = True,
    ) -> None:
        """Write words (holding, FC16) or bits (coils, FC05/FC15) in one request.

        Args:
            table: ``Table.HOLDING`` or ``Table.COIL``.
            address: The first address.
            words: The words (0..65535) or bits.
            retry: Retry a failed write per the retry policy (False for a write that
                triggers a command: it is sent once).
            interruptible: A stop request (``interrupt``) ends the waits between
                retries.

        Raises:
            ConfigError: A read-only table.
            ValueOutOfRangeError: A word outside 0..65535 (nothing is sent).
            TransportError: The write failed (a subclass says how).
        """
        if table.read_only:
            raise ConfigError(f"the {table.value} table is read-only")
        what = f"write {table.value} {address}+{len(words)}"
        values = [int(bool(v)) for v in words] if table.is_bit else list(words)
        check_request(table, address, len(values), write=True)
        for value in values:
            if not (isinstance(value, int) and 0 <= value <= 0xFFFF):
                raise ValueOutOfRangeError(what, value, "0-65535, one 16-bit register")
        function_code = 16 if table is Table.HOLDING else 5 if len(values) == 1 else 15

        once = functools.partial(self._execute, what, function_code, address, len(values), values)
        self._run(what, once, retry=retry, interruptible=interruptible)

    # -- fields ---------------------------------------------------------------

    def read_fields(
        self,
        fields: Iterable[RegisterField],
        *,
        max_gap: int = 0,
        retry: bool = True,
        interruptible: bool = True,
    ) -> dict[str, Value]:
        """Read and decode fields, one request per contiguous block.

        Args:
            fields: The fields.
            max_gap: A read may span this many unused addresses to fetch two fields
                in one request.
            retry: Retry a failed read per the retry policy.
            interruptible: A stop request (``interrupt``) ends the waits between
                retries.

        Returns:
            Each field's engineering value, by name.

        Raises:
            TransportError: A read failed (a subclass says how).
        """
        plan = self.read_plan(fields, max_gap=max_gap)
        return plan.decode(self._read_blocks(plan.blocks, retry, interruptible))

    def _read_blocks(
        self, blocks: tuple[Block, ...], retry: bool, interruptible: bool
    ) -> list[list[int]]:
        """Each block's words, a request each (a driver's link reads them in one hand-over)."""
        return [
            self.read_block(b.table, b.address, b.count, retry=retry, interruptible=interruptible)
            for b in blocks
        ]

    def read_plan(self, fields: Iterable[RegisterField], *, max_gap: int = 0) -> ReadPlan:
        """The cached :class:`ReadPlan` of ``fields`` (computed on first use)."""
        if fields.__class__ is tuple:
            # The channels read the same tuples every poll: found by the tuple's identity
            # (the entry holds the tuple, so its id cannot be reused while it lives).
            known = self._tuple_plans.get((max_gap, id(fields)))
            if known is not None and known[1] is fields:
                return known[0]
        chosen = tuple(fields)
        key = (max_gap, tuple(map(id, chosen)))
        entry = self._plans.get(key)
        if entry is None:
            entry = (ReadPlan.build(chosen, max_gap=max_gap), chosen)
            if len(self._plans) < 256:  # bounded: ad-hoc reads of new field sets
                self._plans[key] = entry
        if fields.__class__ is tuple and len(self._tuple_plans) < 256:
            self._tuple_plans[(max_gap, id(fields))] = (entry[0], fields)
        return entry[0]

    def write_fields(
        self,
        values: Sequence[tuple[RegisterField, Value]] | Mapping[RegisterField, Value],
        *,
        retry: bool,
        interruptible: bool = True,
    ) -> None:
        """Encode every value (refusing before any I/O), then write each block in one request.

        Pass ``retry=False`` for a write that triggers a command: it is sent once. Pass
        ``interruptible=False`` for clean-up writes (withdraw, stop) that must still be
        attempted after a stop request.

        Args:
            values: ``(field, value)`` pairs, or a mapping of them.
            retry: Retry a failed write per the retry policy (False for a write that
                triggers a command: it is sent once).
            interruptible: False for clean-up writes (withdraw, stop) that must still
                be attempted after a stop request.

        Raises:
            ValueOutOfRangeError: A value does not fit its field (nothing is sent).
            TransportError: A write failed (a subclass says how).
        """
        items = values.items() if isinstance(values, Mapping) else values
        # Every value is encoded before the first write: one out of range sends nothing.
        for block, words in group_writes(encode_writes(items)):
            self.write_block(
                block.table, block.address, words, retry=retry, interruptible=interruptible
            )


def endpoint_text(host: str, port: int) -> str:
    """``host:port`` as written in a URL: ``192.168.1.100:502``, ``[::1]:502``."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def connect_error(exc: BaseException, link: AsyncLink) -> ConnectError:
    """The typed error of a connection that could not be opened (the one mapping).

    A name that does not resolve is a :class:`HostNotFoundError`, a refusal a
    :class:`ConnectRefusedError`; anything else (no answer in time, no route, the
    network down) a plain :class:`ConnectError`, an outage.
    """
    name, host, port, timeout = link.name, link.host, link.port, link.timeout
    where = endpoint_text(host, port)
    if isinstance(exc, socket.gaierror | UnicodeError):
        # UnicodeError: the IDNA codec refusing a label (longer than 63 characters).
        reason = exc.strerror if isinstance(exc, socket.gaierror) else str(exc)
        return HostNotFoundError(f"cannot resolve host {host!r} ({name}): {reason}")
    if isinstance(exc, ConnectionRefusedError):
        return ConnectRefusedError(
            f"{name} at {where} refused the connection: nothing listens on port {port}"
            " (is the port right, the robot's Modbus slave on, the simulator started?)"
        )
    if isinstance(exc, TimeoutError):
        return ConnectError(f"cannot connect to {name} at {where}: no answer within {timeout:g} s")
    reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
    return ConnectError(f"cannot connect to {name} at {where}: {reason or type(exc).__name__}")


def refused_error(code: int, *, name: str, what: str) -> TransportError:
    """The typed error of a Modbus exception answer's ``code`` (IllegalAddressError for 2 ...).

    Code 5, "acknowledge: accepted, done later" (sent instead of letting the client time
    out), and 11, a gateway's "the device did not answer", are a
    :class:`ResponseTimeoutError`: the request may still take effect, as one that timed
    out may.
    """
    if code in (5, 11):
        return ResponseTimeoutError(f"{name}: no answer to {what} yet (Modbus exception {code})")
    error_class = MODBUS_EXCEPTIONS.get(code, ModbusExceptionError)
    return error_class(f"{name}: device refused {what}", code=code)


#: A request's MBAP header and its PDU's first fields: transaction id, protocol id,
#: length, unit id, function code, address, and the count (FC05: the coil's value).
_REQUEST = struct.Struct(">HHHBBHH")


def request_frame(
    function_code: int,
    address: int,
    count: int,
    values: list[int] | None,
    *,
    device_id: int,
    tid: int,
) -> bytes:
    """One request's Modbus TCP frame, byte for byte what pymodbus' framer builds.

    Reads (FC 1-4), FC05 (one coil), FC15 (coils, eight to a byte, the first in the
    lowest bit) and FC16 (holding registers).
    """
    words = values or []
    if function_code <= 5:
        last = count if function_code <= 4 else 0xFF00 if words[0] else 0
        return _REQUEST.pack(tid, 0, 6, device_id, function_code, address, last)
    if function_code == 16:
        data = struct.pack(f">B{len(words)}H", 2 * len(words), *words)
    else:
        packed = [
            sum(bool(b) << i for i, b in enumerate(words[k : k + 8]))
            for k in range(0, len(words), 8)
        ]
        data = bytes([len(packed), *packed])
    head = _REQUEST.pack(tid, 0, 6 + len(data), device_id, function_code, address, len(words))
    return head + data


def answer_words(
    function_code: int,
    answer: list[int] | ModbusPDU,
    asked: int,
    *,
    count: int,
    name: str,
    what: str,
) -> list[int]:
    """The words (bits as 0/1) of an answer to a read of function ``asked``, ``[]`` for a
    write; refusals raised. ``answer``: a common answer's words, or pymodbus' PDU."""
    if not isinstance(answer, list):
        if isinstance(answer, ExceptionResponse) or answer.isError():
            raise refused_error(int(getattr(answer, "exception_code", 0)), name=name, what=what)
        answer = [int(b) for b in answer.bits] if function_code <= 2 else list(answer.registers)
    if function_code != asked:
        raise TransportError(f"{name}: answer of another function to {what}")
    if asked > 4:
        return []
    words = answer[:count] if asked <= 2 else answer
    if len(words) < count:
        raise ResponseTimeoutError(f"{name}: short answer to {what}")
    return words


#: An answer cut from the stream: (transaction id, function code, the words of a common
#: answer (:func:`common_answer`) or, for any other, pymodbus' PDU).
Answer = tuple[int, int, list[int] | ModbusPDU]


def next_answer(
    framer: FramerSocket, buffer: bytes, *, device_id: int, name: str
) -> tuple[int, Answer | None]:
    """The first whole answer from ``device_id`` in ``buffer``: (bytes used, answer or None).

    A common answer is decoded here (:func:`common_answer`), any other by pymodbus'
    socket framer; a frame from another unit id is skipped (pymodbus would log it as an
    error). ``(0, None)``: wait for more bytes. Bytes no Modbus TCP server sends raise
    :class:`ForeignReplyError` (:func:`check_header`).
    """
    used = 0
    while used < len(buffer):
        check_header(buffer, used)
        size, unit, answer = common_answer(buffer, used) or _decoded(framer, buffer[used:])
        if not size:
            break
        used += size
        if answer is None:
            continue
        if unit != device_id:
            _log.debug("transport.foreign_unit", device=name, unit=unit)
            continue
        return used, answer
    return used, None


def _decoded(framer: FramerSocket, buffer: bytes) -> tuple[int, int, Answer | None]:
    """pymodbus' decoding of the frame ``buffer`` starts with: (its size, unit id, answer)."""
    size, pdu = framer.handleFrame(buffer, 0, 0)
    if pdu is None:
        return size, -1, None
    return size, pdu.dev_id, (pdu.transaction_id, pdu.function_code, pdu)


#: The MBAP header and the first two bytes of the PDU: transaction id, protocol id,
#: length, unit id, function code, and a read's byte count (or a write's address's high byte).
_HEAD = struct.Struct(">HHHBBB")


def common_answer(buffer: bytes, start: int) -> tuple[int, int, Answer | None] | None:
    """A whole, well-formed answer to a read (FC 1-4) or an FC16 write at ``start``.

    (Its size, its unit id, the answer with its words: a read's registers, or its bits
    as 0/1, eight per byte; ``[]`` for the write), decoded here at a tenth of the CPU of
    pymodbus' decoder; None for anything else, which pymodbus' framer decodes (a partial
    frame, an exception answer, a frame it refuses). ``(0, 0, None)``: wait for more
    bytes, where pymodbus would cut a frame short: the first 8 bytes of one whose length
    says 2 (a device that leaves the exception code out of the count), whose code is
    still on its way (pymodbus reads that frame as 9 bytes only when they came together).
    """
    if len(buffer) - start < 9:
        return (0, 0, None) if buffer[start + 4 : start + 6] == b"\x00\x02" else None
    tid, _protocol, length, unit, function_code, byte_count = _HEAD.unpack_from(buffer, start)
    if len(buffer) - start < 6 + length:
        return None
    if 1 <= function_code <= 4 and length == byte_count + 3:
        data = buffer[start + 9 : start + 6 + length]
        if function_code > 2 and not byte_count % 2:
            words = list(struct.unpack(f">{byte_count // 2}H", data))
            return 6 + length, unit, (tid, function_code, words)
        if function_code <= 2:
            bits = [byte >> i & 1 for byte in data for i in range(8)]
            return 6 + length, unit, (tid, function_code, bits)
    return (12, unit, (tid, 16, [])) if function_code == 16 and length == 6 else None


class ForeignReplyError(Exception):
    """Bytes no Modbus TCP server sends (internal: each link maps it to :class:`NotModbusError`).

    Args:
        reason: What is wrong, e.g. ``protocol id 21584, Modbus TCP's is 0``.
        data: The bytes received, from the frame that is wrong.
    """

    def __init__(self, reason: str, data: bytes) -> None:
        super().__init__(reason)
        #: What is wrong.
        self.reason = reason
        #: The bytes received, from the frame that is wrong.
        self.data = data


#: The lengths an MBAP header may give (unit id + PDU; 2: pymodbus' tolerance of a
#: device that leaves the exception code out of the count).
MBAP_LENGTHS = range(2, 255)


def check_header(buffer: bytes, start: int) -> None:
    """Refuse a frame at ``start`` whose MBAP header no Modbus TCP server sends.

    Checked as soon as the bytes are there, before pymodbus' framer, which would log
    the frame on its own logger and wait for more bytes forever: a protocol id other
    than 0 (an HTTP answer's is 21584, ``TP``), a length outside 2-254.

    Raises:
        ForeignReplyError: The header is not Modbus TCP's.
    """
    size = len(buffer) - start
    if size < 4:
        return
    if buffer[start + 2] or buffer[start + 3]:
        protocol = buffer[start + 2] << 8 | buffer[start + 3]
        raise ForeignReplyError(f"protocol id {protocol}, Modbus TCP's is 0", buffer[start:])
    if size >= 6 and (length := buffer[start + 4] << 8 | buffer[start + 5]) not in MBAP_LENGTHS:
        raise ForeignReplyError(f"frame length {length}, Modbus TCP's is 2-254", buffer[start:])


def shown_bytes(data: bytes) -> str:
    """The start of ``data`` for a message: up to 24 characters of text, quoted, or 12
    bytes in hex."""
    if all(32 <= b < 127 or b in (9, 10, 13) for b in data[:24]):
        return repr(data[:24].decode("ascii")) + ("..." if len(data) > 24 else "")
    return data[:12].hex(" ") + ("..." if len(data) > 12 else "")


#: What reading an answer may raise: bytes that are not Modbus TCP, and what pymodbus'
#: framer and PDU decoding raise on a malformed answer.
UNREADABLE_ANSWER: tuple[type[Exception], ...] = (
    ForeignReplyError,
    ModbusException,
    ValueError,
    IndexError,
    struct.error,
)


def answer_error(reply: Exception, link: AsyncLink, what: str) -> TransportError:
    """The error of an answer that cannot be read: a :class:`NotModbusError` for bytes
    that are not Modbus TCP (one line, host:port), else a malformed Modbus answer's."""
    if not isinstance(reply, ForeignReplyError):
        return TransportError(f"{link.name}: malformed answer to {what}: {reply}")
    where = endpoint_text(link.host, link.port)
    return NotModbusError(
        f"{link.name} at {where} is not a Modbus TCP server: its answer to {what} starts"
        f" {shown_bytes(reply.data)} ({reply.reason}); is the port right?",
        host=link.host,
        port=link.port,
    )


class _Stream(asyncio.Protocol):
    """One Modbus TCP stream of an :class:`AsyncLink`: answers matched to requests by id.

    Common answers are cut and decoded here (:func:`common_answer`), any other frame by
    pymodbus' socket framer and PDU decoder; an answer from another unit id, or whose
    transaction id no request awaits (a late answer to a request that timed out), is
    dropped, as pymodbus' own client does. An answer under an id never sent on this
    stream is kept: a request that then gets no answer of its own fails as
    :class:`NotModbusError` (no Modbus server answers so). Losing the connection or an
    undecodable frame fails every awaited request and closes the stream.
    """

    def __init__(self, link: AsyncLink) -> None:
        #: The link it carries: its name, unit id, byte counters and address.
        self.link = link
        self.framer = FramerSocket(DecodePDU(is_server=False))
        self.transport: asyncio.Transport | None = None
        self.closed = False
        #: Transaction id -> what its answer settles (its :class:`_Call`).
        self.awaited: dict[int, _Call] = {}
        #: The first transaction id sent on this stream, and how many were sent on it.
        self.first_tid = 0
        self.sent = 0
        #: Set on the first answer from the device (an exception answer included).
        self.answered = False
        #: The first answer under an id never sent here: (its id, its frame).
        self.stray: tuple[int, bytes] | None = None
        self._buffer = b""
        # The awaited requests' one deadline timer, (the time it is set for, its handle):
        # set again when a request's deadline is earlier, left when one is answered (a
        # timer per request, set and cancelled, cost more than the rest of its start).
        self._timer: tuple[float, asyncio.TimerHandle] | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # uvloop's transports implement asyncio.Transport's methods without subclassing it.
        self.transport = cast(asyncio.Transport, transport)

    def data_received(self, data: bytes) -> None:
        link = self.link
        if link.stats is not None:
            link.stats.bytes_received += len(data)
        self._buffer += data
        while self._buffer and not self.closed:
            try:
                used, answer = next_answer(
                    self.framer, self._buffer, device_id=link.device_id, name=link.name
                )
            except UNREADABLE_ANSWER as exc:
                self.fail(functools.partial(answer_error, exc, link))
                return
            if not used:
                return  # a partial frame: wait for the rest
            frame, self._buffer = self._buffer[:used], self._buffer[used:]
            if answer is None:
                continue
            self._take(answer, frame)

    def _take(self, answer: Answer, frame: bytes) -> None:
        """An answer from the device: to the request awaiting its id, or dropped."""
        tid = answer[0]
        call = self.awaited.pop(tid, None)
        if call is None or call.done():
            if self.stray is None and not self.sent_here(tid):
                self.stray = (tid, frame)
            _log.debug("transport.unawaited_answer", device=self.link.name, tid=tid)
            return
        self.answered = True
        call.set_result(answer[1], answer[2])

    def sent_here(self, tid: int) -> bool:
        """Whether a request under ``tid`` was sent on this stream."""
        if self.sent >= 0xFFFF:
            return 1 <= tid <= 0xFFFF
        return 1 <= tid <= 0xFFFF and (tid - self.first_tid) % 0xFFFF < self.sent

    def watch(self, deadline: float) -> None:
        """A request awaited until ``deadline`` (the loop's time): the timer fires by then."""
        if self._timer is None or deadline < self._timer[0]:
            if self._timer is not None:
                self._timer[1].cancel()
            loop = asyncio.get_running_loop()
            self._timer = (deadline, loop.call_at(deadline, self._expire_due, deadline))

    def _expire_due(self, due: float) -> None:
        """The timer: every request due by ``due`` fails; it is set for the next one."""
        self._timer = None
        for call in [c for c in self.awaited.values() if c.deadline <= due]:
            _expire(call, self)
        if self.awaited and not self.closed:
            self.watch(min(c.deadline for c in self.awaited.values()))

    def connection_lost(self, exc: Exception | None) -> None:
        name = self.link.name
        self.fail(lambda what: ConnectionLostError(f"{name}: connection lost during {what}"))

    def fail(self, error: Callable[[str], TransportError]) -> None:
        """Fail every awaited request with ``error(what)`` and close the stream."""
        self.closed = True  # the timer finds nothing awaited then
        awaited, self.awaited = self.awaited, {}
        for call in awaited.values():
            if not call.done():
                call.set_exception(error(call.what))
        if self.transport is not None:
            self.transport.close()


def no_answer_error(link: AsyncLink, what: str, *, answered: bool) -> ResponseTimeoutError:
    """The error of a request that got no answer in time.

    The rule: a link that has never answered anything is not retried beyond its first
    request's timeout. Something accepted the connection but does not speak Modbus to
    us (another protocol, a unit id it ignores); waiting the retry policy's whole
    budget there only hides that. Once the device has answered, a silence is an outage
    and the retry policy rides it out. Only retries are dropped, so nothing is ever
    sent more often than before.
    """
    if answered:
        return ResponseTimeoutError(f"{link.name}: no answer to {what} within {link.timeout:g} s")
    where = endpoint_text(link.host, link.port)
    error = ResponseTimeoutError(
        f"{link.name} at {where} accepted the connection but never answered:"
        f" no answer to {what} within {link.timeout:g} s (is it a Modbus TCP"
        f" server, for unit id {link.device_id}?)"
    )
    error.retryable = False
    return error


def _expire(future: _Call, stream: _Stream) -> None:
    """A request's deadline: fail it unless answered (the message is built only here).

    Answers came, but only under ids never sent on this stream: not a Modbus server.
    """
    if future.done():
        return
    link = stream.link
    if stream.stray is not None:
        tid, frame = stream.stray
        reply = ForeignReplyError(f"transaction id {tid}, never sent on this connection", frame)
        error = answer_error(reply, link, future.what)
    else:
        error = no_answer_error(link, future.what, answered=link.answered or stream.answered)
    future.set_exception(error)


def settle(future: asyncio.Future[T], value: T) -> None:
    """Give ``future`` its result, unless settled already (its task may have been cancelled)."""
    if not future.done():
        future.set_result(value)


def settle_failed(future: asyncio.Future[Any], error: BaseException) -> None:
    """Fail ``future`` with ``error``, unless settled already."""
    if not future.done():
        future.set_exception(error)


@dataclass(slots=True, eq=False)  # compared and hashed by identity, as a request is
class _Call:
    """One request awaiting its answer (:meth:`AsyncLink.start`: a coroutine's, a thread's).

    Its answer, failure or deadline settles it at once on the loop: ``settle(words)`` or
    ``fail(error)``, once, with no future and no further turn of the loop.
    """

    #: The request's function code.
    code: int
    count: int
    name: str
    what: str
    settle: Callable[[list[int]], object]
    fail: Callable[[BaseException], object]
    stream: _Stream | None = None
    tid: int = 0
    #: The loop's time by which it fails unanswered (its stream's timer).
    deadline: float = 0.0
    _done: bool = field(default=False, init=False)

    def done(self) -> bool:
        """True once settled."""
        return self._done

    def end(self) -> None:
        """Settled or given up: its deadline and its slot go (a late answer is dropped)."""
        self._done = True
        stream = self.stream
        if stream is not None and stream.awaited.get(self.tid) is self:
            del stream.awaited[self.tid]

    def set_result(self, function_code: int, answer: list[int] | ModbusPDU) -> None:
        """The answer came (from the stream): its function code, its words or PDU."""
        if self._done:
            return
        self.end()
        try:
            words = answer_words(
                function_code, answer, self.code, count=self.count, name=self.name, what=self.what
            )
        except TransportError as exc:
            self.fail(exc)
            return
        self.settle(words)

    def set_exception(self, exception: BaseException) -> None:
        """The request failed: the link, its deadline, or an undecodable answer."""
        if self._done:
            return
        self.end()
        self.fail(exception)


class AsyncLink:
    """The Modbus TCP link, on the running asyncio loop (every robot's, a StatusMonitor's).

    Requests are packed here, answers decoded here or by pymodbus (:func:`next_answer`);
    the stream is a plain asyncio protocol, not pymodbus' async client, whose
    per-request machinery was most of a monitor's CPU (docs/performance.md). Failures
    map to :class:`TransportError` subclasses. It has no retry and no counters of its own
    (``stats``, when set, counts bytes): a request is sent once, a failed one raises,
    and the caller closes the link and reconnects (a robot's
    :class:`~tmmaster.ModbusTransport` applies its retry policy above it).
    """

    def __init__(self, host: str, port: int, *, device_id: int, timeout: float, name: str):
        self.host = host
        self.port = port
        self.device_id = device_id
        self.timeout = timeout
        self.name = name
        #: When set, the bytes sent and received are counted here (a Fleet robot's link).
        self.stats: TransportStats | None = None
        self._stream: _Stream | None = None
        self._tid = 0
        #: Whether the device has answered on any stream of this link (see no_answer_error).
        self.answered = False

    @property
    def connected(self) -> bool:
        """True while the link is open."""
        return self._stream is not None and not self._stream.closed

    async def connect(self) -> None:
        """Open a fresh link within ``timeout`` (:class:`ConnectError` when it cannot)."""
        self.close()
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(self.timeout):
                stream = await self._open_stream(loop)
        except (OSError, TimeoutError, UnicodeError) as exc:
            raise connect_error(exc, self) from exc
        stream.first_tid = self._tid % 0xFFFF + 1
        self._stream = stream

    async def _open_stream(self, loop: asyncio.AbstractEventLoop) -> _Stream:
        """A connected stream; a host name resolved as ``socket.create_connection`` does
        (the standard resolver, in a worker thread; each address in turn)."""
        addresses: list[tuple[str, int]] = [(self.host, self.port)]
        if not is_ip_address(self.host):
            infos = await loop.run_in_executor(
                None, socket.getaddrinfo, self.host, self.port, 0, socket.SOCK_STREAM
            )
            addresses = [(str(info[4][0]), int(info[4][1])) for info in infos]
        error: OSError = OSError(f"no address for {self.host}")
        for host, port in addresses:
            try:
                _transport, opened = await loop.create_connection(lambda: _Stream(self), host, port)
            except OSError as exc:
                error = exc
            else:
                return opened
        raise error

    async def read_block(self, table: Table, address: int, count: int, what: str) -> list[int]:
        """Read ``count`` words (or bits as 0/1) in one request; failures as TransportError."""
        return await self.exchange(what, READ_FUNCTION[table], address, count, None)

    async def exchange(
        self, what: str, function_code: int, address: int, count: int, values: list[int] | None
    ) -> list[int]:
        """Send one request once and await its own answer within ``timeout``.

        The words (bits as 0/1) of a read's answer, ``[]`` for a write; failures as
        :class:`TransportError` subclasses. Nothing is ever resent here.
        """
        answer: asyncio.Future[list[int]] = asyncio.get_running_loop().create_future()
        done, failed = functools.partial(settle, answer), functools.partial(settle_failed, answer)
        call = self.start(what, function_code, address, count, values, done, failed)
        try:
            return await answer
        finally:
            if call is not None:
                call.end()  # given up (cancelled): its deadline and slot go

    def start(
        self,
        what: str,
        function_code: int,
        address: int,
        count: int,
        values: list[int] | None,
        settle: Callable[[list[int]], object],
        fail: Callable[[BaseException], object],
    ) -> _Call | None:
        """On the loop: send one request; ``settle(words)`` or ``fail(error)`` follows, once.

        Without a coroutine or a future per request (a thread's request, a chained read).
        The call (None: failed at once) can be ended early (:meth:`_Call.end`).
        """
        stream = self._stream
        if stream is None or stream.closed or stream.transport is None:
            fail(ConnectionLostError(f"{self.name}: not connected for {what}"))
            return None
        self._tid = tid = self._tid % 0xFFFF + 1
        try:
            frame = request_frame(
                function_code, address, count, values, device_id=self.device_id, tid=tid
            )
        except BaseException as exc:
            fail(exc)
            return None
        call = _Call(function_code, count, self.name, what, settle, fail)
        call.stream, call.tid = stream, tid
        stream.awaited[call.tid] = call
        stream.sent += 1
        stream.transport.write(frame)
        if self.stats is not None:
            self.stats.bytes_sent += len(frame)
        call.deadline = asyncio.get_running_loop().time() + self.timeout
        stream.watch(call.deadline)
        return call

    def close(self) -> None:
        """Close the link (safe when closed): after a failure it may still carry a late answer."""
        stream, self._stream = self._stream, None
        if stream is not None:
            self.answered = self.answered or stream.answered
            stream.fail(lambda what: ConnectionLostError(f"{self.name}: link closed during {what}"))
