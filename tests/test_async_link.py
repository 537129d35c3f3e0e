"""AsyncLink (the monitor's link) against a scripted slave: what it does with bad answers.

The slave is a raw asyncio server in the test's own loop that answers each request as
the test scripts it: held, late, of another function, short, undecodable, or with the
connection closed. The link must never hand one request's answer to another.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import Awaitable, Callable

import pytest

from scripted_slave import (
    Answer,
    ScriptedServer,
    answer_in_parts,
    answer_with,
    close_connection,
    registers,
)
from tmmaster import (
    ConnectionLostError,
    IllegalAddressError,
    NotModbusError,
    ResponseTimeoutError,
    TransportError,
)
from tmmaster._registers import Table
from tmmaster._transport import AsyncLink


async def with_slave(
    script: list[Answer], body: Callable[[AsyncLink], Awaitable[None]], *, timeout: float = 0.2
) -> None:
    """Run ``body`` with a link connected to a slave that answers request k by ``script[k]``."""
    server = ScriptedServer(script)
    port = await server.start()
    link = AsyncLink("127.0.0.1", port, device_id=1, timeout=timeout, name="slave")
    try:
        await link.connect()
        await body(link)
    finally:
        link.close()
        await server.stop()  # the slave's side ends too


def test_a_late_answer_is_dropped_not_taken_for_the_next_read() -> None:
    async def body(link: AsyncLink) -> None:
        with pytest.raises(ResponseTimeoutError, match=r"no answer to first read within 1 s"):
            await link.read_block(Table.HOLDING, 0, 2, "first read")
        # The first answer (111, 111) arrives while the second read waits: it is not its.
        assert await link.read_block(Table.HOLDING, 0, 2, "second read") == [222, 222]

    # 0.25 s or more between the events (the first read's give-up at 1 s, the late answer
    # at 1.25 s, the second's at about 1.75 s, its give-up at about 2 s): with 0.05 s
    # (a 0.2 s timeout) the second read once timed out in a run on a loaded machine.
    asyncio.run(
        with_slave(
            [
                answer_with(registers(111, 111), after_s=1.25),  # after the first gave up
                answer_with(registers(222, 222), after_s=0.75),  # after that late one
            ],
            body,
            timeout=1.0,
        )
    )


def test_an_answer_under_another_transaction_id_is_not_taken() -> None:
    # An id never sent on this connection: no Modbus server answers so.
    async def body(link: AsyncLink) -> None:
        with pytest.raises(NotModbusError, match="transaction id"):
            await link.read_block(Table.HOLDING, 0, 2, "read")

    asyncio.run(with_slave([answer_with(registers(1, 2), tid_offset=7)], body))


def test_an_answer_from_another_unit_is_not_taken() -> None:
    async def body(link: AsyncLink) -> None:
        with pytest.raises(ResponseTimeoutError):
            await link.read_block(Table.HOLDING, 0, 2, "read")

    asyncio.run(with_slave([answer_with(registers(1, 2), unit=7)], body))


def test_an_answer_of_another_function_is_an_error() -> None:
    async def body(link: AsyncLink) -> None:
        with pytest.raises(TransportError, match="another function"):
            await link.read_block(Table.HOLDING, 0, 2, "read")

    fc4 = struct.pack(">BB2H", 4, 4, 1, 2)  # input registers, to a holding read
    asyncio.run(with_slave([answer_with(fc4)], body))


def test_a_short_answer_is_an_error() -> None:
    async def body(link: AsyncLink) -> None:
        with pytest.raises(ResponseTimeoutError, match="short answer"):
            await link.read_block(Table.HOLDING, 0, 3, "read")

    asyncio.run(with_slave([answer_with(registers(1, 2))], body))


def test_an_exception_answer_is_the_typed_refusal() -> None:
    async def body(link: AsyncLink) -> None:
        with pytest.raises(IllegalAddressError, match="device refused read") as caught:
            await link.read_block(Table.HOLDING, 0, 2, "read")
        assert caught.value.code == 2
        assert link.connected  # the device answered: the link is fine

    asyncio.run(with_slave([answer_with(bytes([0x83, 2]))], body))


def test_an_undecodable_answer_fails_and_closes_the_link() -> None:
    async def body(link: AsyncLink) -> None:
        with pytest.raises(TransportError):
            await link.read_block(Table.HOLDING, 0, 2, "read")
        assert not link.connected

    asyncio.run(with_slave([answer_with(bytes([0x41, 0, 0]))], body))


def test_a_connection_closed_mid_read_is_connection_lost() -> None:
    async def body(link: AsyncLink) -> None:
        with pytest.raises(ConnectionLostError, match="connection lost"):
            await link.read_block(Table.HOLDING, 0, 2, "read")
        assert not link.connected
        with pytest.raises(ConnectionLostError, match="not connected"):
            await link.read_block(Table.HOLDING, 0, 2, "read")

    asyncio.run(with_slave([close_connection], body))


def test_closing_the_link_fails_the_read_it_awaits() -> None:
    async def body(link: AsyncLink) -> None:
        read = asyncio.create_task(link.read_block(Table.HOLDING, 0, 2, "read"))
        await asyncio.sleep(0.05)
        link.close()
        with pytest.raises(ConnectionLostError, match="link closed"):
            await read
        link.close()  # twice is fine

    asyncio.run(with_slave([answer_with(registers(1, 2), after_s=0.15)], body))


def test_bits_and_an_answer_split_across_segments() -> None:
    async def body(link: AsyncLink) -> None:
        assert await link.read_block(Table.HOLDING, 0, 2, "read") == [7, 8]
        assert await link.read_block(Table.COIL, 0, 3, "coils") == [1, 0, 1]

    coils = bytes([1, 1, 0b101])
    split = answer_in_parts(registers(7, 8), cuts=(3, 9), pause_s=0.01)
    asyncio.run(with_slave([split, answer_with(coils)], body))
