"""article: the operator's reset while the arm still brakes from an e-stop.

Hunt 32. The simulated article controller reports ``motion_status`` 1 while an arm
stopped by an error still brakes, and 0 once it is at rest; but only while the error
lasts. A reset (``clear_error``, the pendant) that came while the arm still braked left
``motion_status`` at 1 for good: the master then read a robot moving forever, its
``wait_until_at_rest()`` timed out, and the same Robot's next move was refused as busy
(found by ``test_hunt32_same_robot``: an e-stop then its reset, one run in a few at
100x). The e-stop and the reset are made in one call on the simulator's thread, so the
reset lands while the arm brakes whatever the machine's speed.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from safety_invariant import Issued, at_rest, check
from tmmaster import PollPolicy, Pose, Robot, RobotError
from tmmaster.sim import Simulator, Timing

SimFactory = Callable[..., Simulator]

START = Pose(220, -200, 200, 180, 0, 90)
FAILED = Pose(220, 200, 250, 180, 0, 90)
NEXT = Pose(300, 0, 180, 180, 0, 90)


def estop_and_reset(sim: Simulator) -> None:
    """The e-stop, and the operator's reset at once: the arm still brakes."""

    def both() -> None:
        sim._controller.press_estop()
        assert not sim.backend.is_settled()  # braking
        sim._controller.clear_error()

    sim.call(both)


def test_a_reset_while_the_arm_brakes_ends_in_rest(tm_simulator_factory: SimFactory) -> None:
    # 10x, not QUICK's 100x: the move lasts some 0.3 s, so the arm still moves when the
    # test's thread sees it under way and presses the e-stop, however loaded the machine.
    sim = tm_simulator_factory("article", time_scale=10.0, timing=Timing(tick_hz=25.0))
    issued = [Issued(START, 0.0, 0.0, "done"), Issued(FAILED, 0.0)]
    with Robot(sim.url, profile="article", polling=PollPolicy(interval_s=0.01)) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(START, speed=50)
        motion = robot.start_move(FAILED, speed=20, timeout=1.0)
        sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=5.0)
        estop_and_reset(sim)
        sim.wait_for(at_rest(sim), timeout=5.0)
        # Stopped short of FAILED, the error gone before the master looked: never done.
        with pytest.raises(RobotError, match="reported the move finished but the TCP is at"):
            motion.wait()
        issued[-1].outcome = "stopped"
        assert not motion.done
        sim.wait_for(lambda: sim.field("motion_status") == 0, timeout=2.0)
        assert not robot.status().moving
        robot.wait_until_at_rest()
        issued.append(Issued(NEXT, 0.0))
        robot.move_to(NEXT, speed=30)
        issued[-1].outcome = "done"
    assert sim.tcp_pose().is_close(NEXT, mm=0.05)
    check(issued, sim.motion_log())
