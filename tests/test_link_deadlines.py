"""AsyncLink's request deadlines: each awaited request fails at its own deadline.

The link keeps one timer for all the requests it awaits (set for the earliest deadline,
left running when a request is answered): a request sent after an answered one, or with
a shorter timeout than one still awaited, must still fail at its own deadline.
"""

from __future__ import annotations

import asyncio

import pytest

from scripted_slave import ScriptedServer, answer_with, never_answer, registers
from tmmaster import ConnectionLostError, ResponseTimeoutError
from tmmaster._registers import Table
from tmmaster._transport import AsyncLink


async def _connected(server: ScriptedServer, timeout: float) -> AsyncLink:
    port = await server.start()
    link = AsyncLink("127.0.0.1", port, device_id=1, timeout=timeout, name="slave")
    await link.connect()
    return link


def test_a_request_after_an_answered_one_fails_at_its_own_deadline() -> None:
    async def body() -> None:
        server = ScriptedServer([answer_with(registers(1, 2)), never_answer])
        link = await _connected(server, 0.2)
        try:
            assert await link.read_block(Table.HOLDING, 0, 2, "first read") == [1, 2]
            with pytest.raises(ResponseTimeoutError, match=r"no answer to second read within 0\.2"):
                # Bounded here so that a deadline that never fires fails the test.
                await asyncio.wait_for(link.read_block(Table.HOLDING, 0, 2, "second read"), 5)
        finally:
            link.close()
            await server.stop()

    asyncio.run(body())


def test_a_shorter_deadline_fails_before_an_earlier_request_s() -> None:
    async def body() -> None:
        server = ScriptedServer([never_answer, never_answer])
        link = await _connected(server, 30.0)
        first = asyncio.ensure_future(link.read_block(Table.HOLDING, 0, 2, "slow read"))
        try:
            await asyncio.sleep(0.05)  # the slow read is sent and awaited
            link.timeout = 0.1
            with pytest.raises(ResponseTimeoutError, match=r"no answer to quick read within 0\.1"):
                # Far under the slow read's 30 s: the quick read's own deadline fired.
                await asyncio.wait_for(link.read_block(Table.HOLDING, 0, 2, "quick read"), 10)
            assert not first.done()  # its deadline is still ahead
        finally:
            link.close()
            await server.stop()
        with pytest.raises(ConnectionLostError, match="slow read"):
            await first

    asyncio.run(body())
