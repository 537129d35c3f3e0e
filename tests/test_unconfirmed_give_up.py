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

import asyncio
import math
import threading
import time
from collections.abc import Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from tmmaster import (
    CommandStateUnknownError,
    Fleet,
    PollPolicy,
    Pose,
    RetryPolicy,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
    TMMasterError,
    aio,
)
from tmmaster.sim import Simulator, Timing

START = Pose(300, -200, 150, 180, 0, 90)
STALE = Pose(300, -200, 180, 180, 0, 90)
NEXT = Pose(300, -180, 150, 180, 0, 90)
FAR = Pose(300, 200, 150, 180, 0, 90)  # from START: a long turn of J1
#: Writes to the robot: FC5 (Stop), FC16 (a command, its cancel record, a beat).
WRITES = (5, 15, 16)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(profile="tmflow", time_scale=20.0, timing=Timing(tick_hz=50.0)) as simulator:
        yield simulator


def robot_behind(proxy: FaultProxy, link: Fleet | None = None) -> Robot:
    """A tmflow robot whose retry policy (0.15 s) gives up well inside its TTL (5 s)."""
    return Robot(
        "127.0.0.1",
        proxy.port,
        profile="tmflow",
        gripper=None,
        link=link,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(
            request_s=0.2, ack_timeout_s=2.0, motion_margin_s=1.0, heartbeat_ttl_s=5.0
        ),
        retry=RetryPolicy(attempts=2, total_time_s=0.15, initial_backoff_s=0.02),
    )


def give_up_undelivered(
    robot: Robot, proxy: FaultProxy, issued: list[Issued], landed: threading.Event
) -> None:
    """The STALE command's write held in the network, the link down behind it: the master
    gives it up and can deliver neither its cancel record nor the Stop."""
    robot.move_to(START, speed=80)
    issued.append(Issued(START, 0.0, 0.0, "done"))
    proxy.add(Rule("hold", function_code=16, address=9000, release=landed))
    # The link goes down behind the held write: every reconnect refused, until the
    # master has given the command up.
    proxy._refusing_until = math.inf
    command = Issued(STALE, time.monotonic())
    issued.append(command)
    with pytest.raises(TMMasterError) as failed:
        robot.move_to(STALE, speed=80)
    command.outcome, command.ended_at = type(failed.value).__name__, time.monotonic()
    assert robot.last_motion is not None
    assert not robot.last_motion.withdrawn
    assert not robot.last_motion.stop_delivered
    assert not robot._heartbeat.running  # silent while the give-up is owed


def writes_since(sim: Simulator, mark: int) -> list[tuple[int, int, tuple[int, ...] | None]]:
    return [
        (r.function_code, r.address, r.values)
        for r in sim.request_log[mark:]
        if r.function_code in WRITES
    ]


def land_and_check(
    sim: Simulator, proxy: FaultProxy, landed: threading.Event, issued: list[Issued]
) -> None:
    landed.set()  # the held frame lands
    proxy.wait_held()
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + 10, timeout=5.0)  # 4 simulated s
    check(issued, sim.motion_log())


def test_a_give_up_not_delivered_is_done_once_the_link_is_back(
    sim: Simulator, driver_or_fleet: Fleet | None
) -> None:
    issued: list[Issued] = []
    landed = threading.Event()
    with FaultProxy(sim.port) as proxy, robot_behind(proxy, driver_or_fleet) as robot:
        give_up_undelivered(robot, proxy, issued, landed)
        seq = robot.last_motion.ticket.seq  # type: ignore[union-attr]
        mark = len(sim.request_log)
        proxy._refusing_until = 0.0  # the link is back
        assert robot.status().mode == "running"  # the next call reconnects
        # Before anything else: the cancel record, and the program's answer.
        assert writes_since(sim, mark) == [(16, 9014, (0, seq))]
        assert robot.last_motion.withdrawn  # type: ignore[union-attr]
        assert robot.last_motion.stop_delivered is None  # type: ignore[union-attr]
        mark = len(sim.request_log)
        robot.status()
        assert writes_since(sim, mark) == []  # delivered: nothing owed any more
        land_and_check(sim, proxy, landed, issued)


def test_a_give_up_that_fails_again_stays_owed_and_nothing_else_is_sent(
    sim: Simulator, driver_or_fleet: Fleet | None
) -> None:
    issued: list[Issued] = []
    landed = threading.Event()
    with FaultProxy(sim.port) as proxy, robot_behind(proxy, driver_or_fleet) as robot:
        give_up_undelivered(robot, proxy, issued, landed)
        session = robot._heartbeat.session
        # The link still down: a call tries the give-up again first, and says what is owed.
        with pytest.raises(CommandStateUnknownError, match="withdraw or stop is still owed"):
            robot.move_to(NEXT, speed=80)
        assert not robot._heartbeat.running
        mark = len(sim.request_log)
        proxy._refusing_until = 0.0  # the link is back
        command = Issued(NEXT, time.monotonic())
        issued.append(command)
        robot.move_to(NEXT, speed=80)
        command.outcome, command.ended_at = "done", time.monotonic()
        writes = writes_since(sim, mark)
        # The cancel record went first: then a beat of a new session, then the command.
        assert writes[0][:2] == (16, 9014)
        assert writes[1][:2] == (16, 9050)
        assert robot._heartbeat.session not in (0, session)
        assert (16, 9000) in [w[:2] for w in writes[2:]]
        land_and_check(sim, proxy, landed, issued)


