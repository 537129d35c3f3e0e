"""The simulator's Modbus TCP servers: the only module that calls pymodbus' server API.

One :class:`DeviceServer` serves one :class:`~tmmaster.sim._bank.RegisterBank` on one TCP
port. pymodbus 3.16 runs a ``SimDevice`` internally; we give it one ``SimData`` block per
readable run of the bank (so the layout comes from the register map, never from a second
list of addresses) and an ``action`` callback that copies words from the bank before a
read and applies writes to the bank. The bank stays the single source of truth; the
pymodbus registers are only a mirror.

Every request first passes the per-request trace hook (``trace_pdu``), which sees the
exact request (device id, function code, address, count, values). It records the
request, enforces the device id, validates reads against the bank (pymodbus packs coils
16 to a register, so its own checks cannot be exact for bits), applies the
``modbus_exception`` fault and counts requests for the network faults. A refused request
is swapped for a small PDU whose only job is to answer with the exception code.

Everything here runs on the simulator's event loop thread; nothing is locked except the
request log, which other threads read.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import threading
import time
import weakref
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

from pymodbus.constants import ExcCodes
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from .._exceptions import ConnectError, IllegalAddressError, IllegalValueError
from .._registers import Table
from ._faults import (
    DropConnectionsFault,
    ModbusExceptionFault,
    NetworkFault,
    SlowResponsesFault,
    StopListeningFault,
)

#: Table addressed by each function code pymodbus' server decodes.
_TABLE_OF_FC: dict[int, Table] = {
    1: Table.COIL,
    5: Table.COIL,
    15: Table.COIL,
    2: Table.DISCRETE_INPUT,
    3: Table.HOLDING,
    6: Table.HOLDING,
    16: Table.HOLDING,
    22: Table.HOLDING,
    23: Table.HOLDING,
    4: Table.INPUT,
}
_READ_FCS = frozenset({1, 2, 3, 4})

#: Oldest entries are dropped beyond this, so a long-running CLI does not grow forever.
REQUEST_LOG_LIMIT = 100_000


@dataclass(frozen=True)
class RequestRecord:
    """One Modbus request as the simulator received it."""

    #: Wall-clock time (``time.time()``) when the request arrived.
    time: float
    #: Which listener got it: ``"robot"`` or ``"gripper"``.
    server: str
    #: The request's unit id.
    device_id: int
    #: The Modbus function code (3 = read holding registers, 16 = write registers...).
    function_code: int
    #: The first address.
    address: int
    #: How many registers or bits.
    count: int
    #: Written words (0/1 for coils); None for reads.
    values: tuple[int, ...] | None
    #: Modbus exception code the simulator answered with before touching data, else 0.
    refused: int = 0

    @property
    def is_write(self) -> bool:
        """True for a request that writes (FC 5, 6, 15, 16, 22, 23)."""
        return self.values is not None

    def as_dict(self) -> dict[str, Any]:
        """The record as plain JSON-able data.

        Returns:
            The fields by name (``values`` a list).
        """
        data = asdict(self)
        data["values"] = None if self.values is None else list(self.values)
        return data


class RequestLog:
    """Thread-safe, bounded list of :class:`RequestRecord`, shared by all servers."""

    def __init__(
        self,
        *,
        limit: int = REQUEST_LOG_LIMIT,
        listener: Callable[[RequestRecord], None] | None = None,
    ) -> None:
        self._records: deque[RequestRecord] = deque(maxlen=limit)
        # Written on the loop thread, copied from test threads: a lock keeps copies whole.
        self._lock = threading.Lock()
        self._listener = listener

    def append(self, record: RequestRecord) -> None:
        """Add a record (and pass it to the listener, if any)."""
        with self._lock:
            self._records.append(record)
        if self._listener is not None:
            self._listener(record)

    def records(self) -> list[RequestRecord]:
        """A copy of every record, oldest first."""
        with self._lock:
            return list(self._records)

    def clear(self) -> None:
        """Forget every record."""
        with self._lock:
            self._records.clear()


def json_line(record: RequestRecord) -> str:
    """One JSON line for ``--trace-requests``."""
    return json.dumps(record.as_dict(), separators=(",", ":"))


class Bank(Protocol):
    """What a server needs from a register bank."""

    def readable(self, table: Table) -> list[tuple[int, int]]:
        """Readable runs as (first address, count)."""

    def read(self, table: Table, address: int, count: int) -> list[int]:
        """Words (0/1 for bits); raises IllegalAddressError."""

    def write(self, table: Table, address: int, values: Sequence[int]) -> None:
        """Store words; raises IllegalAddressError / IllegalValueError."""


class _Refusal(ModbusPDU):
    """Stands in for a refused request: answers with a Modbus exception, touches nothing."""

    def __init__(self, request: ModbusPDU, code: int, delay_s: float) -> None:
        super().__init__(dev_id=request.dev_id, transaction_id=request.transaction_id)
        self.function_code = request.function_code
        self._code = code
        self._delay_s = delay_s

    async def datastore_update(self, context: Any, device_id: int) -> ModbusPDU:
        """Answer with the exception (after the slow_responses delay, like every answer)."""
        _ = context, device_id
        if self._delay_s > 0:
            await asyncio.sleep(self._delay_s)
        return ExceptionResponse(self.function_code, self._code)


@dataclass(frozen=True)
class _Request:
    table: Table
    address: int
    count: int
    values: tuple[int, ...] | None


@dataclass(frozen=True)
class MemoryAnswer:
    """What an in-memory request got back from :class:`DeviceServer`."""

    #: Words read (bits as 0/1); empty for writes and refusals.
    words: list[int] = field(default_factory=list)
    #: Modbus exception code, or 0.
    refused: int = 0
    #: Wall seconds the answer is late (slow_responses).
    delay_s: float = 0.0
    #: The data is untouched yet: call ``memory_apply`` after ``delay_s``.
    pending: bool = False
    #: "none"; "link" (link was down: request not sent); "request" (lost, not executed);
    #: "answer" (executed, answer lost).
    lost: str = "none"


def _describe(pdu: ModbusPDU) -> _Request | None:
    """Table, address, count and written values of a request (None: not a data request)."""
    table = _TABLE_OF_FC.get(pdu.function_code)
    if table is None:
        return None
    fc = pdu.function_code
    if fc in _READ_FCS:
        return _Request(table, pdu.address, pdu.count, None)
    if fc in (5, 15):
        bits = tuple(int(bool(b)) for b in pdu.bits)
        return _Request(table, pdu.address, len(bits), bits)
    if fc == 23:
        written = tuple(int(v) for v in getattr(pdu, "write_registers", ()))
        return _Request(table, int(getattr(pdu, "write_address", 0)), len(written), written)
    if fc == 22:
        # Mask write: the written word depends on the current value; log the masks' target.
        return _Request(table, pdu.address, 1, ())
    registers = tuple(int(v) for v in pdu.registers)
    return _Request(table, pdu.address, len(registers), registers)


def _writes_to(request: _Request | None, address: int) -> bool:
    """True when ``request`` is a write covering ``address``."""
    if request is None or request.values is None:
        return False
    return _overlaps(request, request.table, address, address)


def _overlaps(request: _Request, table: Table, start: int, end: int) -> bool:
    last = request.address + max(request.count, 1) - 1
    return request.table is table and request.address <= end and last >= start


class _Listener(ModbusTcpServer):
    """pymodbus' TCP server, remembering its connection handlers to close late ones.

    asyncio sets a connection up in a task: when the listener closes between the accept
    and the handler's ``connection_made``, pymodbus has already closed and forgotten the
    handler, and ``connection_made`` then installs a transport nobody closes; its socket
    would leak until garbage collection warns about it.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.handlers: weakref.WeakSet[Any] = weakref.WeakSet()

    def callback_new_connection(self) -> Any:
        """Create a connection handler (pymodbus) and remember it."""
        handler = super().callback_new_connection()  # type: ignore[no-untyped-call]
        self.handlers.add(handler)
        return handler

    def close_late_connections(self) -> None:
        """Close every handler transport still open (after the listener shut down)."""
        for handler in list(self.handlers):
            if handler.transport is not None:
                handler.transport.close()


