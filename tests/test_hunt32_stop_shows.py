"""Play after ``close()`` stopped the arm: the next Robot waits for that Stop to show.

Hunt 32. ``close()`` of a tmflow robot whose arm moves presses Stop and returns once the
Stop is answered: the controller takes it at its next cycle, so the project still shows
running for a moment. A script that then opens a new ``Robot`` on the same robot and
calls ``play()`` (the documented way after a close: a closed Robot does not connect
again) had ``play()`` read the project still running, press nothing and return RUNNING;
the Stop then landed, the project stopped, and the next move failed with "the TMflow
project is stopped" (found by ``test_hunt32_same_robot``'s close case, one run in a few).
The wait for a Stop not shown yet was the closed Robot's own; it is now kept per robot
address for the process, as an owed Stop is.

The first Robot presses Stop (``stop()``, as its ``close()`` does for a moving arm; alone
here, so that no cancel record's watchdog stops the project first) and is closed. The
Stop's frame is held in the network after a gateway answered it (``answer_now``), and
lands when the new Robot's ``play()`` first reads: the moment between the answer and
the controller's cycle, made to last, with no timing in the test.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, ProjectState, Robot
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

START = Pose(220, -200, 200, 180, 0, 90)
NEXT = Pose(300, 0, 180, 180, 0, 90)
STOP_COIL = 7105


def through(proxy: FaultProxy) -> Robot:
    robot = Robot("127.0.0.1", proxy.port, profile="tmflow", polling=PollPolicy(interval_s=0.01))
    robot.connect()
    return robot


def test_play_after_close_waits_for_the_closed_robots_stop(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow", **QUICK)
    issued: list[Issued] = []
    landed = threading.Event()
    with FaultProxy(sim.port) as proxy:
        with through(proxy) as first:
            first.wait_until_ready(timeout_s=5)
            first.move_to(START, speed=50)
            issued.append(Issued(START, 0.0, 0.0, "done"))
            proxy.add(
                Rule("hold", function_code=5, address=STOP_COIL, release=landed, answer_now=True)
            )
            # The Stop a close() presses for a moving arm (here alone: no command in
            # flight, no cancel record whose watchdog would stop the project first).
            first.stop()
            assert first.close()
        assert proxy.played("hold")
        with through(proxy) as second:
            mark = len(sim.request_log)

            def land_at_the_first_read() -> None:
                sim.wait_for(
                    lambda: any(r.function_code in (1, 2, 3, 4) for r in sim.request_log[mark:]),
                    timeout=5.0,
                )
                landed.set()

            helper = threading.Thread(target=land_at_the_first_read)
            helper.start()
            try:
                assert second.play() is ProjectState.RUNNING
            finally:
                landed.set()
                helper.join()
            proxy.wait_held()
            ticks = sim.ticks
            sim.wait_for(lambda: sim.ticks >= ticks + 5, timeout=5.0)
            # play() told the truth: the project runs, the Stop having landed before it.
            assert sim.field("project_running")
            assert second.project_state() is ProjectState.RUNNING
            second.wait_until_at_rest()
            issued.append(Issued(NEXT, 0.0))
            second.move_to(NEXT, speed=30)
            issued[-1].outcome = "done"
    assert sim.tcp_pose().is_close(NEXT, mm=0.05)
    check(issued, sim.motion_log())
