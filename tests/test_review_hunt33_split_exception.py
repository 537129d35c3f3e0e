"""Review of hunt 33: the exception answer whose length leaves its code out, byte by byte.

``tests/test_hunt33_split_exception.py`` sends that answer in two segments 10 ms apart
through a socket: whether the master reads the first eight bytes alone depends on that
pause (on a loaded machine both segments can arrive in one read, and the test passes
without the fix). Here the decoder is given the bytes themselves: the first eight are
waited on, never decoded alone (pymodbus refused them, "Unable to decode"), at any cut.
"""

from __future__ import annotations

import struct

import pytest
from pymodbus.exceptions import ModbusIOException
from pymodbus.framer import FramerSocket
from pymodbus.pdu import DecodePDU, ExceptionResponse

from tmmaster._transport import next_answer

#: Transaction 7, unit 1, length 2 (the code left out), FC 3's exception, code 2.
SHORT_COUNT = struct.pack(">HHHB", 7, 0, 2, 1) + bytes([0x83, 2])


@pytest.mark.parametrize("received", range(1, 9))
def test_the_first_bytes_of_a_short_count_exception_are_waited_on(received: int) -> None:
    framer = FramerSocket(DecodePDU(is_server=False))
    assert next_answer(framer, SHORT_COUNT[:received], device_id=1, name="slave") == (0, None)


def test_the_whole_short_count_exception_is_the_refusal() -> None:
    used, answer = next_answer(
        FramerSocket(DecodePDU(is_server=False)), SHORT_COUNT, device_id=1, name="slave"
    )
    assert used == len(SHORT_COUNT)
    assert answer is not None
    tid, function_code, pdu = answer
    assert isinstance(pdu, ExceptionResponse)
    assert (tid, function_code, pdu.exception_code) == (7, 0x83, 2)


def test_pymodbus_alone_refuses_the_first_eight_bytes() -> None:
    """Why the wait matters: decoded alone, the eight bytes are no answer at all."""
    with pytest.raises(ModbusIOException):
        FramerSocket(DecodePDU(is_server=False)).handleFrame(SHORT_COUNT[:8], 0, 0)
