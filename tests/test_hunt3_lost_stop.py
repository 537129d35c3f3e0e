"""A running move whose Stop the link could not carry is stopped once the link is back.

docs/safety.md: a move the master gives up because the link was lost is "stopped, once
the link is back". On ``tmflow`` a give-up the link could not carry stays owed (the
cancel record). The ``article`` profile has no cancel record: its Stop is what ends a
running move. The link is cut (a proxy outage, started once the arm moves) for longer
than the retry policy rides out: the wait gives up and its Stop fails too. The arm runs
on meanwhile (nothing can reach it); but once the link is back, the master's next call
must deliver that Stop before anything else, not leave the arm to finish the move the
master gave up. The judge is the simulator's TCP and motion log.

The same holds for an awaited move of an ``aio.AsyncRobot``, given up by the lost link
or by a cancellation while the link is down: the next awaited call, or ``close()``,
delivers its Stop.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Iterator
from typing import Any

import pytest

import tmmaster
from fault_proxy import FaultProxy
from safety_invariant import at_rest
from test_aio import until
from tmmaster import Fleet, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy, aio
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

START = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)
#: The outage outlasts the poll's retries and the Stop's (0.3 s each): unloaded, the
#: wait gives up and the Stop fails about 0.25 s into it (connections refused at once).
OUTAGE_S = 0.8
#: Ten times real time, FAR at SLOW %: still about 4 s (wall) away, far beyond the
#: outage, as at twice real time and 5 %; the move to START takes a fifth of that.
TIME_SCALE = 10.0
SLOW = 1
#: How far apart the waits look (for an answer, for the arm at rest): 5 ticks of the
#: suite's 100 Hz, so an arm still moving has moved between two looks.
LOOK_S = 0.05
RETRY = RetryPolicy(attempts=2, total_time_s=0.3, initial_backoff_s=0.05, jitter_s=0)


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("article", time_scale=TIME_SCALE)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def article_robot(
    proxy: FaultProxy, link: Fleet | None, request_s: float = 0.2, **options: Any
) -> Robot:
    """The master of these tests: article, behind ``proxy``, retries that give up well
    inside the outage (refused connections fail at once, whatever ``request_s``)."""
    return Robot(
        "127.0.0.1",
        proxy.port,
        profile="article",
        link=link,
        polling=PollPolicy(interval_s=0.02),
        retry=RETRY,
        timeouts=TimeoutPolicy(request_s=request_s),
        **options,
    )


def answered(robot: Robot) -> Callable[[], bool]:
    """True once ``robot.status()`` returns (a call of the master's, not a probe)."""

    def call() -> bool:
        try:
            robot.status()
        except tmmaster.TMMasterError:
            return False
        return True

    return call


def test_a_stop_lost_with_the_link_is_delivered_by_the_next_call(
    sim: Simulator, proxy: FaultProxy, driver_or_fleet: Fleet | None
) -> None:
    with article_robot(proxy, driver_or_fleet) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(START, speed=100)
        motion = robot.start_move(FAR, speed=SLOW)  # about 4 s to go
        sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=20)
        proxy.outage(OUTAGE_S)
        with pytest.raises(tmmaster.TransportError):
            motion.wait()  # given up: the link is gone, and with it the Stop
        # The master's next calls: refused while the Stop still cannot be delivered
        # (CommandStateUnknownError), then, the link back, the Stop goes first.
        sim.wait_for(answered(robot), timeout=OUTAGE_S + 5, interval=LOOK_S)
        sim.wait_for(at_rest(sim), timeout=15, interval=LOOK_S)  # to FAR: about 4 s
        rest = sim.tcp_pose()
        assert rest.distance_to(FAR) > 100, f"the given-up move ran on to {rest}"
        assert motion.stop_delivered is True
    assert [m.target for m in sim.motion_log()] == [START, FAR]


async def answered_awaited(robot: aio.AsyncRobot) -> None:
    """Until ``await robot.status()`` returns (a call of the master's, not a probe)."""
    for _ in range(int((OUTAGE_S + 5) / LOOK_S)):
        try:
            await robot.status()
        except tmmaster.TMMasterError:
            await asyncio.sleep(LOOK_S)
        else:
            return
    raise AssertionError("the robot never answered again")


