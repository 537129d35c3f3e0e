"""A stalled arm is raised within the budget the master announced; a slow one ends done.

The derived timeout grows with the pace the polls observe only while the arm keeps
moving; the simulator's ``stall`` fault stops a move halfway, and the robot stays busy.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

import tmmaster
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.sim import Cell, Simulator

SimFactory = Callable[..., Simulator]

START = Pose(300, -200, 300, 180, 0, 90)
TARGET = Pose(300, -50, 300, 180, 0, 90)  # a 150 mm line


def robot_on(sim: Simulator, profile: str, *, motion_margin_s: float) -> Robot:
    """A robot whose derived timeouts are the model's time and ``motion_margin_s``."""
    return Robot(
        "127.0.0.1",
        sim.port,
        profile=profile,
        gripper=None,
        timeouts=TimeoutPolicy(motion_factor=1.0, motion_margin_s=motion_margin_s),
        polling=PollPolicy(interval_s=0.02),
    )


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_stalled_line_is_raised_within_its_announced_timeout(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # Real time: the model's expected time is the simulated arm's (the stall is the
    # only difference), so the polls see the pace drop to nothing halfway.
    sim = tm_simulator_factory(profile, faults=["stall:at_move=2"], time_scale=1.0)
    with robot_on(sim, profile, motion_margin_s=0.6) as robot:
        robot.wait_until_ready(5)
        robot.move_to(START, speed=100)
        motion = robot.start_move(TARGET, speed=60, motion="line")
        with pytest.raises(tmmaster.MotionTimeoutError) as info:
            motion.wait()
        raised_at = time.monotonic()
    acked_at = motion.ticket.acknowledged_at
    assert acked_at is not None
    announced = motion.timeout_s
    # Within the announced budget, where the observed pace used to stretch it up to 4
    # times. Beyond the budget: a poll, the error's own pose read and the stop, 5-15 ms
    # here on an idle machine, once 0.29 s with the suite's four workers on two cores;
    # half the budget covers that and still refuses the old 4 times.
    assert raised_at - acked_at <= 1.5 * announced, (raised_at - acked_at, announced)
    message = str(info.value)
    assert f"within {announced:.2f} s" in message
    assert "a stall" in message or "no progress" in message


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_an_arm_eight_times_slower_than_the_model_still_ends_done(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # An arm that keeps moving is given the time its pace asks for, up to 20 times the
    # model's budget (a project speed of 5 %): here 8 times, past the 4 it once was.
    sim = tm_simulator_factory(profile, cell=Cell(speed_factor=0.125), time_scale=1.0)
    with robot_on(sim, profile, motion_margin_s=0.1) as robot:
        robot.wait_until_ready(5)
        target = sim.tcp_pose().offset(dy=15)
        motion = robot.move_to(target, speed=100, motion="line")
        assert motion.done
        assert time.monotonic() - (motion.ticket.acknowledged_at or 0.0) > 4 * motion.timeout_s
    assert sim.tcp_pose().is_close(target)
