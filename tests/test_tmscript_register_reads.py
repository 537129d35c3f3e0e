"""A read of registers converted at once is the read, then the conversion.

``Byte_ToInt16Array(modbus_read(...), ...)``, the robot program's read of its registers,
runs as one step of the interpreter: these compare it with the same read kept in a
byte array and converted after, values and errors, and check that it waits for the
link and gives a new array each time.
"""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from tmmaster import TMScriptRuntimeError
from tmmaster.tmscript import ExecState, Execution, ModbusDevice, NullHost, parse
from tmmaster.tmscript._host import HostError

#: Words of a slave: high bit set, a low byte only, over 16 bits and negative (a host's
#: odd answer: the low 16 bits count).
WORDS = {0: 0x0102, 1: 0xFFFF, 2: 0x8000, 3: 0x007F, 4: 0x1_0005, 5: -2}


class _Slave(NullHost):
    """Answers every read from ``WORDS`` (bits: a word's truth); refuses address 99."""

    def __init__(self) -> None:
        super().__init__(clock=lambda: 0.0)
        self.shown: list[str] = []
        self.ready = True

    def display(self, text: str) -> None:
        self.shown.append(text)

    def modbus_ready(self, device: ModbusDevice) -> bool:
        return self.ready

    def modbus_request(
        self,
        device: ModbusDevice,
        function: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> list[int]:
        if address == 99:
            raise HostError("illegal data address")
        return [WORDS.get(address + i, 0) for i in range(count)]


def _run(main: str) -> tuple[_Slave, Execution]:
    host = _Slave()
    program = parse(f'define\n{{\n ModbusTCP TM = "127.0.0.1", 502\n}}\nmain\n{{\n{main}}}\n')
    execution = Execution(program, host)
    execution.run_to_end(timeout_s=5)
    return host, execution


@pytest.mark.parametrize("kind", ["RO", "RI", "DO", "DI"])
@pytest.mark.parametrize("args", ["", ", 1", ", 0", ", 2", ", 1, 0", ", 1, 1", ", 0, 1"])
def test_a_read_converted_at_once_equals_the_read_then_the_conversion(kind: str, args: str) -> None:
    lines = "".join(
        f' raw = modbus_read("TM", 1, "{kind}", {first}, {count})\n'
        f" Display(Byte_ToInt16Array(raw{args}))\n"
        f' words = Byte_ToInt16Array(modbus_read("TM", 1, "{kind}", {first}, {count}){args})\n'
        " Display(words)\n"
        for first, count in ((0, 1), (0, 2), (1, 3), (0, 6))
    )
    host, execution = _run(f" byte[] raw = {{}}\n int[] words = {{}}\n{lines}")
    assert execution.error is None
    assert len(host.shown) == 8
    assert host.shown[0::2] == host.shown[1::2]


def test_a_refused_read_is_the_error_of_modbus_read() -> None:
    _, kept = _run(' byte[] raw = modbus_read("TM", 1, "RO", 99, 2)\n')
    _, converted = _run(' int[] w = Byte_ToInt16Array(modbus_read("TM", 1, "RO", 99, 2), 1, 0)\n')
    assert isinstance(kept.error, TMScriptRuntimeError)
    assert isinstance(converted.error, TMScriptRuntimeError)
    assert kept.error.reason == converted.error.reason
    assert "modbus_read()" in converted.error.reason
    # Each at its own modbus_read call (line 7), not at Byte_ToInt16Array (column 12).
    assert (kept.error.line, kept.error.column) == (7, 15)
    assert (converted.error.line, converted.error.column) == (7, 30)


def test_an_unknown_device_is_the_error_of_modbus_read() -> None:
    _, execution = _run(' int[] w = Byte_ToInt16Array(modbus_read("XX", 1, "RO", 0, 2))\n')
    assert isinstance(execution.error, TMScriptRuntimeError)
    assert "modbus_read()" in execution.error.reason
    assert "XX" in execution.error.reason


def test_the_read_waits_for_the_link() -> None:
    host = _Slave()
    host.ready = False
    program = parse(
        'define\n{\n ModbusTCP TM = "127.0.0.1", 502\n}\n'
        'main\n{\n int[] w = Byte_ToInt16Array(modbus_read("TM", 1, "RO", 0, 2), 1, 0)\n'
        " Display(w)\n}\n"
    )
    execution = Execution(program, host)
    assert execution.step().state == ExecState.BLOCKED
    assert execution.step().state == ExecState.BLOCKED
    assert host.shown == []
    host.ready = True
    execution.run_to_end(timeout_s=5)
    assert execution.error is None
    assert host.shown == ["{258,-1}"]


def test_each_read_is_a_new_array() -> None:
    host, execution = _run(
        ' int[] a = Byte_ToInt16Array(modbus_read("TM", 1, "RO", 0, 2), 1, 0)\n'
        " int[] b = a\n"
        ' a = Byte_ToInt16Array(modbus_read("TM", 1, "RO", 0, 2), 1, 0)\n'
        " a[0] = 7\n"
        " b[1] = 9\n"
        " Display(a)\n Display(b)\n"
    )
    assert execution.error is None
    assert host.shown == ["{7,-1}", "{258,9}"]