_Runs = tuple[tuple[int, int], ...]


@functools.lru_cache(maxsize=16)
def _sim_data(
    runs: tuple[_Runs, _Runs, _Runs, _Runs],
) -> tuple[tuple[SimData, ...], ...]:
    """pymodbus' entries for the readable runs of the coils, discrete inputs, holding and
    input registers, made once per layout: a server of a bank with Techman's table has
    hundreds (pymodbus checks each as it is made) and a simulator starts one server each
    time. pymodbus reads them, and copies their values into each device's registers."""
    blocks: list[tuple[SimData, ...]] = []
    for table, table_runs in zip(
        (Table.COIL, Table.DISCRETE_INPUT, Table.HOLDING, Table.INPUT), runs, strict=True
    ):
        if table.is_bit:
            # One list of n bits, not count=n: pymodbus 3.16 checks bit blocks for
            # overlap with n * n addresses, which a long run (e.g. 900-1699) overflows.
            entries = [
                SimData(address=a, values=[False] * n, datatype=DataType.BITS)
                for a, n in table_runs
            ]
            # pymodbus needs at least one entry per table; the trace hook refuses
            # every address of an empty table before pymodbus looks at it.
            entries = entries or [SimData(address=0, values=False, datatype=DataType.BITS)]
        else:
            entries = [
                SimData(address=a, count=n, values=0, datatype=DataType.REGISTERS)
                for a, n in table_runs
            ]
            entries = entries or [SimData(address=0, datatype=DataType.INVALID)]
        blocks.append(tuple(entries))
    return tuple(blocks)


