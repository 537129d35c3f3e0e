"""A small pymodbus server for transport tests: plain registers, a request log, and knobs.

It is deliberately independent of tmmaster.sim so the transport is tested against a
device that shares no code with it.
"""

from __future__ import annotations

import asyncio
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice


@dataclass
class LoggedRequest:
    """One request as the server saw it."""

    function_code: int
    address: int
    count: int
    values: list[int] | None


@dataclass
class Knobs:
    """Behaviour switches tests flip while the server runs."""

    #: Seconds to wait before answering a write (the answer arrives late).
    write_delay_s: float = 0.0
    #: Exception code to answer for requests touching [start, end].
    exception: tuple[int, int, int] | None = None
    requests: list[LoggedRequest] = field(default_factory=list)


class _TcpServer(ModbusTcpServer):
    """A pymodbus server that remembers its connection handlers, to close late ones.

    asyncio accepts a connection in a task: when the listener closes between the accept
    and the handler's ``connection_made``, pymodbus has already closed (and forgotten)
    the handler, and ``connection_made`` then installs a transport nobody ever closes.
    Its socket would leak until garbage collection warns about it in some later test.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.handlers: list[Any] = []

    def callback_new_connection(self) -> Any:
        handler = super().callback_new_connection()
        self.handlers.append(handler)
        return handler

    def close_late_connections(self) -> None:
        """Close every handler transport still open (call once the listener is shut)."""
        for handler in self.handlers:
            transport = handler.transport
            if transport is not None:
                transport.close()
        self.handlers.clear()


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nobody listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


class TestServer:
    """A pymodbus TCP server on 127.0.0.1 in a background thread."""

    __test__ = False  # not a pytest test class

    def __init__(self, port: int | None = None, *, size: int = 1024) -> None:
        self.port = port or free_port()
        self.size = size
        self.knobs = Knobs()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: _TcpServer | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()

    async def _action(
        self,
        function_code: int,
        _start: int,
        address: int,
        count: int,
        _registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        self.knobs.requests.append(
            LoggedRequest(
                function_code, address, count, None if values is None else list(map(int, values))
            )
        )
        if self.knobs.exception is not None:
            start, end, code = self.knobs.exception
            if address <= end and address + count - 1 >= start:
                return ExcCodes(code)
        if values is not None and self.knobs.write_delay_s:
            await asyncio.sleep(self.knobs.write_delay_s)
        return None

    def _device(self) -> SimDevice:
        regs = [SimData(0, count=self.size, values=0, datatype=DataType.REGISTERS)]
        bits = [SimData(0, count=self.size, values=False, datatype=DataType.BITS)]
        return SimDevice(
            id=0,
            simdata=(list(bits), list(bits), list(regs), list(regs)),
            action=self._action,
        )

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop

        async def main() -> None:
            self._server = _TcpServer(self._device(), address=("127.0.0.1", self.port))
            await self._server.serve_forever(background=True)
            self._ready.set()
            await self._server.serving

        loop.run_until_complete(main())

        # Requests still being answered (a delayed write) hold the accepted sockets:
        # finish them here, or their sockets outlive the server.
        async def finish_pending() -> None:
            # Let in-flight work end by itself (cancelling asyncio's accept task would
            # leave its socket open); cancel only what is still stuck after that.
            pending = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            if pending:
                _, stuck = await asyncio.wait(pending, timeout=3)
                for task in stuck:
                    task.cancel()
                await asyncio.gather(*stuck, return_exceptions=True)
            # Every accept has been handled by now: close what connected too late.
            assert self._server is not None
            self._server.close_late_connections()
            await asyncio.sleep(0.01)

        loop.run_until_complete(finish_pending())
        loop.close()

    def start(self) -> TestServer:
        """Start serving; returns when the port accepts connections."""
        self._ready.clear()
        self._thread = threading.Thread(target=self._run, name="test-modbus-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(5):
            raise RuntimeError("test server did not start")
        return self

    def stop(self) -> None:
        """Stop serving and drop every connection."""
        if self._loop is None or self._server is None or self._thread is None:
            return
        server = self._server

        async def shutdown() -> None:
            # As the simulator's server does (sim/_server.py _unlisten): stop accepting,
            # let a connection accepted in this very loop turn reach its protocol, then
            # shut down. Otherwise pymodbus never closes that just-accepted socket.
            loop = asyncio.get_running_loop()
            for sock in getattr(server.transport, "sockets", None) or ():
                loop.remove_reader(sock.fileno())
            for _ in range(3):
                await asyncio.sleep(0)
            await server.shutdown()  # type: ignore[no-untyped-call]

        asyncio.run_coroutine_threadsafe(shutdown(), self._loop).result(5)
        self._thread.join(5)
        self._loop = None
        self._server = None
        self._thread = None

    def call(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` on the server's loop."""
        assert self._loop is not None
        self._loop.call_soon_threadsafe(fn)

    def __enter__(self) -> TestServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
