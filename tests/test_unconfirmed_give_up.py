"""A tmflow command whose give-up could not be delivered must not run once the link is back.

The command write is held in the network and the link goes down right behind it. The
master gives the command up (its write is in doubt) but cannot deliver the cancel record
nor the Stop: the retry policy gave up first. Where the policy's budget is shorter than
the heartbeat's time-to-live, the robot program never saw the master go silent, so the
number is not used up; once the link is back the master beats again, and the held frame,
landing then, carries the next number of a live master. The simulator runs the
generated robot program; its motion log is the judge.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from tmmaster import PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy, TMMasterError
from tmmaster.sim import Simulator, Timing

START = Pose(300, -200, 150, 180, 0, 90)
STALE = Pose(300, -200, 180, 180, 0, 90)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(profile="tmflow", time_scale=20.0, timing=Timing(tick_hz=50.0)) as simulator:
        yield simulator


@pytest.mark.xfail(
    strict=True,
    reason="design question: a give-up whose cancel record and Stop could not be delivered"
    " (the retry policy gave up, logged robot.withdraw_failed / robot.stop_failed) is not"
    " done again when the link is back, and the master beats again, keeping the number"
    " of the frame still in the network alive; with the default policy (10 s) the"
    " program has seen the master silent for longer than its time-to-live by then",
)
def test_a_give_up_not_delivered_is_done_once_the_link_is_back(sim: Simulator) -> None:
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            gripper=None,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(
                request_s=0.2, ack_timeout_s=0.5, motion_margin_s=1.0, heartbeat_ttl_s=5.0
            ),
            retry=RetryPolicy(attempts=3, total_time_s=0.3, initial_backoff_s=0.02),
        )
        with robot:
            robot.move_to(START, speed=80)
            issued.append(Issued(START, 0.0, 0.0, "done"))
            landed = threading.Event()
            proxy.add(Rule("hold", function_code=16, address=9000, release=landed))
            # The link goes down behind the held write: every reconnect refused, until
            # the master has given the command up.
            proxy._refusing_until = math.inf
            command = Issued(STALE, time.monotonic())
            issued.append(command)
            with pytest.raises(TMMasterError) as failed:
                robot.move_to(STALE, speed=80)
            command.outcome, command.ended_at = type(failed.value).__name__, time.monotonic()
            assert robot.last_motion is not None
            assert not robot.last_motion.withdrawn
            assert not robot.last_motion.stop_delivered
            proxy._refusing_until = 0.0  # the link is back
            assert robot.status().mode == "running"  # the next call reconnects
            landed.set()  # the held frame lands
            proxy.wait_held()
            start = sim.ticks
            sim.wait_for(lambda: sim.ticks >= start + 10, timeout=5.0)  # 4 simulated s
            check(issued, sim.motion_log())