_Blocks = dict[str, tuple[int, list[int], list[int]]]


def _fresh_entries(
    runs: tuple[_Runs, _Runs, _Runs, _Runs],
) -> tuple[list[SimData], list[SimData], list[SimData], list[SimData]]:
    """Fresh lists (pymodbus sorts them in place) of the entries made for ``runs``."""
    coils, discrete, holding, inputs = (list(entries) for entries in _sim_data(runs))
    return coils, discrete, holding, inputs


@functools.lru_cache(maxsize=16)
def _built_blocks(runs: tuple[_Runs, _Runs, _Runs, _Runs]) -> _Blocks:
    """pymodbus' own ``build_device`` of the entries for ``runs``, made once per layout.

    pymodbus fills every address between two entries one by one (Techman's table spans
    about 18,000 registers): about 7 ms of CPU per server start for a tmflow bank.
    """
    built = SimDevice(id=0, simdata=_fresh_entries(runs)).build_device()
    assert isinstance(built, dict)  # four tables: always a dict
    return built


def _probe_entries() -> tuple[list[SimData], list[SimData], list[SimData], list[SimData]]:
    """One entry a table: what pymodbus needs to check a device's other parameters."""
    return (
        [SimData(address=0, values=False, datatype=DataType.BITS)],
        [SimData(address=0, values=False, datatype=DataType.BITS)],
        [SimData(address=0, datatype=DataType.INVALID)],
        [SimData(address=0, datatype=DataType.INVALID)],
    )


