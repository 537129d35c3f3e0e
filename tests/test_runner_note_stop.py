"""A stop noted by a Ctrl-C's handler (``Runner.note_stop``), before its thread has set
the stop request, ends the run where the request itself ends it.

The sequence machine's guard (``may_continue``) read only the stop event: with only the
flag set, the finished state's ``advance`` was taken, the next state entered (logged,
shown on the live display, a next cycle begun) and failed at once, so the run reported a
state, or a cycle, it never worked in. The machine now reads the runner's
``stop_requested``. Deterministic: the stop is asked for from the state's own action.
Found by the review of the note_stop change (both note_stop cases failed without it).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from tmmaster import EmergencyStopError, PollPolicy, Robot, RobotError, RobotFaultError
from tmmaster.pickplace import Runner, StateEvent, StepContext, TaskSequence
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]


@pytest.fixture
def robot(memory_simulator_factory: SimFactory) -> Iterator[Robot]:
    sim = memory_simulator_factory("article")
    with Robot(sim.url, profile="article", polling=PollPolicy(interval_s=0.02)) as r:
        yield r


def _two_states(stop: Callable[[], None]) -> TaskSequence:
    """A: asks for the stop (as a Ctrl-C during its move would); B: does nothing."""
    seq = TaskSequence("two")

    def a(_ctx: StepContext) -> None:
        stop()

    seq.add("A", a)
    seq.add("B", lambda _ctx: None)
    return seq


@pytest.mark.parametrize("how", ["request_stop", "note_stop"])
def test_a_stop_in_a_state_fails_that_state_however_it_was_asked(robot: Robot, how: str) -> None:
    events: list[StateEvent] = []
    runner = Runner(robot, on_state=events.append)
    result = runner.run(_two_states(getattr(runner, how)), cycles=2)
    assert result.interrupted
    assert result.failure is not None
    entered = [(e.state, e.cycle) for e in events]
    # The request: failed in A, cycle 1, B never entered. The noted stop must say the same.
    assert (result.failure.state, result.failure.cycle) == ("A", 1), entered
    assert ("B", 1) not in entered, entered


@pytest.mark.parametrize("how", ["request_stop", "note_stop"])
def test_a_stop_in_a_cycles_last_state_begins_no_next_cycle(robot: Robot, how: str) -> None:
    events: list[StateEvent] = []
    runner = Runner(robot, on_state=events.append)
    seq = TaskSequence("two")
    seq.add("A", lambda _ctx: None)

    def b(_ctx: StepContext) -> None:
        getattr(runner, how)()

    seq.add("B", b)
    result = runner.run(seq, cycles=2)
    assert result.interrupted
    assert result.failure is not None
    entered = [(e.state, e.cycle) for e in events]
    assert (result.failure.state, result.failure.cycle) == ("B", 1), entered
    assert ("A", 2) not in entered, entered


@pytest.mark.parametrize(
    ("fault", "reported"),
    [
        (EmergencyStopError("emergency stop is pressed"), "EmergencyStopError"),
        (RobotFaultError("robot in error (mode error)", error_code=0x0200), "RobotFaultError"),
        (RobotFaultError("the TMflow project is stopped"), "StopRequestedError"),
        (RobotError("reported the move finished but the TCP is at ..."), "StopRequestedError"),
    ],
)
def test_a_fault_the_robot_reports_is_not_relabelled_as_the_stop(
    robot: Robot, fault: RobotError, reported: str
) -> None:
    """A Ctrl-C noted while the robot reports its own fault (an e-stop pressed as the
    operator hits Ctrl-C): the run's failure is the fault, which a Stop never causes, not
    "stop requested". What a stop does cause (the project stopped, a move ended short) is
    still the stop. Review finding (P1): every failure became the stop once the flag was
    set."""
    runner = Runner(robot)

    def step(_ctx: StepContext) -> None:
        runner.note_stop()
        raise fault

    seq = TaskSequence("fault")
    seq.add("A", step)
    result = runner.run(seq)
    assert result.failure is not None
    assert result.failure.type == reported, result.failure
