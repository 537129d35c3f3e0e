"""``motion.wait()`` on a motion given up before it (``motion.cancel()``) says so.

docs/robot-api.md: a cancelled motion is abandoned, never done. Waiting on it polled the
robot again and reported what the give-up itself had left there, in words that blame
the robot: on ``tmflow`` a withdrawn move was "robot program rejected command N:
cancelled" and a stopped one "the TMflow project is stopped: press Play"; on
``article`` "robot reported the move finished but the TCP is ... mm from the target".
It now raises ``StopRequestedError`` at once, naming the give-up, and sends nothing.
The judge of what ran is the simulator's motion log (tests/safety_invariant.py).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from safety_invariant import Issued, check
from test_fleet import late_ack_over
from tmmaster import PollPolicy, Pose, Robot, StopRequestedError
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
A = Pose(300, -200, 200, 180, 0, 90)


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_wait_after_cancel_names_the_give_up_and_sends_nothing(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])
    with Robot(sim.url, profile=profile, polling=PollPolicy(interval_s=0.01)) as robot:
        robot.wait_until_ready(timeout_s=5)
        issued = [Issued(A, time.monotonic())]
        motion = robot.start_move(A, speed=60)
        assert motion.cancel() is True
        issued[0].ended_at, issued[0].outcome = time.monotonic(), "cancelled"
        sim.clear_faults()
        late_ack_over(sim, motion)
        sent = len(sim.request_log)
        assert sent > 0
        with pytest.raises(StopRequestedError, match="cancelled or given up"):
            motion.wait()
        assert len(sim.request_log) == sent  # nothing read, nothing written
        assert not motion.done
    check(issued, sim.motion_log())
