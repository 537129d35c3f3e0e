"""How the simulated TCP server hands its bank to pymodbus.

The device pymodbus serves is the one pymodbus itself would make of the same entries,
checked the same way. pymodbus hands the server's read hook the packed words a bit read
covers (16 bits a word, LSB first). Every bit of those words is the bank's bit where the
bank serves it (a field, a raw area or a bridgeable gap) and 0 elsewhere, whatever the
word's mix of the two.
"""

from __future__ import annotations

import dataclasses
import random

import pytest
from pymodbus.simulator import SimDevice

from tmmaster._registers import Table
from tmmaster.sim import Simulator
from tmmaster.sim._bank import RegisterBank
from tmmaster.sim._server import _built_blocks, _fresh_entries, _LayoutDevice


def packed_bit_by_bit(bank: RegisterBank, table: Table, word_address: int) -> int:
    """The reference: each bit of the word looked up on its own."""
    readable = bank.readable(table)
    word = 0
    for bit in range(16):
        address = word_address * 16 + bit
        if any(a <= address < a + n for a, n in readable) and bank.read(table, address, 1)[0]:
            word |= 1 << bit
    return word


@pytest.mark.parametrize("table", [Table.COIL, Table.DISCRETE_INPUT])
def test_every_packed_word_holds_the_banks_bits_and_zeros_where_nothing_is_served(
    table: Table,
) -> None:
    # tmflow's bits: Techman's coils and discrete inputs, with gaps inside packed words.
    profile = "tmflow"
    sim = Simulator(profile, listen=False)  # never started: the bank and server only
    server = sim.device_server("robot")
    bank: RegisterBank = server._bank  # type: ignore[assignment]
    runs = bank.readable(table)
    assert runs, f"{profile} serves no {table.value}"
    # Half of the served bits set, at random but the same on every run.
    chosen = random.Random(7)
    for first, count in runs:
        for address in range(first, first + count):
            if address in bank._words[table]:
                bank._words[table][address] = chosen.randint(0, 1)
    assert any(bank.read(table, a, n) != [0] * n for a, n in runs)
    last_word = max(a + n - 1 for a, n in runs) // 16
    # Every word from 0 past the last served one, read one word at a time and as one
    # block of all of them (a read starting mid-block: start_word below first_word).
    for word_address in range(last_word + 2):
        registers = [-1]
        server._refresh_bits(table, word_address, 1, word_address, registers)
        assert registers == [packed_bit_by_bit(bank, table, word_address)], word_address
    registers = [-1] * (last_word + 2)
    server._refresh_bits(table, 1, last_word + 1, 0, registers)
    assert registers[0] == -1  # before the read: untouched
    assert registers[1:] == [packed_bit_by_bit(bank, table, w) for w in range(1, last_word + 2)]


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_the_served_device_is_the_one_pymodbus_makes_of_the_same_entries(profile: str) -> None:
    server = Simulator(profile).device_server("robot")  # never started
    device = server._sim_device()
    own = SimDevice(id=0, simdata=_fresh_entries(device.runs), action=server._action)
    names = [f.name for f in dataclasses.fields(SimDevice)]
    assert [getattr(device, n) for n in names] == [getattr(own, n) for n in names]
    assert device.use_bit_addressing is True
    assert device.build_device() == own.build_device()


def test_pymodbus_still_checks_the_device_and_each_layouts_entries() -> None:
    server = Simulator("article").device_server("robot")  # never started
    runs = server._sim_device().runs
    entries = _fresh_entries(runs)

    def not_async(*args: object) -> None: ...

    with pytest.raises(TypeError, match="async"):
        _LayoutDevice(id=0, simdata=entries, action=not_async)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="id"):
        _LayoutDevice(id=256, simdata=entries, action=server._action)
    # Two runs of the holding registers that overlap: refused when the layout is built.
    with pytest.raises(TypeError, match="overlapping"):
        _built_blocks(((), (), ((0, 5), (3, 2)), ()))
