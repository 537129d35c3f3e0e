"""A stop request made on the robot is not taken back by a pick & place run.

``Robot.interrupt()``: "until clear_stop_request(), no new command is written either".
A run started while such a request stands (another thread's ``robot.interrupt()``, a
cancelled awaited call, a Ctrl-C handler of the user's) must end interrupted without
moving: the check is on what the simulated robot did (its motion log).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, Robot
from tmmaster.pickplace import ERROR, Runner, StateEvent, TaskSequence
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
ABOVE = Pose(300.0, -200.0, 200.0, 180.0, 0.0, 90.0)


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: SimFactory) -> SimFactory:
    """The runner is the subject here, not TCP: simulators in memory."""
    return memory_simulator_factory


def one_move() -> TaskSequence:
    seq = TaskSequence("one-move")
    seq.add("MOVE", lambda ctx: ctx.move(ABOVE, speed=30))
    return seq


def test_a_run_started_after_robot_interrupt_does_not_move(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow", **QUICK)
    with Robot(sim.url, polling=PollPolicy(interval_s=0.01)) as robot:
        robot.wait_until_ready(5.0)
        robot.interrupt()
        result = Runner(robot).run(one_move())
    assert result.interrupted
    assert result.state == ERROR
    assert sim.motion_log() == ()


def test_a_robot_interrupt_between_runs_is_not_taken_back(
    tm_simulator_factory: SimFactory,
) -> None:
    # A loop of one-cycle runs: a stop requested on the robot during one run (here by
    # its state callback, as another thread's robot.interrupt() would) ends that run,
    # and the next run must not clear it and move.
    sim = tm_simulator_factory("article", **QUICK)
    with Robot(sim.url, profile="article", polling=PollPolicy(interval_s=0.01)) as robot:
        robot.wait_until_ready(5.0)
        runner = Runner(robot)

        def on_state(event: StateEvent) -> None:
            if event.state == "MOVE":
                robot.interrupt()

        runner.on_state = on_state
        first = runner.run(one_move())
        runner.on_state = None
        ticks = sim.ticks  # the first run's stop (robot.stop()) is taken meanwhile
        sim.wait_for(lambda: sim.ticks >= ticks + 3, 5.0)
        second = runner.run(one_move())
    assert first.interrupted
    assert second.interrupted
    assert sim.motion_log() == ()
