"""What the simulated tmflow robot publishes at every tick, and how its bank reads it back.

Techman's Running Timer and Up Time are stored part by part (days, hours, minutes,
seconds), each part only when it changed while nothing else wrote their tables; a
field's value read from the bank is the codec's decoding of its words.
"""

from __future__ import annotations

import random

import pytest

from tmmaster._codec import decode
from tmmaster._profiles import robot_profile
from tmmaster._registers import Table
from tmmaster._robot_models import robot_model
from tmmaster.sim import _simulator
from tmmaster.sim._bank import RegisterBank
from tmmaster.sim._kinematic import KinematicBackend
from tmmaster.sim._script_project import ScriptProjectController
from tmmaster.sim._world import World

PARTS = ("days", "hours", "minutes", "seconds")


def _robot() -> tuple[ScriptProjectController, RegisterBank]:
    """A tmflow robot running the generated program, as the Simulator builds it."""
    profile = robot_profile("tmflow")
    model = robot_model("tm5-700")
    cls, options = _simulator._script_project(profile, "generated", None)
    bank = cls.bank_for(profile)
    controller = cls(profile, bank, KinematicBackend(model, world=World(())), model, **options)
    assert isinstance(controller, ScriptProjectController)
    return controller, bank


def _clock(bank: RegisterBank, prefix: str) -> int:
    days, hours, minutes, seconds = (bank.get(f"{prefix}_{p}") for p in PARTS)
    assert isinstance(days, int)
    assert isinstance(hours, int)
    assert 0 <= hours < 24
    assert isinstance(minutes, int)
    assert 0 <= minutes < 60
    assert isinstance(seconds, int)
    assert 0 <= seconds < 60
    return ((days * 24 + hours) * 60 + minutes) * 60 + seconds


@pytest.mark.parametrize("start_s", [0.0, 50.0, 3590.0, 86390.0, 3 * 86400.0 - 7.0])
def test_the_up_time_counts_across_minutes_hours_and_days(start_s: float) -> None:
    controller, bank = _robot()
    for _ in range(10):
        controller.tick(0.4)  # the project runs: its Running Timer counts too
    controller.tick(start_s)
    for _ in range(60):  # 24 s in the suite's ticks, across the next boundary
        controller.tick(0.4)
        assert _clock(bank, "up") == int(controller.time_s)
        running = _clock(bank, "running")
        assert running == int(controller._running_timer_s())
        assert running > 0


def test_a_part_written_meanwhile_is_published_again() -> None:
    controller, bank = _robot()
    for _ in range(10):
        controller.tick(0.4)
    controller.tick(3599.0)
    up = int(controller.time_s)
    # Only the seconds change at the next tick; the hours, written by someone else
    # meanwhile, are stored again all the same.
    bank.set("up_hours", 7)
    controller.tick(0.4)
    assert _clock(bank, "up") == int(controller.time_s)
    assert int(controller.time_s) // 3600 == up // 3600


@pytest.mark.parametrize("seed", [1, 2])
def test_a_field_read_back_is_the_codec_decoding_of_its_words(seed: int) -> None:
    _, bank = _robot()
    chosen = random.Random(seed)
    names = [n for n in bank.register_map.fields if bank.has(n)] + ["up_seconds", "flange_x"]
    for _ in range(3):
        # Random words everywhere a field is (a master's writes, the device's sets).
        for name in names:
            field = bank.field(name)
            limit = 1 if field.table.is_bit else 0xFFFF
            words = [chosen.randint(0, limit) for _ in range(field.end - field.address + 1)]
            bank.write(field.table, field.address, words, device=True)
        for name in names:
            field = bank.field(name)
            words = bank.read(field.table, field.address, field.end - field.address + 1)
            got, expected = bank.get(name), decode(field, words)
            assert got == expected or (got != got and expected != expected), name  # NaN
            assert type(got) is type(expected), name


def test_a_bit_field_reads_as_a_bool() -> None:
    _, bank = _robot()
    field = bank.field("project_running")
    assert field.table is Table.DISCRETE_INPUT
    bank.write(field.table, field.address, [1], device=True)
    assert bank.get("project_running") is True