class _LayoutDevice(SimDevice):
    """pymodbus' SimDevice whose memory is a copy of the one built for its layout.

    ``build_device`` depends on the entries only; each server gets its own copy of the
    lists (its registers are written), built by pymodbus once per layout.
    """

    #: The readable runs of the four tables the entries were made for (set at creation).
    runs: tuple[_Runs, _Runs, _Runs, _Runs] = ((), (), (), ())

    def __post_init__(self) -> None:
        """pymodbus' checks of the device's own parameters; not of the entries again.

        pymodbus checks every entry by expanding its values, then that list ``count``
        times (a million words for Techman's 1000-register run): about 1.2 ms of CPU
        per tmflow server start. These very entries passed that check when
        :func:`_built_blocks` built their layout's memory, before any device is made
        of them; id, identity and action are checked here by pymodbus itself, on a
        one-entry stand-in, and bit addressing is what pymodbus sets for four blocks.
        """
        probe = SimDevice(
            id=self.id,
            simdata=_probe_entries(),
            use_bit_addressing=self.use_bit_addressing,
            identity=self.identity,
            action=self.action,
        )
        self.use_bit_addressing = probe.use_bit_addressing

    def build_device(self) -> _Blocks:
        """A copy of the memory pymodbus built for these runs."""
        return {
            table: (start, list(registers), list(flags))
            for table, (start, registers, flags) in _built_blocks(self.runs).items()
        }


def _nothing() -> None:
    """No control ticks to run (a server on its own)."""


