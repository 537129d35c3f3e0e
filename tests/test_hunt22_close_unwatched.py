"""``Robot.close()`` leaves a move that finished while nobody polled it as it is.

docs/safety.md: the give-up "never acts after the robot reported the command finished".
A move started with ``start_move`` and never waited for (nor polled) is not known done
to the master; ``close()`` gave it up as a command still outstanding: on ``tmflow`` the
robot program's answer to the cancel record showed the number taken, so close() pressed
Stop (``stop_delivered`` True for a move that had ended at its target; the Stop ends the
TMflow project); on ``article`` the withdraw read an idle arm and reported the move
``withdrawn`` although it had run to its end. ``Motion.cancel()`` polls once first for
this reason; ``close()`` now does too. The judge: the simulator's motion log, its Stop
button's writes, its project state.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from safety_invariant import Issued, check
from test_motion_cancel import braked, finished_on_the_robot
from tmmaster import PollPolicy, Pose, Robot
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
PROFILES = ["tmflow", "article"]
A = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)
#: The TM Stop button (tmflow's coil 7105).
STOP_BUTTON = 7105


def robot_of(sim: Simulator, profile: str) -> Robot:
    return Robot(sim.url, profile=profile, polling=PollPolicy(interval_s=0.01))


def stop_presses(sim: Simulator) -> list[object]:
    return [r for r in sim.request_log if r.is_write and r.address == STOP_BUTTON]


@pytest.mark.parametrize("profile", PROFILES)
def test_close_leaves_a_move_that_finished_unwatched_as_it_is(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robot_of(sim, profile)
    robot.connect()
    robot.move_to(A, speed=100)
    issued = [Issued(A, 0.0, 0.0, "done"), Issued(A.offset(dz=20), time.monotonic())]
    motion = robot.start_move(A.offset(dz=20), speed=100)
    sim.wait_for(lambda: finished_on_the_robot(sim, profile, motion.ticket.seq), timeout=5.0)
    assert motion.done is False  # nothing polled it
    sim.clear_request_log()
    assert robot.close() is True
    issued[1].ended_at, issued[1].outcome = time.monotonic(), "done"
    # Before: tmflow (False, True, True): Stop pressed; article (True, None, False).
    assert (motion.withdrawn, motion.stop_delivered, motion.done) == (None, None, True)
    assert not motion.abandoned
    assert stop_presses(sim) == []
    if profile == "tmflow":
        assert sim.field("project_running")  # the project was not stopped
    check(issued, sim.motion_log())


@pytest.mark.parametrize("profile", PROFILES)
def test_close_still_stops_a_move_that_runs(tm_simulator_factory: SimFactory, profile: str) -> None:
    # The control: the poll first sees it running; the close stops it short.
    sim = tm_simulator_factory(profile, time_scale=5.0)
    robot = robot_of(sim, profile)
    robot.connect()
    robot.move_to(A, speed=100)
    motion = robot.start_move(FAR, speed=10)
    sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)
    issued = [Issued(A, 0.0, 0.0, "done"), Issued(FAR, 0.0)]
    assert robot.close() is True
    issued[1].ended_at, issued[1].outcome = time.monotonic(), "closed"
    assert motion.stop_delivered is True
    assert motion.abandoned
    assert not braked(sim).is_close(FAR)
    check(issued, sim.motion_log())
