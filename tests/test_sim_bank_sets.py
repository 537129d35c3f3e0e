"""A device-side ``set`` stores exactly the codec's words for the value, or refuses it whole.

Every field of a tmflow robot's bank (Techman's table included) and of a 2FG7's, set to
values in and out of its range, again and again: the words stored are ``encode()``'s,
a refused value raises the codec's error and leaves the field's words as they were.
"""

from __future__ import annotations

import pytest

from tmmaster._codec import encode
from tmmaster._exceptions import ValueOutOfRangeError
from tmmaster._registers import DataType
from tmmaster.sim import RobotSetup, Simulator
from tmmaster.sim._bank import RegisterBank

#: Values for a number field: whole, fractional, signed zeros, huge, not finite, a bool.
NUMBERS: tuple[object, ...] = (1, 0.5, -0.0, 0.0, -3.25, 12345.678, 1e12, float("nan"), True, 7)
BITS: tuple[object, ...] = (True, False, 1, 0, 2, 0.5)


def outcome(run: object) -> object:
    try:
        return run()  # type: ignore[operator]
    except ValueOutOfRangeError as exc:
        return ("refused", str(exc))


def words_of(bank: RegisterBank, name: str) -> list[int]:
    field = bank.field(name)
    return bank.read(field.table, field.address, field.end - field.address + 1)


@pytest.mark.parametrize("device", ["robot", "gripper"])
def test_every_field_stores_the_codecs_words_or_refuses_the_value(device: str) -> None:
    sim = Simulator("tmflow", listen=False, robot=RobotSetup(gripper="onrobot-2fg7"))
    bank: RegisterBank = sim.device_server(device)._bank  # type: ignore[assignment]
    names = [*bank.register_map.fields, *bank._extra]
    assert len(names) > 20
    for _ in range(2):  # the second round finds each field's encoding already made
        for name in names:
            field = bank.field(name)
            values = BITS if field.dtype is DataType.BOOL else NUMBERS
            for value in values:
                before = words_of(bank, name)
                expected = outcome(lambda: encode(field, value))  # type: ignore[arg-type]  # noqa: B023
                got = outcome(lambda: bank.set(name, value))  # type: ignore[arg-type]  # noqa: B023
                if isinstance(expected, tuple):
                    assert got == expected, (name, value)
                    assert words_of(bank, name) == before, (name, value)
                else:
                    assert got is None, (name, value)
                    assert words_of(bank, name) == expected, (name, value)
    with pytest.raises(KeyError):
        bank.set("no_such_field", 1)
