"""The physics-backend interface, proven end to end with a second, misbehaving backend.

The master drives the simulator (in memory) exactly as it would a robot; underneath,
the test-only SlowSettlingBackend settles slowly and loses its physics view after every
motion (like an Isaac Sim scene restarted). The controller must re-initialise it and
keep commands pending meanwhile, and the master must never see a move finish early.
"""

from __future__ import annotations

import pytest

import tmmaster
from sim_backends import SlowSettlingBackend
from tmmaster import PollPolicy, Pose, TimeoutPolicy
from tmmaster.sim import Simulator, Timing

APPROACH = Pose(300, -200, 200, 180, 0, 90)
PICK = Pose(300, -200, 100, 180, 0, 90)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_moves_complete_through_slow_settling_and_reinitialisation(profile: str) -> None:
    backend = SlowSettlingBackend(
        tmmaster.robot_model("tm5-700"), settle_time_s=2.0, invalidate_after_motions=1
    )
    # 40x at 100 Hz, polled every 5 ms: 0.4 simulated s per tick and two polls per tick,
    # as at 20x, 50 Hz and 10 ms, in half the wall time; the 2 s settle is 5 ticks.
    with (
        Simulator(
            profile, time_scale=40, timing=Timing(tick_hz=100), cell=backend, listen=False
        ) as sim,
        # The article's register gripper waits its settle time for a close on nothing:
        # 0.2 s (wall) is 8 simulated s, ~20 ticks for the controller to take the close.
        tmmaster.connect(
            sim.url,
            profile=profile,
            polling=PollPolicy(interval_s=0.005),
            timeouts=TimeoutPolicy(gripper_settle_s=0.2),
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        for target in (APPROACH, PICK, APPROACH):
            motion = robot.move_to(target, speed=30, timeout=10)
            # Done only once the arm settled: the slow settle is part of the move.
            assert motion.done
            assert sim.tcp_pose().is_close(target, mm=0.01)
        assert robot.gripper.close().holding is False  # nothing at APPROACH
    # Every motion invalidated the view; the controller re-initialised it each time and
    # never sent a command into an invalid view.
    assert backend.reinitialize_count >= 3
    assert backend.rejected_commands == 0
    assert backend.motions_completed == 3
