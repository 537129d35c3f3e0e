"""A motion timeout's Stop does not wait out the retries of a read for its report (tmflow).

``Motion.wait(timeout_s)`` on a long move: at the deadline the master gives the move up and
stops the arm. Before that Stop it read the TCP pose for the timeout's message, with the
retry policy: where that read goes unanswered (a link that stalls one request), the arm
ran on for the retry policy's whole budget before its Stop went (measured with the cell
below: 4 attempts of 1 s, the Stop about 4.6 s after the deadline; with the default
policy, 12 attempts in 10 s). A read for a report is now made once: the Stop follows
within one request timeout, as ``Motion.cancel()``'s (``tests/test_lostreads_giveup.py``).

Judged on what the robot received, in order (the proxy's log of the requests it got):
at most one pose read between the wait and the Stop, and the Stop delivered.
"""

from __future__ import annotations

import time

import pytest

from fault_proxy import FaultProxy, Rule
from sim_speeds import SUITE_TICK_HZ
from tmmaster import MotionTimeoutError, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy
from tmmaster.sim import Simulator, Timing

A = Pose(300, -200, 150, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)  # about 8 s away from A at 1 % (40 simulated s)
#: tmflow's registers: the TCP pose (input registers), the Stop button (a coil).
POSE, STOP_COIL = 7025, 7105


def test_a_motion_timeout_stops_the_arm_before_retrying_a_report_read() -> None:
    timing = Timing(tick_hz=SUITE_TICK_HZ, init_time_s=0.02)
    with (
        Simulator("tmflow", time_scale=5.0, timing=timing) as sim,
        FaultProxy(sim.port) as proxy,
        Robot(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            gripper=None,
            polling=PollPolicy(interval_s=0.02),
            retry=RetryPolicy(attempts=4, total_time_s=8.0, initial_backoff_s=0.05, jitter_s=0),
            timeouts=TimeoutPolicy(request_s=1.0),
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(A, speed=100)
        motion = robot.start_move(FAR, speed=1)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(A) > 5, timeout=5)
        # Every read of the TCP pose from now on goes unanswered (the polls of a move
        # this far from its end do not read it).
        proxy.add(Rule("drop_request", function_code=4, address=POSE, times=10**9))
        began = time.monotonic()
        with pytest.raises(MotionTimeoutError):
            motion.wait(timeout_s=0.3)
        assert motion.stop_delivered, motion
        seen = [s for s in proxy.seen if s.time >= began]
        stops = [k for k, s in enumerate(seen) if (s.function_code, s.address) == (5, STOP_COIL)]
        assert stops, f"no Stop reached the robot: {seen}"
        poses = [s for s in seen[: stops[0]] if (s.function_code, s.address) == (4, POSE)]
        assert len(poses) <= 1, f"the Stop waited for {len(poses)} attempts of a pose read"
        stopped = sim.tcp_pose()
        assert stopped.distance_to(FAR) > 50, f"the arm ran on to {stopped}"
