"""A bank read serves exactly the words of its fields, raw areas and bridgeable gaps.

Each address of a read is served (a gap reads 0) or the whole read is refused, naming the
first address that is not and the read; checked against an address-by-address reference
at every edge of every readable run of every table, and at random.
"""

from __future__ import annotations

import random

import pytest

from tmmaster._exceptions import IllegalAddressError
from tmmaster._registers import Table
from tmmaster.sim import RobotSetup, Simulator
from tmmaster.sim._bank import RegisterBank


def read_address_by_address(bank: RegisterBank, table: Table, address: int, count: int) -> object:
    """The reference: the words read, or the refusal's message."""
    name = bank.register_map.name
    if count < 1 or address < 0 or address + count - 1 > 65535:
        return str(IllegalAddressError(f"{name}: bad {table.value} range: {count} from {address}"))
    words = bank._words[table]
    gaps = bank._gaps[table]
    for a in range(address, address + count):
        if a not in words and a not in gaps:
            refused = f"{table.value} address {a} is not served (read of {count} from {address})"
            return str(IllegalAddressError(f"{name}: {refused}"))
    return [words.get(a, 0) for a in range(address, address + count)]


def read(bank: RegisterBank, table: Table, address: int, count: int) -> object:
    try:
        return bank.read(table, address, count)
    except IllegalAddressError as exc:
        return str(exc)


def reads_to_try(runs: list[tuple[int, int]], chosen: random.Random) -> list[tuple[int, int]]:
    """Reads starting and ending on, just before and just after every run's edges."""
    tries = [(0, 1), (65535, 1), (65535, 2), (-1, 1), (0, 0), (5, -1)]
    for first, count in runs:
        last = first + count - 1
        for start in (first - 1, first, first + 1, last - 1, last, last + 1):
            for end in (first, last - 1, last, last + 1, last + 2):
                tries.append((start, end - start + 1))
        tries.append((chosen.randrange(first, last + 1), chosen.randrange(1, 130)))
    return tries


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_every_read_serves_or_refuses_as_the_address_by_address_check(profile: str) -> None:
    # Never started: its banks only; with a Modbus gripper, the gripper's bank too.
    sim = Simulator(profile, listen=False, robot=RobotSetup(gripper="onrobot-2fg7"))
    chosen = random.Random(11)
    for device in ("robot", "gripper"):
        bank: RegisterBank = sim.device_server(device)._bank  # type: ignore[assignment]
        for table in Table:
            words = bank._words[table]
            for address in words:
                words[address] = chosen.randrange(2 if table.is_bit else 65536)
            for address, count in reads_to_try(bank.readable(table), chosen):
                expected = read_address_by_address(bank, table, address, count)
                assert read(bank, table, address, count) == expected, (device, table, address)
