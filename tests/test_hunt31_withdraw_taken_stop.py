"""A give-up that finds its command taken stops the arm without reading the flags twice (tmflow).

A move the robot took but whose acknowledgement no poll of the master has seen yet (a
wait given up before its first poll: ``interrupt()``, a Ctrl-C that cancels the loop's
poll mid-way) is withdrawn first: the master reads the project's flags and the program's
feedback, finds the number taken, and stops the arm. Between the two, ``withdraw()``
asks ``may_resume()``, which reads the flags again, although the read just made showed
the project running; the abandon path stops the arm and writes the cancel record after
the Stop anyway. On a slow link those two requests are arm motion before the Stop:
measured (hunt 31) with every request 0.6 s late, a Ctrl-C during ``move_to`` on
``tmflow`` pressed Stop 5.6 s after it, the arm running on for 328 mm (beats between the
reads did the rest).

Judged on what the robot received, in order: the flag block (7201) read once between the
stop request and the Stop.
"""

from __future__ import annotations

import time

import pytest

from sim_speeds import SUITE_TICK_HZ
from tmmaster import PollPolicy, Pose, Robot, StopRequestedError
from tmmaster.sim import Simulator, Timing

A = Pose(300, -200, 150, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)  # about 8 s away from A at 1 % (40 simulated s)
#: tmflow's project flags (discrete inputs) and its Stop button (a coil).
FLAGS, STOP_COIL = 7201, 7105


def test_a_taken_command_given_up_unseen_is_stopped_after_one_read_of_the_flags() -> None:
    timing = Timing(tick_hz=SUITE_TICK_HZ, init_time_s=0.02)
    with (
        Simulator("tmflow", time_scale=5.0, timing=timing) as sim,
        Robot(
            "127.0.0.1",
            sim.port,
            profile="tmflow",
            gripper=None,
            polling=PollPolicy(interval_s=0.02),
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(A, speed=100)
        motion = robot.start_move(FAR, speed=1)  # not waited for: no poll saw it taken
        sim.wait_for(lambda: sim.tcp_pose().distance_to(A) > 5, timeout=5)
        sim.clear_request_log()
        asked = time.time()
        robot.interrupt()
        with pytest.raises(StopRequestedError):
            motion.wait()
        assert motion.stop_delivered, motion
        assert not motion.withdrawn, motion
        log = [r for r in sim.request_log if r.time >= asked]
        stops = [k for k, r in enumerate(log) if (r.function_code, r.address) == (5, STOP_COIL)]
        assert stops, f"no Stop reached the robot: {log}"
        flags = [r for r in log[: stops[0]] if (r.function_code, r.address) == (2, FLAGS)]
        assert len(flags) == 1, f"the flags read {len(flags)} times before the Stop: {log}"
        assert sim.tcp_pose().distance_to(FAR) > 50, "the arm ran on to its target"