class DeviceServer:
    """A Modbus TCP listener serving one register bank, with network faults."""

    def __init__(
        self,
        name: str,
        bank: Bank,
        *,
        host: str,
        port: int,
        log: RequestLog,
        device_id: int | None = None,
        max_connections: int | None = None,
        tcp: bool = True,
    ) -> None:
        self.name = name
        #: False: no socket at all, only in-memory links (see :meth:`memory_connect`).
        self.tcp = tcp
        self._accepting = False
        # In-memory links: ids of the open ones; a dropped link's id is forgotten.
        self._links: set[int] = set()
        self._next_link = 0
        self._bank = bank
        self._host = host
        self._port = port
        self._log = log
        #: None = answer every unit id (the TM controller ignores it).
        self._device_id = device_id
        self._max_connections = max_connections
        self._server: _Listener | None = None
        self._faults: list[NetworkFault] = []
        # Requests counted since each fault was injected (same order as _faults).
        self._counts: list[int] = []
        # Faults whose trigger request arrived; they fire when its answer has been sent.
        self._pending: list[NetworkFault] = []
        self._lose_answer = False
        self._outage: asyncio.Task[None] | None = None
        self._stopped = False
        #: Called before a request reads or writes the bank: the Simulator runs its due
        #: control ticks there, so every answer is as fresh as the ticks due by then.
        self.before_data: Callable[[], None] = _nothing

    # -- lifecycle ----------------------------------------------------------------------

    @property
    def port(self) -> int:
        """The TCP port (the real one once started with port 0)."""
        return self._port

    @property
    def listening(self) -> bool:
        """True while the listener accepts connections (TCP or in-memory)."""
        return self._accepting

    async def start(self) -> None:
        """Bind and start accepting connections."""
        self._stopped = False
        await self._listen()

    async def stop(self) -> None:
        """Stop listening and close every client connection."""
        self._stopped = True
        if self._outage is not None:
            self._outage.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._outage
            self._outage = None
        await self._unlisten()

    async def _listen(self) -> None:
        self._accepting = True
        if not self.tcp:
            return
        server = _Listener(
            self._sim_device(),
            address=(self._host, self._port),
            trace_pdu=self._trace_pdu,
            trace_connect=self._trace_connect,
        )
        try:
            await server.serve_forever(background=True)
        except RuntimeError as exc:  # pymodbus's "Could not start listen": name the cause
            raise OSError(
                f"cannot listen on {self._host}:{self._port} (port in use, or not an"
                " address of this machine)"
            ) from exc
        listener = server.transport
        sockets = getattr(listener, "sockets", None)
        if sockets:
            # Port 0 asked for a free port: remember the real one so a restart after a
            # stop_listening outage binds the same port.
            self._port = int(sockets[0].getsockname()[1])
        self._server = server

    async def _unlisten(self) -> None:
        self._accepting = False
        self._links.clear()
        server, self._server = self._server, None
        if server is None:
            return
        # Stop accepting first and let connections accepted in this very loop turn finish
        # their setup: on Python 3.11 a connection accepted just before the listener
        # closes is never handed to its protocol and its socket leaks.
        loop = asyncio.get_running_loop()
        for sock in getattr(server.transport, "sockets", None) or ():
            loop.remove_reader(sock.fileno())
        for _ in range(3):
            await asyncio.sleep(0)
        await server.shutdown()  # type: ignore[no-untyped-call]
        for _ in range(3):
            await asyncio.sleep(0)  # a set-up still in flight reaches connection_made
        server.close_late_connections()

    def _sim_device(self) -> SimDevice:
        coils, discrete, holding, inputs = (
            tuple(self._bank.readable(table))
            for table in (Table.COIL, Table.DISCRETE_INPUT, Table.HOLDING, Table.INPUT)
        )
        runs = (coils, discrete, holding, inputs)
        # pymodbus checks (and builds the memory of) these entries once per layout here.
        _built_blocks(runs)
        # id 0 = every unit id; the trace hook enforces a device id where one is required.
        device = _LayoutDevice(id=0, simdata=_fresh_entries(runs), action=self._action)
        device.runs = runs
        return device

    # -- faults -------------------------------------------------------------------------

    def set_faults(self, faults: Iterable[NetworkFault]) -> None:
        """Replace the network faults."""
        self._faults = list(faults)
        self._counts = [0] * len(self._faults)
        self._pending = []

    def add_fault(self, fault: NetworkFault) -> None:
        """Add one network fault; its request count starts now."""
        self._faults.append(fault)
        self._counts.append(0)

    def _remove_fault(self, fault: NetworkFault) -> None:
        for index, known in enumerate(self._faults):
            if known is fault:
                del self._faults[index]
                del self._counts[index]
                return

    def _delay_s(self) -> float:
        return sum(f.delay_s for f in self._faults if isinstance(f, SlowResponsesFault))

    # -- pymodbus hooks -----------------------------------------------------------------

    def _trace_connect(self, connected: bool) -> None:
        """Enforce max_connections: a newcomer is closed while older clients are connected."""
        if not connected or self._max_connections is None or self._server is None:
            return
        handlers = list(self._server.active_connections.values())
        # pymodbus adds a connection before announcing it, so the newest ones are last.
        for extra in handlers[self._max_connections :]:
            extra.close()

    def _trace_pdu(self, sending: bool, pdu: ModbusPDU) -> ModbusPDU:
        if sending:
            if self._lose_answer:
                # The request was executed; cut the links before its answer is written.
                self._lose_answer = False
                self.drop_connections()
            if self._pending:
                # The trigger request's answer is written right after this hook returns;
                # acting on the next loop turn lets the client receive that answer first.
                due, self._pending = self._pending, []
                asyncio.get_running_loop().call_soon(self._fire, due)
            return pdu
        try:
            return self._gate(pdu)
        except Exception:  # a bug in the gate must not kill the connection
            return _Refusal(pdu, ExcCodes.DEVICE_FAILURE, 0.0)

    def _gate(self, pdu: ModbusPDU) -> ModbusPDU:
        request = _describe(pdu)
        refused, lose = self._admit(pdu.dev_id, pdu.function_code, request, pdu.address, pdu.count)
        if refused:
            return _Refusal(pdu, refused, 0.0 if lose == "request" else self._delay_s())
        return pdu

    def _admit(
        self,
        device_id: int,
        function_code: int,
        request: _Request | None,
        address: int,
        count: int,
    ) -> tuple[int, str]:
        """Check, count and log one request (TCP or in-memory): (refusal code, what is lost)."""
        refused = self._check(device_id, request)
        lose = self._count_request(request)
        if not refused and lose == "request":
            # Lose the request itself: cut every link now and never execute it (the
            # refusal's answer goes nowhere: its connection is already closed).
            refused = ExcCodes.DEVICE_FAILURE
            self.drop_connections()
        self._log.append(
            RequestRecord(
                time=time.time(),
                server=self.name,
                device_id=device_id,
                function_code=function_code,
                address=request.address if request else address,
                count=request.count if request else count,
                values=request.values if request else None,
                refused=int(refused),
            )
        )
        return int(refused), lose

    def _check(self, device_id: int, request: _Request | None) -> int:
        """Exception code to answer with, or 0 to let the request through."""
        if self._device_id is not None and device_id != self._device_id:
            return ExcCodes.GATEWAY_NO_RESPONSE
        if request is None:
            return ExcCodes.ILLEGAL_FUNCTION
        for fault in self._faults:
            if isinstance(fault, ModbusExceptionFault) and _overlaps(
                request, fault.table, fault.start, fault.end
            ):
                return fault.code
        if request.values is None:
            try:
                self._bank.read(request.table, request.address, request.count)
            except IllegalAddressError:
                return ExcCodes.ILLEGAL_ADDRESS
        return 0

    def _count_request(self, request: _Request | None) -> str:
        """Count a request for the connection faults; returns what a due drop must lose."""
        lose = "none"
        spent: list[NetworkFault] = []
        for index, fault in enumerate(self._faults):
            if not isinstance(fault, DropConnectionsFault | StopListeningFault):
                continue
            target = fault.on_write_to if isinstance(fault, DropConnectionsFault) else None
            if target is not None and not _writes_to(request, target):
                continue
            self._counts[index] += 1
            if self._counts[index] < fault.after_requests:
                continue
            self._counts[index] = 0
            if isinstance(fault, DropConnectionsFault) and fault.lose != "none":
                lose = fault.lose
                if fault.once:
                    spent.append(fault)
                if lose == "answer":
                    self._lose_answer = True
                continue
            self._pending.append(fault)
        for fault in spent:
            self._remove_fault(fault)
        return lose

    def _fire(self, due: list[NetworkFault]) -> None:
        for fault in due:
            if isinstance(fault, DropConnectionsFault):
                self.drop_connections()
                if fault.once:
                    self._remove_fault(fault)
            elif isinstance(fault, StopListeningFault):
                # One outage per injected fault: afterwards the server behaves again.
                self._remove_fault(fault)
                if self._outage is None and not self._stopped:
                    self._outage = asyncio.get_running_loop().create_task(
                        self._stop_listening(fault.duration_s)
                    )

    def drop_connections(self) -> None:
        """Close every client connection (the listener keeps accepting)."""
        self._links.clear()
        if self._server is not None:
            for handler in list(self._server.active_connections.values()):
                handler.close()

    # -- in-memory links (same checks, log and faults as a TCP request) ------------------

    def memory_connect(self) -> int:
        """Open an in-memory link; its id. Raises ConnectError while not listening."""
        if not self._accepting:
            raise ConnectError(f"simulated {self.name}: not listening (connection refused)")
        self._next_link += 1
        link = self._next_link
        if self._max_connections is None or len(self._links) < self._max_connections:
            self._links.add(link)
        # Else, as over TCP, the newcomer is accepted and closed at once: its first
        # request finds the link gone.
        return link

    def memory_disconnect(self, link: int) -> None:
        """Close an in-memory link."""
        self._links.discard(link)

    def memory_request(
        self,
        link: int,
        device_id: int,
        function_code: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> MemoryAnswer:
        """Serve one request of an in-memory link through the TCP path's gate and faults.

        With a ``slow_responses`` fault the data is not touched here: the caller waits
        ``delay_s`` and then calls :meth:`memory_apply` (as the TCP server touches the
        data only after its delay).
        """
        if link not in self._links:
            return MemoryAnswer(lost="link")  # the request never reached the device
        table = _TABLE_OF_FC.get(function_code)
        request = (
            None
            if table is None
            else _Request(table, address, count, None if values is None else tuple(values))
        )
        refused, lose = self._admit(device_id, function_code, request, address, count)
        if lose == "request":
            return MemoryAnswer(refused=refused, lost="request")
        delay = self._delay_s()
        if refused:
            return MemoryAnswer(refused=refused, delay_s=delay)
        if delay > 0:
            return MemoryAnswer(delay_s=delay, pending=True)
        return self._finish(function_code, address, count, values)

    def memory_apply(
        self, function_code: int, address: int, count: int, values: Sequence[int] | None
    ) -> MemoryAnswer:
        """Touch the data of a request admitted by :meth:`memory_request` (after a delay)."""
        return self._finish(function_code, address, count, values)

    def _finish(
        self, function_code: int, address: int, count: int, values: Sequence[int] | None
    ) -> MemoryAnswer:
        table = _TABLE_OF_FC[function_code]
        words: list[int] = []
        refused = 0
        self.before_data()
        try:
            if values is not None:
                self._bank.write(table, address, [int(v) for v in values])
            else:
                words = self._bank.read(table, address, count)
        except IllegalAddressError:
            refused = ExcCodes.ILLEGAL_ADDRESS
        except IllegalValueError:
            refused = ExcCodes.ILLEGAL_VALUE
        lost = "none"
        if self._lose_answer:
            # Executed; the link goes down before the answer is delivered.
            self._lose_answer = False
            self.drop_connections()
            lost = "answer"
        if self._pending:
            # The answer is delivered when this returns: due faults act right after it.
            due, self._pending = self._pending, []
            asyncio.get_running_loop().call_soon(self._fire, due)
        return MemoryAnswer(words=words, refused=int(refused), lost=lost)

    async def _stop_listening(self, duration_s: float) -> None:
        try:
            await self._unlisten()
            await asyncio.sleep(duration_s)
            if not self._stopped:
                await self._listen()
        finally:
            self._outage = None

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """Copy bank words into pymodbus' registers before a read; apply writes to the bank."""
        table = _TABLE_OF_FC[function_code]
        # pymodbus reads back after a write (same request): delay only the first call.
        if values is not None or function_code in _READ_FCS:
            delay = self._delay_s()
            if delay > 0:
                await asyncio.sleep(delay)
        self.before_data()
        try:
            if values is not None:
                self._bank.write(table, address, [int(v) for v in values])
            if table.is_bit:
                # For bits pymodbus passes the first packed word and the number of words.
                self._refresh_bits(table, address // 16, count, start_address, registers)
            elif values is None:
                offset = address - start_address
                registers[offset : offset + count] = self._bank.read(table, address, count)
        except IllegalAddressError:
            return ExcCodes.ILLEGAL_ADDRESS
        except IllegalValueError:
            return ExcCodes.ILLEGAL_VALUE
        return None

    def _refresh_bits(
        self, table: Table, first_word: int, words: int, start_word: int, registers: list[int]
    ) -> None:
        """Pack the bank's bits of ``words`` packed words from ``first_word`` into ``registers``.

        A bit outside the readable runs (no field, no bridgeable gap) packs as 0; the runs
        are read whole, not bit by bit.
        """
        first = first_word * 16
        end = (first_word + words) * 16
        bits = [0] * (end - first)
        for run_first, run_count in self._bank.readable(table):
            low = max(run_first, first)
            high = min(run_first + run_count, end)
            if low < high:
                bits[low - first : high - first] = self._bank.read(table, low, high - low)
        for k in range(words):
            word = 0
            for bit, value in enumerate(bits[16 * k : 16 * k + 16]):
                if value:
                    word |= 1 << bit  # pymodbus packs bits LSB first
            registers[first_word + k - start_word] = word