def test_close_delivers_an_owed_give_up(sim: Simulator) -> None:
    issued: list[Issued] = []
    landed = threading.Event()
    with FaultProxy(sim.port) as proxy:
        robot = robot_behind(proxy).connect()
        try:
            give_up_undelivered(robot, proxy, issued, landed)
            seq = robot.last_motion.ticket.seq  # type: ignore[union-attr]
            mark = len(sim.request_log)
            proxy._refusing_until = 0.0  # the link is back
            assert robot.close(timeout_s=3.0)  # confirmed: the give-up was delivered
            assert writes_since(sim, mark) == [(16, 9014, (0, seq))]
        finally:
            robot.close()
        land_and_check(sim, proxy, landed, issued)


def test_a_give_up_delivered_leaves_nothing_owed(sim: Simulator) -> None:
    with FaultProxy(sim.port) as proxy, robot_behind(proxy) as robot:
        robot.move_to(START, speed=80)
        session = robot._heartbeat.session
        motion = robot.start_move(STALE, speed=80)
        robot.interrupt()
        with pytest.raises(StopRequestedError):
            motion.wait()
        robot.clear_stop_request()
        assert motion.withdrawn or motion.stop_delivered
        assert robot._follower.owed is None
        assert robot._heartbeat.running
        mark = len(sim.request_log)
        robot.status()
        # No give-up again: no write but the heartbeat's, of the same session.
        assert {(fc, address) for fc, address, _ in writes_since(sim, mark)} <= {(16, 9050)}
        assert robot._heartbeat.session == session


def test_an_async_robot_delivers_its_owed_give_up_first(sim: Simulator) -> None:
    issued: list[Issued] = []
    landed = threading.Event()

    async def scenario(proxy: FaultProxy) -> None:
        async with aio.AsyncRobot(robot_behind(proxy)) as robot:
            await robot.move_to(START, speed=80)
            issued.append(Issued(START, 0.0, 0.0, "done"))
            proxy.add(Rule("hold", function_code=16, address=9000, release=landed))
            proxy._refusing_until = math.inf  # the link down behind the held write
            command = Issued(STALE, time.monotonic())
            issued.append(command)
            with pytest.raises(TMMasterError) as failed:
                await robot.move_to(STALE, speed=80)
            command.outcome, command.ended_at = type(failed.value).__name__, time.monotonic()
            assert robot.robot._follower.owed is robot.robot.last_motion
            mark = len(sim.request_log)
            proxy._refusing_until = 0.0  # the link is back
            await robot.status()
            assert [w[:2] for w in writes_since(sim, mark)] == [(16, 9014)]
            assert robot.robot._follower.owed is None

    with FaultProxy(sim.port) as proxy:
        asyncio.run(asyncio.wait_for(scenario(proxy), 10.0))
        land_and_check(sim, proxy, landed, issued)


def test_a_stop_the_robot_refuses_owes_nothing() -> None:
    """Manual mode: the robot answers the Stop coil with an exception. The Stop was
    delivered (refused), and the cancel record after it ends the command (the program's
    watchdog): nothing is owed, the master beats on, nothing is written again."""
    refused = "modbus_exception:table=coil,start=7105,end=7105,code=1"
    with (
        Simulator(profile="tmflow", time_scale=5, faults=[refused]) as sim,
        Robot("127.0.0.1", sim.port, gripper=None) as robot,
    ):
        robot.move_to(START, speed=80)
        motion = robot.start_move(FAR, speed=5)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(START) > 5, timeout=5.0)
        robot.interrupt()
        with pytest.raises(StopRequestedError):
            motion.wait()
        robot.clear_stop_request()
        assert motion.stop_delivered is False
        assert robot._follower.owed is None
        assert robot._heartbeat.running
        mark = len(sim.request_log)
        robot.status()
        assert {(fc, address) for fc, address, _ in writes_since(sim, mark)} <= {(16, 9050)}


def test_a_close_that_cannot_deliver_the_give_up_sends_nothing_after(
    sim: Simulator, driver_or_fleet: Fleet | None
) -> None:
    # Robot.close() (or Fleet.close()) with the link still down: the give-up stays
    # unconfirmed and the master is gone. When the link comes back nothing of it is sent
    # (no beat, no retry); the program sees the master silent for its TTL and uses the
    # number up, so the held frame, landing after that, never runs.
    issued: list[Issued] = []
    landed = threading.Event()
    with FaultProxy(sim.port) as proxy:
        # A short TTL, so that the program sees the closed master gone soon.
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            gripper=None,
            link=driver_or_fleet,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.2, heartbeat_s=0.1, heartbeat_ttl_s=0.5),
            retry=RetryPolicy(attempts=2, total_time_s=0.15, initial_backoff_s=0.02),
        ).connect()
        try:
            give_up_undelivered(robot, proxy, issued, landed)
            seq = robot.last_motion.ticket.seq  # type: ignore[union-attr]
            if driver_or_fleet is None:
                assert robot.close(timeout_s=0.5) is False
            else:
                assert driver_or_fleet.close(timeout_s=0.5) == (robot.name,)
            mark = len(sim.request_log)
            proxy._refusing_until = 0.0  # the link is back
            sim.wait_for(lambda: sim.field("ack_seq") == seq, timeout=5.0)
        finally:
            robot.close()
        land_and_check(sim, proxy, landed, issued)
        assert [w[:2] for w in writes_since(sim, mark)] == [(16, 9000)]  # the held frame only
        assert [r.target for r in sim.motion_log()] == [START]
