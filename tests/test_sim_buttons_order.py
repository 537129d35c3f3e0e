"""The simulator acts on the buttons pressed within one tick in the order pressed.

TMflow acts on each press of a Robot Stick coil as it is received: 7104 Play/Pause
"Triggered as 1 received (Toggle)", 7105 Stop "Triggered as 1 received" (TMflow 2.24
Software Manual, Appendix C: Modbus List, Robot Stick, p. 313). Two presses that land
within one simulator tick are acted on in that order: a network write by its number
(RegisterBank.last_write), the pendant's Play (press_play()) after the writes received
before it. A press set on the robot's side without press_play() (a test's
``bank.set("stop_project", True)``, "the pendant's Stop") has no network write since
the buttons were released: its coil's last write is an older press, already acted on,
and ordering by it put the pendant's press before a write it came after.

Deterministic: the controller is ticked by hand, nothing runs on a thread.
"""

from __future__ import annotations

from typing import Any

import pytest

from test_sim_controller import DT, FAR, ListLogger, run, run_until, send_tmflow, tmflow
from tmmaster._registers import Table
from tmmaster.sim._bank import RegisterBank

PLAY_PAUSE, STOP = 7104, 7105


def running_project() -> tuple[Any, RegisterBank, ListLogger]:
    ctl, bank, _, log = tmflow()
    run(ctl, 0.5)
    assert ctl.project_running
    assert not ctl.project_paused
    return ctl, bank, log


def starts(log: ListLogger) -> int:
    return log.names().count("sim.project_started")


def press(bank: RegisterBank, address: int) -> None:
    """A master's press: FC05 of 1 on the coil (as a network write)."""
    bank.write(Table.COIL, address, [1])


def pendant(bank: RegisterBank, name: str) -> None:
    """A press on the robot's side, as the tests' pendant helpers make it."""
    bank.set(name, True)


@pytest.mark.parametrize("earlier_presses", [0, 1])
def test_a_written_stop_then_the_pendants_play_pause_in_one_tick_starts_over(
    earlier_presses: int,
) -> None:
    """Stop received first stops the project; the pendant's toggle after it is Play on a
    stopped project: it starts over (before 718febc too). With the coils' last writes,
    the pendant's press (no write: 0, or the master's earlier press) came first: paused,
    then stopped."""
    ctl, bank, log = running_project()
    for _ in range(2 * earlier_presses):  # the master paused and resumed, long ago
        press(bank, PLAY_PAUSE)
        run(ctl, 0.2)
    assert ctl.project_running
    assert not ctl.project_paused
    started = starts(log)
    press(bank, STOP)
    pendant(bank, "play_pause")  # tests/pendant.py press_play_pause()
    ctl.tick(DT)
    assert "sim.project_stopped" in log.names()
    assert ctl.project_running
    assert not ctl.project_paused
    assert starts(log) == started + 1  # started over


def test_a_written_pause_then_the_pendants_stop_in_one_tick_stops_the_project() -> None:
    """Pause received first, then the pendant's Stop: paused, then stopped. Stop first
    (its coil never written: 0) toggled the stopped project, starting it again."""
    ctl, bank, log = running_project()
    started = starts(log)
    press(bank, PLAY_PAUSE)
    pendant(bank, "stop_project")
    ctl.tick(DT)
    assert not ctl.project_running
    assert starts(log) == started


def test_the_pendants_play_then_a_written_stop_in_one_tick_leaves_it_stopped() -> None:
    """After an error: the operator's reset and Play, then the master's Stop received in
    the same tick. TMflow starts the project and the Stop stops it; the pendant's Play
    put after every write started a project the robot would have stopped."""
    ctl, bank, log = running_project()
    ctl.press_estop()
    run(ctl, 0.2)
    assert not ctl.project_running
    ctl.clear_error()
    run(ctl, 0.2)
    started = starts(log)
    ctl.press_play()
    press(bank, STOP)  # received after the Play
    ctl.tick(DT)
    assert not ctl.project_running
    assert starts(log) == started + 1  # started, then stopped


