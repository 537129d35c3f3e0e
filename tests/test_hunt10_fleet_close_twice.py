"""Fleet.close() called by two threads at once (hunt 10: the master's own threads).

A program may close its fleet from two places that meet: the ``with Fleet()`` block
ending on the main thread while a supervisor thread (a fault handler, a signal
handler's thread, a watchdog) closes it too. ``Robot.close()`` from two threads has
the second wait for the first's clean-up and say what it found. ``Fleet.close()``
returned at once on the second call, an empty tuple, which says "every command the
fleet's robots sent can no longer run", while the first call was still stopping the
arm: a caller told the cell is safe while a robot still moves.

Here the first close's Stop (coil 7105, by address) is held by a FaultProxy, so its
first attempt times out and the stop is written again; the second ``close()`` must not
return before that Stop reached the robot. The simulator's request log and arm judge.
"""

from __future__ import annotations

import contextlib
import threading

from fault_proxy import FaultProxy, Rule
from tmmaster import Fleet, PollPolicy, Pose, Robot, TimeoutPolicy, TMMasterError
from tmmaster.sim import Simulator, Timing

FAR = Pose(250, 0, 400, 180, 0, 90)  # 1.3 s away from the home pose at speed 10
STOP = 7105


def test_a_second_fleet_close_returns_only_once_the_arm_was_stopped() -> None:
    release = threading.Event()
    # Ready at once: the robot's start-up (0.2 s at 1x) is not this test's subject.
    timing = Timing(init_time_s=0.0)
    with Simulator("tmflow", time_scale=1.0, timing=timing) as sim, FaultProxy(sim.port) as proxy:
        fleet = Fleet()
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            gripper=None,
            link=fleet,
            name="a",
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.3, ack_timeout_s=5.0, motion_margin_s=1.0),
        )
        try:
            robot.connect()
            robot.wait_until_ready(timeout_s=5)

            def move() -> None:
                with contextlib.suppress(TMMasterError):
                    robot.move_to(FAR, speed=10)

            mover = threading.Thread(target=move)
            mover.start()
            sim.wait_for(lambda: any(m.target == FAR for m in sim.motion_log()), timeout=5)
            proxy.add(Rule("hold", address=STOP, release=release))
            first = threading.Thread(target=fleet.close)
            first.start()
            sim.wait_for(lambda: proxy.played("hold"), timeout=5)  # the first close's Stop
            assert fleet.close() == ()  # the second: every command given up, it says
            stops = [r for r in sim.request_log if r.address == STOP]
            assert stops, "the second Fleet.close() returned before the arm was stopped"
            first.join(10)
            mover.join(10)
            assert not first.is_alive()
            assert not mover.is_alive()
            ticks = sim.ticks
            sim.wait_for(lambda: sim.ticks >= ticks + 25, timeout=5)  # braked to rest
            assert not sim.tcp_pose().is_close(FAR)  # stopped short of its target
        finally:
            release.set()
            fleet.close()
            robot.close()
            proxy.wait_held()
