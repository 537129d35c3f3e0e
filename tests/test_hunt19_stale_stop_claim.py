"""A run's ``stop_delivered`` speaks of its own moves, never of an earlier run's.

One ``Robot`` runs two sequences (a library user's cell loop). The first run's move
stalls (the simulator's ``stall``) and is given up: the master stops the arm
(``stop_delivered`` True). The operator presses the e-stop; the second run fails at its
start, in IDLE, and sends no move. Its result said ``stop_delivered`` True, read from
the robot's last motion, the first run's: a stop claimed for a run that moved nothing.

Found by this hunt (fails without its fix): the runner reads only a motion its own run
made. The judge for "moved nothing" is the simulator's motion log.
"""

from __future__ import annotations

from collections.abc import Callable

from sim_speeds import QUICK
from tmmaster import MotionType, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.pickplace import PlannedMove, Runner, TaskSequence
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
TARGET = Pose(300, -200, 200, 180, 0, 90)


def test_a_run_that_moved_nothing_claims_no_stop_of_an_earlier_run(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("article", faults=["stall:at_move=1"], **QUICK)
    sequence = TaskSequence("one-move")
    sequence.add("MOVE", move=PlannedMove("MOVE", TARGET, 30, MotionType.PTP))
    with Robot(
        "127.0.0.1",
        sim.port,
        profile="article",
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(motion_timeout_s=0.2),
    ) as robot:
        runner = Runner(robot)
        first = runner.run(sequence)
        assert first.failure is not None
        assert first.stop_delivered is True  # the stalled move, given up and stopped
        robot.wait_until_ready(5)
        moves = len(sim.motion_log())
        sim.press_estop()
        second = runner.run(sequence)

    assert len(sim.motion_log()) == moves  # the second run moved nothing
    assert second.failure is not None
    assert second.failure.state == "IDLE"
    assert second.stop_delivered is None, "a stop claimed for a run that moved nothing"
