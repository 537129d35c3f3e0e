"""article: a stop request during the in-flight watch of a command write in doubt.

The master watches for a lost write to land for ``in_flight_s`` (docs/safety.md,
"Uncertain writes"), the part of the article contract that can be guaranteed. A stop
request (Ctrl-C, ``robot.interrupt()``, a cancelled awaited call, ``close()``) ends that
watch at once: the command is withdrawn (``command := 0``), and the frame, landing
later but still inside the window, is a new command to the slave, which runs it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from tmmaster import PollPolicy, Pose, Robot, StopRequestedError, TimeoutPolicy
from tmmaster.sim import Simulator, Timing

START = Pose(300, -200, 150, 180, 0, 90)
STALE = Pose(300, -200, 180, 180, 0, 90)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(profile="article", time_scale=20.0, timing=Timing(tick_hz=50.0)) as simulator:
        yield simulator


@pytest.mark.xfail(
    strict=True,
    reason="design question (article): a stop request ends the in-flight watch at once and"
    " the command is withdrawn; a frame that lands after the withdraw runs, even inside"
    " in_flight_s. Watching on through the window would delay every stop request by up"
    " to in_flight_s (5 s), and a frame landing then starts the arm before it is stopped",
)
def test_a_stop_request_during_the_in_flight_watch_leaves_no_write_to_land(
    sim: Simulator,
) -> None:
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="article",
            gripper=None,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.15, in_flight_s=2.0, motion_margin_s=1.0),
        )
        with robot:
            robot.move_to(START, speed=80)
            issued.append(Issued(START, 0.0, 0.0, "done"))
            landed = threading.Event()
            proxy.add(Rule("hold", function_code=16, address=0x0200, release=landed))

            def ctrl_c() -> None:
                sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)
                robot.interrupt()  # while the write is on its way

            stopping = threading.Thread(target=ctrl_c)
            stopping.start()
            command = Issued(STALE, time.monotonic())
            issued.append(command)
            with pytest.raises(StopRequestedError):
                robot.move_to(STALE, speed=80)
            command.outcome, command.ended_at = "StopRequestedError", time.monotonic()
            stopping.join()
            landed.set()  # inside in_flight_s of the write
            proxy.wait_held()
            start = sim.ticks
            sim.wait_for(lambda: sim.ticks >= start + 10, timeout=5.0)
            check(issued, sim.motion_log())
