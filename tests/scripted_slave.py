"""A scripted Modbus TCP slave: it answers request k as ``script[k]`` says (late, wrong, never).

Shared by the tests of both links (``test_async_link.py``, ``test_sync_link.py``): it
runs on an event loop, the test's own or one in a thread of its own (:class:`SlaveThread`).
The script is consumed across connections, so a link that reconnects meets the next
scripted answer, not the first again.
"""

from __future__ import annotations

import asyncio
import itertools
import struct
import threading
from collections import deque
from collections.abc import Callable, Coroutine, Iterable
from types import TracebackType
from typing import Any

#: What the scripted slave does with one request: (transaction id, the request's PDU, writer).
Answer = Callable[[int, bytes, asyncio.StreamWriter], Coroutine[Any, Any, None]]


def frame(tid: int, pdu: bytes, unit: int = 1) -> bytes:
    """An MBAP frame for ``unit`` around ``pdu``."""
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def registers(*words: int) -> bytes:
    """An FC3 answer PDU carrying ``words``."""
    return struct.pack(f">BB{len(words)}H", 3, 2 * len(words), *words)


def answer_with(pdu: bytes, *, after_s: float = 0.0, tid_offset: int = 0, unit: int = 1) -> Answer:
    """Answer ``pdu`` after ``after_s`` as ``unit``, under the request's id + ``tid_offset``."""

    async def answer(tid: int, _request: bytes, writer: asyncio.StreamWriter) -> None:
        await asyncio.sleep(after_s)
        writer.write(frame(tid + tid_offset, pdu, unit))
        await writer.drain()

    return answer


def answer_in_parts(pdu: bytes, *, cuts: Iterable[int], pause_s: float) -> Answer:
    """Answer ``pdu`` in segments cut at ``cuts`` (byte offsets), ``pause_s`` apart."""

    async def answer(tid: int, _request: bytes, writer: asyncio.StreamWriter) -> None:
        whole = frame(tid, pdu)
        edges = [0, *cuts, len(whole)]
        for start, end in itertools.pairwise(edges):
            writer.write(whole[start:end])
            await writer.drain()
            await asyncio.sleep(pause_s)

    return answer


async def close_connection(_tid: int, _request: bytes, writer: asyncio.StreamWriter) -> None:
    """Close the connection instead of answering."""
    writer.close()


async def never_answer(_tid: int, _request: bytes, _writer: asyncio.StreamWriter) -> None:
    """Take the request and say nothing."""


class ScriptedServer:
    """The slave's server on the running loop; :attr:`requests` records each request's PDU."""

    def __init__(self, script: Iterable[Answer]) -> None:
        self.script: deque[Answer] = deque(script)
        self.requests: list[bytes] = []
        self._served: list[asyncio.Task[None]] = []
        self._handlers: list[asyncio.Task[None]] = []
        self._writers: list[asyncio.StreamWriter] = []
        self._server: asyncio.Server | None = None
        self.port = 0

    async def start(self) -> int:
        """Listen on a free loopback port and return it."""
        self._server = await asyncio.start_server(self._accept, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]
        return self.port

    async def stop(self) -> None:
        """Stop listening and wait (bounded) for every connection's handler to end."""
        # A connection the loop is accepting right now must finish first: closing the
        # server under it makes asyncio (3.11) drop the accepted socket unclosed.
        await asyncio.sleep(0.01)
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
        if self._handlers:
            await asyncio.wait(self._handlers, timeout=2)
        for writer in self._writers:  # whatever is still open (a handler cut short)
            writer.close()
        closing = [asyncio.ensure_future(w.wait_closed()) for w in self._writers]
        if closing:
            await asyncio.wait(closing, timeout=2)  # the sockets are closed, not just asked to

    def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        # Registered here, in connection_made, not when the handler first runs: stop()
        # must see every accepted connection, however short the test.
        self._writers.append(writer)
        self._handlers.append(asyncio.get_running_loop().create_task(self._handle(reader, writer)))

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while self.script:
                head = await reader.readexactly(7)
                tid, _protocol, length, _unit = struct.unpack(">HHHB", head)
                pdu = await reader.readexactly(length - 1)
                self.requests.append(pdu)
                answer = self.script.popleft()
                self._served.append(asyncio.create_task(answer(tid, pdu, writer)))
            await reader.read()  # until the link closes
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        finally:
            await asyncio.gather(*self._served, return_exceptions=True)
            writer.close()


class SlaveThread:
    """A :class:`ScriptedServer` on an event loop in a thread of its own (blocking tests)."""

    def __init__(self, script: Iterable[Answer]) -> None:
        self.server = ScriptedServer(script)
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="scripted-slave")

    @property
    def port(self) -> int:
        """The slave's loopback port."""
        return self.server.port

    def __enter__(self) -> SlaveThread:
        self._thread.start()
        asyncio.run_coroutine_threadsafe(self.server.start(), self._loop).result(5)
        return self

    def __exit__(
        self,
        _type: type[BaseException] | None,
        _value: BaseException | None,
        _traceback: TracebackType | None,
    ) -> None:
        asyncio.run_coroutine_threadsafe(self.server.stop(), self._loop).result(5)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(5)
        self._loop.close()
