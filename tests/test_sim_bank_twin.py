"""Twinned bank fields (Techman's robot-base copies of the flange and the TCP) take the
words their original encoded for the same value: the words stored are still exactly
``encode()``'s for the copy, a zero keeps its sign, a refused value is still refused."""

from __future__ import annotations

import pytest

from tmmaster._codec import encode
from tmmaster._exceptions import ValueOutOfRangeError
from tmmaster.sim import Simulator
from tmmaster.sim._bank import RegisterBank

PAIRS = [
    ("robot_base_flange_x", "flange_x"),
    ("robot_base_flange_rz", "flange_rz"),
    ("robot_base_tcp_y", "tcp_y"),
]


def bank_of(sim: Simulator) -> RegisterBank:
    return sim.device_server("robot")._bank  # type: ignore[no-any-return]


def words_of(bank: RegisterBank, name: str) -> list[int]:
    field = bank.field(name)
    return bank.read(field.table, field.address, field.end - field.address + 1)


@pytest.mark.parametrize(("copy", "original"), PAIRS)
def test_a_copy_stores_its_own_encoding_of_each_value(copy: str, original: str) -> None:
    bank = bank_of(Simulator("tmflow", listen=False))
    values = (1.5, 1.5, -0.0, 0.0, -0.0, 0, 0.0, 123.25, -7, 1e30, 2.5)
    for value in values:
        bank.set(original, value)
        bank.set(copy, value)
        assert words_of(bank, copy) == encode(bank.field(copy), value), value
        assert words_of(bank, original) == encode(bank.field(original), value), value
    # The copy set alone (its original holding another value) encodes its own.
    bank.set(original, 4.0)
    bank.set(copy, -0.0)
    assert words_of(bank, copy) == encode(bank.field(copy), -0.0)
    with pytest.raises(ValueOutOfRangeError):
        bank.set(copy, float("inf"))
    assert words_of(bank, copy) == encode(bank.field(copy), -0.0)


def test_fields_that_encode_differently_are_not_twinned() -> None:
    bank = bank_of(Simulator("tmflow", listen=False))
    assert not bank.twin("robot_base_flange_x", "robot_link")
    assert bank.twin("robot_base_flange_x", "flange_x")
