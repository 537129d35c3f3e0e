"""A give-up whose withdraw cannot be read back presses Stop at once (article).

docs/safety.md: a command the master gives up on "can never start later", and a running
one is stopped. On ``article`` the withdraw of a command not yet acknowledged writes
command = none, then reads the status block to learn whether the robot had taken the
command meanwhile (the arm moving). When the robot's reads are lost (a gateway drops
every FC 03/04 request) while its writes get through, that read can never answer: the
master used to retry it for the retry policy's whole budget before it pressed Stop, and
the arm ran its whole move meanwhile, after the master had given it up. The read is now
made once: its failure presses Stop at once (harmless if the robot had not taken the
command; the command itself is never written again).

The move given up is longer than the retry budget is here (about 4 s of motion, 6 s of
retries): a master that waits out the retries finds the arm at the target. The judge is
the simulator's TCP and motion log, not what the master believes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, check
from tmmaster import Fleet, Motion, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

START = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)
#: Twice real time, FAR at SLOW %: about 4 s (wall) of motion, less than RETRY's budget.
TIME_SCALE = 2.0
SLOW = 5
RETRY = RetryPolicy(attempts=30, total_time_s=6.0, initial_backoff_s=0.05, jitter_s=0)
#: Every read the master makes of the article map (holding and input registers).
READS = (3, 4)


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("article", time_scale=TIME_SCALE)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def moving_far(
    sim: Simulator, proxy: FaultProxy, link: Fleet | None
) -> tuple[Robot, Motion, list[Issued]]:
    """An article robot behind ``proxy`` that sent the move to FAR (not yet acknowledged
    by the master: no poll since the write) and whose reads are lost from then on; the
    arm on its way."""
    robot = Robot(
        "127.0.0.1",
        proxy.port,
        profile="article",
        link=link,
        polling=PollPolicy(interval_s=0.02),
        retry=RETRY,
        timeouts=TimeoutPolicy(request_s=0.2),
    )
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    robot.move_to(START, speed=100)
    issued = [Issued(START, 0.0, 0.0, "done"), Issued(FAR, time.monotonic())]
    motion = robot.start_move(FAR, speed=SLOW)
    for function_code in READS:
        proxy.add(Rule("drop_request", function_code=function_code, times=10**6))
    sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=10)
    return robot, motion, issued


def judge(sim: Simulator, issued: list[Issued]) -> None:
    """The arm stopped short of the move given up, which ran once."""
    sim.wait_for(at_rest(sim), timeout=15, interval=0.1)
    rest = sim.tcp_pose()
    assert rest.distance_to(FAR) > 100, f"the move given up ran on to {rest}"
    assert [m.target for m in sim.motion_log()] == [START, FAR]
    check(issued, sim.motion_log())


def test_close_stops_the_arm_without_waiting_out_the_lost_reads(
    sim: Simulator, proxy: FaultProxy, driver_or_fleet: Fleet | None
) -> None:
    robot, motion, issued = moving_far(sim, proxy, driver_or_fleet)
    assert robot.close() is True  # the Stop delivered (writes pass)
    issued[1].ended_at, issued[1].outcome = time.monotonic(), "closed"
    assert motion.stop_delivered is True
    assert motion.withdrawn is False  # not known: the read that would tell was lost
    judge(sim, issued)


def test_cancel_stops_the_arm_without_waiting_out_the_lost_reads(
    sim: Simulator, proxy: FaultProxy, driver_or_fleet: Fleet | None
) -> None:
    """cancel()'s first poll (a move that finished unwatched is left as it is) is made
    once: its lost read gives the command up at once, as close()'s does."""
    robot, motion, issued = moving_far(sim, proxy, driver_or_fleet)
    with robot:
        try:
            assert motion.cancel() is True
            issued[1].ended_at, issued[1].outcome = time.monotonic(), "cancelled"
            assert motion.stop_delivered is True
            judge(sim, issued)
        finally:
            proxy.clear()
