"""A move the master gave up stays given up where the robot refuses the master's Stop.

TMflow takes the Stop coil (7105) over Modbus only in Auto mode with remote control
("cannot be written to when the robot is in Manual Mode", TMflow 2.24, 12.1, p. 219;
the Robot Stick note, appendix C, p. 314). The simulated robot here answers every write
of that coil with a Modbus exception, as such a robot does, and runs the generated robot
program; its TCP pose and motion record are the judge.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from pendant import press_play_pause
from tmmaster import Pose, ProjectPausedError, ResponseTimeoutError, Robot, StopRequestedError
from tmmaster.sim import Simulator

LEFT = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)  # from LEFT: a long turn of J1
STOP_REFUSED = "modbus_exception:table=coil,start=7105,end=7105,code=1"


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(time_scale=5, faults=[STOP_REFUSED]) as simulator:
        yield simulator


def let_run(sim: Simulator, ticks: int) -> None:
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


@pytest.mark.parametrize("how", ["interrupt", "pause"])
def test_a_move_given_up_never_goes_on_when_the_stop_coil_is_refused(
    sim: Simulator, how: str
) -> None:
    with Robot("127.0.0.1", sim.port, gripper=None) as robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)
        motion = robot.start_move(FAR, speed=5)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(LEFT) > 20, timeout=5.0)
        if how == "interrupt":
            robot.interrupt()  # the user's stop: the master gives the move up
        else:
            press_play_pause(sim)  # the operator pauses (Manual mode: the enabling switch)
        expected = StopRequestedError if how == "interrupt" else ProjectPausedError
        with pytest.raises(expected):
            motion.wait()
        assert motion.abandoned
        assert motion.stop_delivered is False  # the robot refused the Stop coil
        let_run(sim, 10)  # 4 simulated s: braked to rest
        if how == "pause":
            sim.press_play()  # the operator's Play after the master gave the move up
            let_run(sim, 5)
        held = sim.tcp_pose()
        let_run(sim, 20)
        assert sim.tcp_pose().is_close(held, mm=0.01, deg=0.01)  # not moving any more
        assert not held.is_close(FAR, mm=1.0, deg=1.0)
        assert len(sim.motion_log()) == 2  # LEFT, then FAR once: never started again


def test_a_cancel_record_that_fails_never_keeps_the_stop_from_going_out(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The other way round: the robot takes the Stop, but the cancel record's write fails
    # (a lossy link). The Stop is the arm's first way to stop: it must still go out.
    with (
        Simulator(time_scale=5) as sim,
        Robot("127.0.0.1", sim.port, gripper=None) as robot,
    ):
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)

        def lost(ticket: object) -> None:
            raise ResponseTimeoutError("the cancel record's write went unanswered")

        monkeypatch.setattr(robot._channel, "cancel", lost)
        motion = robot.start_move(FAR, speed=5)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(LEFT) > 20, timeout=5.0)
        robot.interrupt()
        with pytest.raises(StopRequestedError):
            motion.wait()
        assert motion.stop_delivered is True
        let_run(sim, 10)  # 4 simulated s: braked to rest
        held = sim.tcp_pose()
        let_run(sim, 20)
        assert sim.tcp_pose().is_close(held, mm=0.01, deg=0.01)
        assert not held.is_close(FAR, mm=1.0, deg=1.0)
        assert len(sim.motion_log()) == 2
