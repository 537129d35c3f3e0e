"""A stop requested while ``Runner.run()`` checks its plan ends the run there.

``Runner.run()`` checks every known move of the run before its first command (hunt 21).
A long pallet's check takes seconds (500 slots: 7.5 s measured on the CI's two cores),
and the check did not look at the stop request: Ctrl-C (the CLI's first one calls
``runner.request_stop()``) or another thread's ``request_stop()`` waited for the whole
check to end before the run noticed it. Now the check ends before its next move, and
the run ends interrupted in IDLE, nothing moved.

The stop lands deterministically: from inside the check itself (as a signal handler
does), on the check of a chosen move. The judge of "nothing moved" is the simulator's
request and motion logs.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from typing import Any

import pytest

import tmmaster
from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, Robot, StopRequestedError, TimeoutPolicy
from tmmaster.pickplace import (
    ARTICLE_PICK,
    IDLE,
    Pallet,
    Runner,
    palletizing,
    validate_plan,
)
from tmmaster.sim import Cell, Simulator, TableObject

SimFactory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
#: The tmflow command register (a move's or the gripper's command code).
COMMAND_REGISTER = 9014
#: 4 x 4 slots, 2 layers: 32 cycles, about 160 distinct moves to check.
PALLET = Pallet(
    origin=Pose(350, 100, 100, 180, 0, 90), rows=4, cols=4, dx=20, dy=20, layers=2, dz=5
)
#: The check of this move (1-based) requests the stop.
STOP_AT = 7


@pytest.fixture
def sim(memory_simulator_factory: SimFactory) -> Simulator:
    return memory_simulator_factory(
        "tmflow", cell=Cell(scene=[TableObject(name="part-1", pose=PICK)]), **QUICK
    )


@pytest.fixture
def robot(sim: Simulator) -> Iterator[Robot]:
    with Robot(
        sim.url,
        profile="tmflow",
        polling=PollPolicy(interval_s=0.02),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as r:
        sim.clear_request_log()
        yield r


def counting_checks(
    robot: Robot, monkeypatch: pytest.MonkeyPatch, on_check: Callable[[int], None]
) -> list[int]:
    """Wrap ``robot.check_move``: ``on_check(n)`` before the n-th check; returns the list
    of the numbers of the checks made."""
    made: list[int] = []
    real = robot.check_move

    def check_move(*args: Any, **kwargs: Any) -> tuple[float, ...]:
        made.append(len(made) + 1)
        on_check(len(made))
        return real(*args, **kwargs)

    monkeypatch.setattr(robot, "check_move", check_move)
    return made


def commands(sim: Simulator) -> list[object]:
    return [
        r
        for r in sim.request_log
        if r.is_write and r.address <= COMMAND_REGISTER < r.address + r.count
    ]


def test_a_stop_during_the_plan_check_ends_the_run_there_with_nothing_moved(
    sim: Simulator, robot: Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    sequence = palletizing(pick=PICK, pallet=PALLET, home=tmmaster.DEFAULT_HOME)
    runner = Runner(robot)
    stopped_at: list[int] = []

    def stop_on_the_chosen_check(n: int) -> None:
        if n == STOP_AT:
            stopped_at.append(n)
            runner.request_stop()

    made = counting_checks(robot, monkeypatch, stop_on_the_chosen_check)
    motions = len(sim.motion_log())
    result = runner.run(sequence)
    assert stopped_at == [STOP_AT]
    # Before the fix: every one of the ~160 checks was made after the stop request.
    assert len(made) == STOP_AT, f"{len(made) - STOP_AT} moves checked after the stop request"
    failure = result.failure
    assert failure is not None
    assert failure.interrupted
    assert (failure.state, failure.cycle, result.cycles_completed) == (IDLE, 0, 0)
    assert "during the check of the plan" in failure.message
    assert commands(sim) == [], "a command was sent after the stop request"
    assert len(sim.motion_log()) == motions, "the robot moved"
    assert not any(o.held for o in sim.objects())


def test_validate_plan_ends_at_the_next_move_once_its_stop_is_set(robot: Robot) -> None:
    sequence = palletizing(pick=PICK, pallet=PALLET, home=tmmaster.DEFAULT_HOME)
    stop = threading.Event()
    assert validate_plan(robot, sequence, 2, source="pallet") > 0  # it passes unstopped
    stop.set()
    with pytest.raises(StopRequestedError, match=r"check of the plan \(pallet\)"):
        validate_plan(robot, sequence, 2, source="pallet", stop=stop)


def test_a_stop_after_the_check_still_ends_the_run_in_idle(
    sim: Simulator, robot: Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The control: a check that ends before the stop (as every short plan's does) is
    # unchanged; the request stops the run before its first command.
    sequence = palletizing(pick=PICK, pallet=PALLET, home=tmmaster.DEFAULT_HOME)
    runner = Runner(robot)
    made = counting_checks(robot, monkeypatch, lambda _n: None)
    motions = len(sim.motion_log())
    runner.request_stop()
    result = runner.run(sequence)
    assert made == []  # the run ended before its check
    assert result.failure is not None
    assert result.failure.interrupted
    assert result.failure.state == IDLE
    assert commands(sim) == []
    assert len(sim.motion_log()) == motions
