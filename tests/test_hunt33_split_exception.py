"""Hunt 33: an exception answer whose MBAP length leaves its code out, in two segments.

Some devices count an exception answer's length as 2 (unit id and function code),
leaving the exception code out; pymodbus' framer reads such a frame as 9 bytes, but only
when all 9 are in its buffer at once. Delivered in two segments cut after the function
code (a serial-to-TCP converter flushing on an inter-character gap), the first 8 bytes
were decoded alone: "malformed answer" (a TransportError, never retried, the link
dropped) instead of the device's refusal. Which error the master reported depended on
how the network cut the frame. The link now waits for the ninth byte.
"""

from __future__ import annotations

import asyncio
import struct
from typing import Any

import pytest

from scripted_slave import SlaveThread, answer_with, registers
from tmmaster import IllegalAddressError, ModbusTransport, RetryPolicy
from tmmaster._registers import Table


def short_count_exception(cut: int) -> Any:
    """An exception answer (code 2) whose MBAP length leaves the code out (2, not 3), as
    some devices send it (pymodbus reads it), delivered in two segments cut at ``cut``."""

    async def answer(tid: int, _request: bytes, writer: asyncio.StreamWriter) -> None:
        whole = struct.pack(">HHHB", tid, 0, 2, 1) + bytes([0x83, 2])
        for part in (whole[:cut], whole[cut:]):
            writer.write(part)
            await writer.drain()
            await asyncio.sleep(0.01)

    return answer


@pytest.mark.parametrize("cut", [7, 8, 9])
def test_an_exception_answer_split_after_its_function_code_is_the_refusal(cut: int) -> None:
    """Split after its function code, the answer was read as malformed (TransportError,
    never retried, the link dropped) where the same bytes in one segment are the device's
    refusal: which one the master reported depended on how the network cut the frame."""
    script = [short_count_exception(cut), answer_with(registers(1, 2))]
    with (
        SlaveThread(script) as slave,
        ModbusTransport(
            "127.0.0.1", slave.port, timeout=1.0, retry=RetryPolicy(attempts=1), name="slave"
        ) as link,
    ):
        with pytest.raises(IllegalAddressError):
            link.read_block(Table.HOLDING, 0, 2)
        assert link.read_block(Table.HOLDING, 0, 2) == [1, 2]
