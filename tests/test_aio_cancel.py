"""Cancelling an awaited wait gives its move up, whatever state the call is in.

The invariant (docs/safety.md): a cancelled or interrupted call that owns or follows a
sent command withdraws or stops it before the ``CancelledError`` reaches the caller,
whether the call was queued behind another call of the robot, running, or a coroutine
cancelled before its first step. The simulator's motion log is the judge.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

import pytest

import tmmaster
from safety_invariant import Issued, check
from sim_speeds import SUITE_TICK_HZ
from test_aio import (
    NOTHING_LATER_TICKS,
    given_up,
    late_ack_over,
    moving,
    run,
    ticks_pass,
    until,
)
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy, aio
from tmmaster.sim import Simulator, Timing

SimFactory = Callable[..., Simulator]
T = TypeVar("T")

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)
PROFILES = ["article", "tmflow"]


def open_robot(sim: Simulator, **options: Any) -> aio.AsyncRobot:
    options.setdefault("polling", PollPolicy(interval_s=0.01))
    return aio.connect("127.0.0.1", sim.port, profile=sim.profile, gripper=None, **options)


class Blocker:
    """A call of the robot's that holds its thread until released (a slow link's read)."""

    def __init__(self) -> None:
        self.started = threading.Event()
        self.release = threading.Event()

    def __call__(self, robot: Robot) -> None:
        self.started.set()
        self.release.wait(5)


async def hold_the_thread(robot: aio.AsyncRobot, blocker: Blocker) -> asyncio.Task[None]:
    task = asyncio.create_task(robot.call(blocker))
    await until(blocker.started.is_set)
    return task


@pytest.mark.parametrize("profile", PROFILES)
def test_a_wait_cancelled_while_queued_withdraws_the_unacknowledged_move(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # The acknowledgement comes 20 simulated s (0.5 s) after the write: the move is
    # sent, not taken, when its wait (queued behind another call) is cancelled.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])
    issued: list[Issued] = []

    async def scenario() -> None:
        timeouts = TimeoutPolicy(ack_timeout_s=30)
        async with open_robot(sim, timeouts=timeouts) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(A, time.monotonic()))
            handle = await robot.start_move(A, speed=60)
            blocker = Blocker()
            blocked = await hold_the_thread(robot, blocker)
            waiting = asyncio.create_task(handle.wait())
            await asyncio.sleep(0.02)
            waiting.cancel()
            threading.Timer(0.1, blocker.release.set).start()
            with pytest.raises(asyncio.CancelledError):
                await waiting
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
            assert given_up(handle.motion), handle.motion
            await blocked
            sim.clear_faults()
            await late_ack_over(sim, handle.motion)  # a command still armed would run by now

    run(scenario)
    check(issued, sim.motion_log())
    assert [m.target for m in sim.motion_log() if m.target is not None] == []


@pytest.mark.parametrize("profile", PROFILES)
def test_a_wait_cancelled_while_queued_stops_the_running_move(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # Seconds long.
    sim = tm_simulator_factory(profile, time_scale=2, timing=Timing(tick_hz=SUITE_TICK_HZ))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            handle = await robot.start_move(A, speed=10)
            await until(lambda: bool(sim.motion_log()))
            blocker = Blocker()
            blocked = await hold_the_thread(robot, blocker)
            waiting = asyncio.create_task(handle.wait())
            await asyncio.sleep(0.02)
            waiting.cancel()
            threading.Timer(0.05, blocker.release.set).start()
            with pytest.raises(asyncio.CancelledError):
                await waiting
            assert handle.motion.stop_delivered is True
            await blocked

    run(scenario)
    assert [m.target for m in sim.motion_log() if m.target is not None] == [A]
    assert not sim.tcp_pose().is_close(A)  # stopped short of it (seconds away)


@pytest.mark.parametrize("profile", PROFILES)
def test_wait_for_zero_gives_the_move_up(tm_simulator_factory: SimFactory, profile: str) -> None:
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])
    issued: list[Issued] = []

    async def scenario() -> None:
        async with open_robot(sim, timeouts=TimeoutPolicy(ack_timeout_s=30)) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(A, time.monotonic()))
            handle = await robot.start_move(A, speed=60)
            with pytest.raises(TimeoutError):
                await asyncio.wait_for(handle.wait(), 0)
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "TimeoutError"
            assert given_up(handle.motion), handle.motion
            sim.clear_faults()
            await late_ack_over(sim, handle.motion)

    run(scenario)
    check(issued, sim.motion_log())
    assert [m.target for m in sim.motion_log() if m.target is not None] == []


@pytest.mark.parametrize("made", ["wait_for", "ensure_future"])
@pytest.mark.parametrize("profile", PROFILES)
def test_a_task_made_of_the_handle_itself_gives_the_move_up_cancelled_before_it_ran(
    tm_simulator_factory: SimFactory, profile: str, made: str
) -> None:
    # ``await handle`` is ``await handle.wait()``: a task made of the handle (not of its
    # wait) and cancelled before its first step gives the move up the same way.
    sim = tm_simulator_factory(profile)
    issued: list[Issued] = []

    async def scenario() -> None:
        async with open_robot(sim, timeouts=TimeoutPolicy(ack_timeout_s=30)) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(B, time.monotonic()))
            handle = await robot.start_move(B, speed=60)
            # Each task made of a handle, and each await, is a wait of its own.
            done = await asyncio.gather(handle, asyncio.ensure_future(handle))
            assert done == [handle.motion, handle.motion]
            assert (await handle).done
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "done"
            sim.inject("late_ack:delay_s=20")
            issued.append(Issued(A, time.monotonic()))
            handle = await robot.start_move(A, speed=60)
            if made == "wait_for":
                with pytest.raises(TimeoutError):
                    await asyncio.wait_for(handle, 0)
            else:
                task = asyncio.ensure_future(handle)
                task.cancel()
                with pytest.raises(asyncio.CancelledError):
                    await task
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
            assert given_up(handle.motion), handle.motion
            sim.clear_faults()
            await late_ack_over(sim, handle.motion)

    run(scenario)
    check(issued, sim.motion_log())
    assert [m.target for m in sim.motion_log() if m.target is not None] == [B]


@pytest.mark.parametrize("sibling_first", [True, False])
@pytest.mark.parametrize("profile", PROFILES)
def test_a_task_group_whose_sibling_fails_gives_the_move_up(
    tm_simulator_factory: SimFactory, profile: str, sibling_first: bool
) -> None:
    # Sibling first: the wait's task is cancelled before its first step.
    sim = tm_simulator_factory(profile, time_scale=2, timing=Timing(tick_hz=SUITE_TICK_HZ))
    issued: list[Issued] = []

    async def fails() -> None:
        raise LookupError("a sibling fails at once")

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(A, time.monotonic()))
            handle = await robot.start_move(A, speed=10)
            with pytest.raises(ExceptionGroup):  # noqa: PT012 - the group is the subject
                async with asyncio.TaskGroup() as group:
                    if sibling_first:
                        group.create_task(fails())
                    group.create_task(handle.wait())
                    if not sibling_first:
                        group.create_task(fails())
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
            assert given_up(handle.motion), handle.motion
            await ticks_pass(sim, NOTHING_LATER_TICKS)

    run(scenario)
    check(issued, sim.motion_log())
    assert not sim.tcp_pose().is_close(A)  # stopped short of it (seconds away)


def test_a_second_waiter_is_given_up_with_the_move(tm_simulator_factory: SimFactory) -> None:
    # One task waits on the move (running), a second one's wait is queued behind it;
    # cancelling the queued one gives the move up, and the running wait ends with it.
    sim = tm_simulator_factory("tmflow", time_scale=2, timing=Timing(tick_hz=SUITE_TICK_HZ))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            handle = await robot.start_move(A, speed=10)
            first = asyncio.create_task(handle.wait())
            await until(lambda: bool(sim.motion_log()))
            second = asyncio.create_task(handle.wait())
            await asyncio.sleep(0.02)
            second.cancel()
            with pytest.raises(asyncio.CancelledError):
                await second
            assert handle.motion.stop_delivered is True
            with pytest.raises(tmmaster.StopRequestedError):
                await first

    run(scenario)
    assert not sim.tcp_pose().is_close(A)


def test_an_interrupt_between_a_cancelled_calls_end_and_its_clear_stands(
    tm_simulator_factory: SimFactory,
) -> None:
    # Forced interleaving: the user's interrupt() lands while the robot's thread is
    # taking back a cancelled call's stop request. It must still stand afterwards.
    sim = tm_simulator_factory("article", time_scale=2, timing=Timing(tick_hz=SUITE_TICK_HZ))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            in_clear = threading.Event()
            interrupted = threading.Event()
            real_clear = robot.robot.clear_stop_request

            def slow_clear() -> None:
                if threading.current_thread() is not threading.main_thread():
                    in_clear.set()
                    interrupted.wait(0.3)  # the window the user's interrupt() falls in
                real_clear()

            robot.robot.clear_stop_request = slow_clear  # type: ignore[method-assign]
            task = await moving(robot, sim)
            task.cancel()
            user = threading.Thread(
                target=lambda: (in_clear.wait(5), robot.interrupt(), interrupted.set())
            )
            user.start()
            with pytest.raises(asyncio.CancelledError):
                await task
            await asyncio.to_thread(user.join, 5)
            with pytest.raises(tmmaster.StopRequestedError):
                await robot.move_to(B, speed=10)  # refused, unsent
            robot.robot.clear_stop_request = real_clear  # type: ignore[method-assign]

    run(scenario)
    assert [m.target for m in sim.motion_log() if m.target is not None] == [A]


def test_a_clear_stop_request_while_a_cancelled_call_gives_up_does_not_take_its_stop_back(
    tm_simulator_factory: SimFactory,
) -> None:
    # Forced interleaving: the user's clear_stop_request() (another part of the program
    # resuming) lands after a running move_to was cancelled, before its wait saw the stop
    # request (the driver's loop held). The move must still be stopped, not run to its end.
    sim = tm_simulator_factory("article", time_scale=2, timing=Timing(tick_hz=SUITE_TICK_HZ))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            task = await moving(robot, sim)
            loop = robot.robot._transport.fleet._runner.loop
            release = threading.Event()
            loop.call_soon_threadsafe(release.wait, 5.0)  # the wait's polls held
            task.cancel()
            await until(robot.robot._stop_event.is_set)  # the cancelled call's stop request
            robot.clear_stop_request()
            release.set()
            with pytest.raises(asyncio.CancelledError):
                await task
            assert robot.last_motion is not None
            assert robot.last_motion.stop_delivered is True
            await ticks_pass(sim, NOTHING_LATER_TICKS)  # a move still running would go on
            assert not sim.tcp_pose().is_close(A)  # stopped short of it (seconds away)
            # The user's clear took effect once the cancelled call was over.
            await robot.wait_until_ready(timeout_s=5)
            await robot.move_to(B, speed=100)

    run(scenario)
    assert [m.target for m in sim.motion_log() if m.target is not None] == [A, B]


def test_a_call_that_will_not_give_up_raises_the_cancel_after_settle_timeout_s(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # A call deaf to the stop request (a slow link's read) holds the robot's thread: the
    # CancelledError comes once settle_timeout_s is over, with an error logged, and a
    # second cancel meanwhile does not cut that wait short.
    blocker = Blocker()

    async def scenario() -> float:
        robot = aio.AsyncRobot(Robot("127.0.0.1", 502), settle_timeout_s=0.3)
        task = await hold_the_thread(robot, blocker)
        cancelled_at = time.monotonic()
        task.cancel()
        await asyncio.sleep(0.05)
        task.cancel()  # a second Ctrl-C
        with pytest.raises(asyncio.CancelledError):
            await task
        waited = time.monotonic() - cancelled_at
        blocker.release.set()
        await robot.close()
        return waited

    with caplog.at_level(logging.ERROR, logger="tmmaster.aio"):
        waited = run(scenario)
    assert waited >= 0.3  # the bound is the very feature: never raised before it
    assert any("aio.cancel_unsettled" in r.getMessage() for r in caplog.records)


def test_a_move_cancelled_while_its_write_is_held_in_the_network_never_runs() -> None:
    # tmflow: the task is cancelled while its command write is stuck in the network. The
    # write times out, the master reads back, finds nothing, and may not resend (a stop
    # is requested): it cancels the number before the CancelledError, and the frame that
    # lands afterwards never runs.
    from fault_proxy import FaultProxy, Rule

    async def scenario() -> None:
        issued: list[Issued] = []
        with (
            Simulator("tmflow", time_scale=20.0, timing=Timing(tick_hz=50.0)) as sim,
            FaultProxy(sim.port) as proxy,
        ):
            async with aio.connect(
                "127.0.0.1",
                proxy.port,
                gripper=None,
                timeouts=TimeoutPolicy(request_s=0.15, ack_timeout_s=0.5, motion_margin_s=1.0),
                polling=PollPolicy(interval_s=0.01),
            ) as robot:
                await robot.move_to(A, speed=80)
                issued.append(Issued(A, 0.0, 0.0, "done"))
                release = threading.Event()
                proxy.add(Rule("hold", function_code=16, address=9000, release=release))
                issued.append(Issued(B, time.monotonic()))
                task = asyncio.ensure_future(robot.move_to(B, speed=80))
                await until(lambda: proxy.played("hold"))
                task.cancel()
                with pytest.raises(asyncio.CancelledError):
                    await task
                issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
                assert given_up(robot.last_motion)
                release.set()  # the held frame lands now
                await asyncio.to_thread(proxy.wait_held)
                ticks = sim.ticks
                await asyncio.to_thread(sim.wait_for, lambda: sim.ticks >= ticks + 10, timeout=5.0)
            check(issued, sim.motion_log())
            assert [r.target for r in sim.motion_log() if r.target is not None] == [A]

    run(scenario)