def test_a_written_stop_then_the_pendants_play_in_one_tick_starts_it() -> None:
    """The order 718febc fixed for press_play(): a Stop the master wrote during the error,
    then the operator's reset and Play in the same tick: the project runs."""
    ctl, bank, _ = running_project()
    ctl.press_estop()
    run(ctl, 0.2)
    ctl.clear_error()
    press(bank, STOP)
    ctl.press_play()
    ctl.tick(DT)
    assert ctl.project_running


def test_the_pendants_play_left_pending_is_not_a_later_press() -> None:
    """A pendant's Play acted on at one tick is not carried to a later tick's presses."""
    ctl, bank, log = running_project()
    ctl.press_play()  # pauses the running project
    ctl.tick(DT)
    assert ctl.project_paused
    started = starts(log)
    press(bank, STOP)
    press(bank, PLAY_PAUSE)  # a Stop, then a toggle: starts over
    ctl.tick(DT)
    assert ctl.project_running
    assert not ctl.project_paused
    assert starts(log) == started + 1
    press(bank, PLAY_PAUSE)  # a Pause, then a Stop: stopped
    press(bank, STOP)
    ctl.tick(DT)
    assert not ctl.project_running


@pytest.mark.parametrize("order", ["pause, stop", "stop, play"])
def test_written_presses_in_one_tick_in_the_order_written(order: str) -> None:
    ctl, bank, log = running_project()
    started = starts(log)
    first, second = (PLAY_PAUSE, STOP) if order == "pause, stop" else (STOP, PLAY_PAUSE)
    press(bank, first)
    press(bank, second)
    ctl.tick(DT)
    assert ctl.project_running is (order == "stop, play")
    assert starts(log) == started + (order == "stop, play")


def test_every_network_write_path_stamps_the_coils() -> None:
    """FC05 and FC15 (both coils in one request, and a release of 0) stamp last_write."""
    _, bank, _ = running_project()
    before = bank.network_writes
    bank.write(Table.COIL, PLAY_PAUSE, [1])
    assert bank.last_write("play_pause") == before + 1
    bank.write(Table.COIL, PLAY_PAUSE, [0, 1])  # FC15: a release of 7104, Stop
    assert bank.last_write("play_pause") == bank.last_write("stop_project") == before + 2
    bank.set("stop_project", True)  # the robot's side: no network write
    assert bank.last_write("stop_project") == before + 2


@pytest.mark.parametrize("stop_again", [False, True])
def test_a_play_landing_while_a_stop_brakes_the_arm_starts_the_project_once_at_rest(
    stop_again: bool,
) -> None:
    """A master's Stop, then a toggle (held in the network) in the same tick, while the
    arm moves: the project starts over once the arm is at rest, not while it brakes (the
    robot program's start-up ChangeTCP() failed on the moving arm: robot error 0x0300).
    A Stop pressed meanwhile takes the waiting start back. Hunt 42's former strict xfail,
    here on a controller ticked by hand."""
    ctl, bank, backend, log = tmflow()
    run(ctl, 0.5)
    send_tmflow(bank, 1, target=FAR, speed=100)
    run_until(ctl, lambda: not backend.is_settled())  # the arm moves
    started = starts(log)
    press(bank, STOP)
    press(bank, PLAY_PAUSE)
    ctl.tick(DT)
    assert "sim.project_stopped" in log.names()
    assert not backend.is_settled()  # it brakes
    assert not ctl.project_running  # its start waits for the arm
    if stop_again:
        press(bank, STOP)
    run_until(ctl, backend.is_settled)
    run(ctl, 2 * DT)
    assert ctl.project_running is not stop_again
    assert starts(log) == started + (0 if stop_again else 1)
    assert not bank.get("error")
