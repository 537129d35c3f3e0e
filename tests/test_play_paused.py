"""Play never resumes a paused move the master pressing it does not follow.

A paused TMflow project resumes the move it interrupted at Play. A master's own paused
move (started, not given up) may resume; a move of another master (one that died within
its heartbeat's time-to-live, so the robot program's watchdog still sees a beating
master) or one this master gave up must not. The simulator runs the generated robot
program; its motion log and TCP pose are the judge.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tmmaster import Pose, Robot, RobotError
from tmmaster.sim import Simulator

LEFT = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)  # from LEFT: a long turn of J1


@pytest.fixture
def sim() -> Iterator[Simulator]:
    # The slow move takes 0.77 s of wall time (7.7 simulated seconds): paused 20 mm into
    # its 400 mm, long before its end.
    with Simulator(time_scale=10) as simulator:
        yield simulator


def let_run(sim: Simulator, ticks: int) -> None:
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


def pause_mid_move(sim: Simulator, robot: Robot) -> None:
    """A slow move to FAR, paused on the pendant once it is under way."""
    robot.move_to(LEFT, speed=50)
    robot.start_move(FAR, speed=5)
    sim.wait_for(lambda: sim.tcp_pose().distance_to(LEFT) > 20, timeout=5.0)
    sim.call(lambda: sim._controller.bank.set("play_pause", True))  # the Pause button
    sim.wait_for(lambda: sim.field("paused") == 1, timeout=5.0)
    let_run(sim, 10)  # braked to rest, paused


def test_play_from_another_master_never_resumes_a_paused_move(sim: Simulator) -> None:
    with Robot("127.0.0.1", sim.port, gripper=None) as first:
        first.wait_until_ready()
        pause_mid_move(sim, first)
        first._heartbeat.stop()  # the first master is gone (no close: no clean-up)
        # Another master at once, within the time-to-live: its heartbeat keeps the
        # program's watchdog fed, so only the master's own check refuses the Play.
        with Robot("127.0.0.1", sim.port, gripper=None) as second:
            held = sim.tcp_pose()
            with pytest.raises(RobotError, match="another master's, or given up"):
                second.play()
            let_run(sim, 20)
            assert sim.tcp_pose().is_close(held, mm=0.01, deg=0.01)
            assert len(sim.motion_log()) == 2  # LEFT, then FAR once, never resumed


def test_a_master_resumes_its_own_paused_move(sim: Simulator) -> None:
    with Robot("127.0.0.1", sim.port, gripper=None) as robot:
        robot.wait_until_ready()
        pause_mid_move(sim, robot)
        robot.play()  # the move it still follows goes on
        motion = robot.last_motion
        assert motion is not None
        motion.wait()
        assert sim.tcp_pose().is_close(FAR, mm=1.0, deg=1.0)