async def lost_by_the_link(move: asyncio.Task[object], proxy: FaultProxy) -> None:
    with pytest.raises(tmmaster.TransportError):
        await move  # given up: the link is gone, and with it the Stop


async def cancelled_in_the_outage(move: asyncio.Task[object], proxy: FaultProxy) -> None:
    # At once: the cancellation's Stop is tried while the link is down (its retries,
    # 0.3 s, end well inside the outage), so it fails and is owed.
    move.cancel()
    with pytest.raises(asyncio.CancelledError):
        await move


GiveUp = Callable[[asyncio.Task[object], FaultProxy], Awaitable[None]]


async def moving_then_cut(
    sim: Simulator, proxy: FaultProxy, robot: aio.AsyncRobot
) -> asyncio.Task[object]:
    """The arm on its way from START to FAR (about 4 s), then the link cut."""
    await robot.wait_until_ready(timeout_s=5)
    await robot.move_to(START, speed=100)
    move: asyncio.Task[object] = asyncio.ensure_future(robot.move_to(FAR, speed=SLOW))
    await until(lambda: sim.tcp_pose().y > START.y + 10, timeout_s=20)
    proxy.outage(OUTAGE_S)
    return move


async def stops_short(sim: Simulator) -> None:
    # Looks LOOK_S apart (several ticks): to FAR would take about 4 s.
    await asyncio.to_thread(sim.wait_for, at_rest(sim), 15, interval=LOOK_S)
    rest = sim.tcp_pose()
    assert rest.distance_to(FAR) > 100, f"the given-up move ran on to {rest}"


@pytest.mark.parametrize("give_up", [lost_by_the_link, cancelled_in_the_outage])
def test_an_awaited_moves_lost_stop_is_delivered_by_the_next_awaited_call(
    sim: Simulator, proxy: FaultProxy, driver_or_fleet: Fleet | None, give_up: GiveUp
) -> None:
    async def scenario() -> None:
        async with aio.AsyncRobot(article_robot(proxy, driver_or_fleet, gripper=None)) as robot:
            move = await moving_then_cut(sim, proxy, robot)
            await give_up(move, proxy)
            # Refused while the Stop still cannot be delivered, then it goes first.
            await answered_awaited(robot)
            await stops_short(sim)
            motion = robot.last_motion
            assert motion is not None
            assert motion.stop_delivered is True

    run_long(scenario)
    assert [m.target for m in sim.motion_log()] == [START, FAR]


@pytest.mark.parametrize("give_up", [lost_by_the_link, cancelled_in_the_outage])
def test_an_awaited_moves_lost_stop_is_delivered_by_close(
    sim: Simulator, proxy: FaultProxy, driver_or_fleet: Fleet | None, give_up: GiveUp
) -> None:
    async def scenario() -> None:
        # The Stop close() delivers has one try: 0.5 s for its answer on a loaded machine.
        robot = aio.AsyncRobot(article_robot(proxy, driver_or_fleet, 0.5, gripper=None))
        try:
            await robot
            move = await moving_then_cut(sim, proxy, robot)
            await give_up(move, proxy)
            # The link comes back (the proxy accepts again); no call of the master
            # reached the robot. close() delivers the owed Stop before it closes.
            await until(proxy_accepts(proxy), timeout_s=OUTAGE_S + 2)
            assert await robot.close(timeout_s=2.0) is True
            await stops_short(sim)
        finally:
            await robot.close()

    run_long(scenario)
    assert [m.target for m in sim.motion_log()] == [START, FAR]


def proxy_accepts(proxy: FaultProxy) -> Callable[[], bool]:
    """For ``until``: True once the proxy takes a connection again (the outage over).

    Asked of the proxy, which decides: a probe connection needed 0.5 s of silence to
    tell a taken connection from a refused one whose reset came late (a loaded machine).
    """
    return lambda: proxy.accepting


def run_long(scenario: Callable[[], Awaitable[None]]) -> None:
    async def bounded() -> None:
        async with asyncio.timeout(60):
            await scenario()

    asyncio.run(bounded())
