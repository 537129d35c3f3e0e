"""review2: cancel()'s one-attempt poll must not wait out the retries of its pose read.

67b3f6f made cancel()'s first poll a single attempt, so that where the robot's reads
are lost the arm is not left running for the retry policy's whole budget before the
give-up stops it. On tmflow the poll reads the feedback (FC 03) and the status bits
(FC 02); the pose (input registers, FC 04) is read after it by
``_MotionFollower.poll`` through ``read_pose()``, which still retries. A gateway that
loses the input-register reads (and passes the rest) then holds cancel() for the whole
budget while the arm runs its move to the end, after the master gave it up (here the
program's heartbeat expiry, its own safety net, is set longer than the retries). The
judge is the simulator's arm and motion log.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, check
from test_lostreads_giveup import FAR, RETRY, SLOW, START, TIME_SCALE
from tmmaster import PollPolicy, Robot, TimeoutPolicy
from tmmaster.sim import Simulator


@pytest.fixture
def sim(tm_simulator_factory: object) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=TIME_SCALE)  # type: ignore[operator, no-any-return]


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def test_cancel_stops_the_arm_without_waiting_out_a_lost_pose_read(
    sim: Simulator, proxy: FaultProxy
) -> None:
    robot = Robot(
        "127.0.0.1",
        proxy.port,
        profile="tmflow",
        polling=PollPolicy(interval_s=0.02),
        retry=RETRY,
        # The program's heartbeat expiry (its own safety net) longer than the retries.
        timeouts=TimeoutPolicy(request_s=0.2, heartbeat_ttl_s=10),
    )
    with robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(START, speed=100)
        issued = [Issued(START, 0.0, 0.0, "done"), Issued(FAR, time.monotonic())]
        motion = robot.start_move(FAR, speed=SLOW)
        sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=10)
        proxy.add(Rule("drop_request", function_code=4, times=10**6))  # input registers
        try:
            motion.cancel()
            issued[1].ended_at, issued[1].outcome = time.monotonic(), "cancelled"
            sim.wait_for(at_rest(sim), timeout=15, interval=0.1)
        finally:
            proxy.clear()
        rest = sim.tcp_pose()
        assert rest.distance_to(FAR) > 100, f"the move given up ran on to {rest}"
        check(issued, sim.motion_log())
