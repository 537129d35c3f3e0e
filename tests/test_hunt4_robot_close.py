"""Robot.close(timeout_s=) on a plain Robot while its own command write is held.

The fix of ``close()`` under a held command write (docs/safety.md, Limits: ``close()``
may outlast its ``timeout_s`` by one request and one give-up) was tested through a
Fleet only (``tests/test_hunt3_fleet_close.py``). Here a plain ``Robot`` (``link=None``:
the process's default driver) and an ``aio.AsyncRobot`` on the tmflow profile write a
move whose FC16 to the command block is held by a FaultProxy; ``close(timeout_s=CLOSE_S)``
is called while the frame is held, and the frame lands right after ``close()``
returned. The request timeout (0.5 s) is shorter than the program's ``master_ttl_ms``
(1 s), so only the close's own give-up keeps the frame from running. The simulator's
motion log judges: the given-up move never starts, nothing runs twice.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Awaitable, Callable, Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, check
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy, TMMasterError, aio
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)
#: Half of what these tests first used (a 1 s request timeout against the default 2 s
#: TTL, a 0.5 s close): the same order of the three windows in half the wall time. The TTL
#: no lower than 1 s: a loaded machine once kept a beat from running for that long
#: (tests/test_heartbeat.py).
TIMEOUTS = TimeoutPolicy(
    request_s=0.5, ack_timeout_s=5.0, motion_margin_s=1.0, heartbeat_s=0.25, heartbeat_ttl_s=1.0
)
#: close()'s budget: shorter than the held write's request timeout, which it waits out.
CLOSE_S = 0.25
#: Every master of this file: tmflow, no gripper, 10 ms polls, a 0.5 s request timeout.
OPTIONS: dict[str, Any] = dict(
    profile="tmflow", gripper=None, polling=PollPolicy(interval_s=0.01), timeouts=TIMEOUTS
)


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=20.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def judge(sim: Simulator, issued: list[Issued], closed_at: float, closed_wall: float) -> None:
    """The held frame landed after the close; nothing new ran, nothing twice; at rest at A."""
    # The proxy has handed the frame to the socket: 20 ticks for the robot to read it
    # and, were it to run, to start it.
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
    landed = [
        r
        for r in sim.request_log
        if r.function_code == 16 and r.address == 9000 and r.time > closed_wall
    ]
    assert landed, "the held command frame never reached the robot after the close"
    sim.wait_for(at_rest(sim), timeout=5.0, interval=0.05)
    check(issued, sim.motion_log())
    late = [m for m in sim.motion_log() if m.wall_time > closed_at]
    assert not late, f"motions started after close(): {late}"
    assert [m.target for m in sim.motion_log() if m.target is not None] == [A]
    assert sim.tcp_pose().is_close(A), f"the arm left A: {sim.tcp_pose()}"


def test_close_of_a_plain_robot_gives_up_its_held_command_write(
    sim: Simulator, proxy: FaultProxy
) -> None:
    release = threading.Event()
    issued: list[Issued] = []
    robot = Robot("127.0.0.1", proxy.port, **OPTIONS)
    try:
        robot.connect()
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(A, speed=80)
        issued.append(Issued(A, 0.0, 0.0, "done"))
        proxy.add(Rule("hold", function_code=16, address=9000, release=release))
        command = Issued(B, time.monotonic())
        issued.append(command)

        def move() -> None:
            try:
                robot.move_to(B, speed=80)
            except TMMasterError as exc:
                command.outcome = type(exc).__name__
            else:
                command.outcome = "done"
            command.ended_at = time.monotonic()

        thread = threading.Thread(target=move)
        thread.start()
        sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)
        assert thread.is_alive()  # its write waits on its answer
        robot.close(timeout_s=CLOSE_S)
        closed_at, closed_wall = time.monotonic(), time.time()
        release.set()  # the held frame lands now, after the close gave it up
        proxy.wait_held()
        thread.join(10)
        assert not thread.is_alive()
        judge(sim, issued, closed_at, closed_wall)
        assert command.outcome != "done"
    finally:
        release.set()
        robot.close()


async def held_move(
    robot: aio.AsyncRobot, proxy: FaultProxy, release: threading.Event, issued: list[Issued]
) -> tuple[asyncio.Future[Any], Issued]:
    """``robot`` at A, then its awaited move to B started, its write held until ``release``."""
    await robot
    await robot.wait_until_ready(timeout_s=5)
    await robot.move_to(A, speed=80)
    issued.append(Issued(A, 0.0, 0.0, "done"))
    proxy.add(Rule("hold", function_code=16, address=9000, release=release))
    command = Issued(B, time.monotonic())
    issued.append(command)
    move = asyncio.ensure_future(robot.move_to(B, speed=80))
    while not proxy.played("hold"):
        await asyncio.sleep(0.005)
    return move, command


def run_and_judge(
    sim: Simulator,
    proxy: FaultProxy,
    issued: list[Issued],
    scenario: Callable[[], Awaitable[tuple[float, float]]],
) -> None:
    """Run ``scenario`` (30 s at most), which returns when the master gave the move up
    (monotonic and wall clock); then the held frame lands and :func:`judge` rules."""

    async def bounded() -> tuple[float, float]:
        async with asyncio.timeout(30):
            return await scenario()

    closed_at, closed_wall = asyncio.run(bounded())
    proxy.wait_held()
    judge(sim, issued, closed_at, closed_wall)


def test_close_of_an_async_robot_gives_up_its_awaited_moves_held_write(
    sim: Simulator, proxy: FaultProxy
) -> None:
    release = threading.Event()
    issued: list[Issued] = []

    async def scenario() -> tuple[float, float]:
        robot = aio.connect("127.0.0.1", proxy.port, **OPTIONS)
        try:
            move, command = await held_move(robot, proxy, release, issued)
            assert not move.done()
            await robot.close(timeout_s=CLOSE_S)
            closed_at, closed_wall = time.monotonic(), time.time()
            release.set()
            try:
                await move
            except TMMasterError as exc:
                command.outcome = type(exc).__name__
            else:
                command.outcome = "done"
            command.ended_at = time.monotonic()
            assert command.outcome != "done"
            return closed_at, closed_wall
        finally:
            release.set()
            await robot.close()

    run_and_judge(sim, proxy, issued, scenario)


@pytest.mark.parametrize("order", ["cancel_then_close", "close_then_cancel"])
def test_an_async_robot_closed_while_its_cancelled_moves_write_is_held(
    sim: Simulator, proxy: FaultProxy, order: str
) -> None:
    # The awaited move's write is held; the move's task is cancelled and the robot
    # closed at once, in either order, the cancellation's clean-up and the close both
    # waiting on the same write. The frame lands once both have returned.
    release = threading.Event()
    issued: list[Issued] = []

    async def scenario() -> tuple[float, float]:
        robot = aio.connect("127.0.0.1", proxy.port, **OPTIONS)
        try:
            move, command = await held_move(robot, proxy, release, issued)
            if order == "cancel_then_close":
                move.cancel()
                closing = asyncio.ensure_future(robot.close(timeout_s=CLOSE_S))
            else:
                closing = asyncio.ensure_future(robot.close(timeout_s=CLOSE_S))
                await asyncio.sleep(0)  # the close's thread is started
                move.cancel()
            results = await asyncio.gather(move, closing, return_exceptions=True)
            closed_at, closed_wall = time.monotonic(), time.time()
            release.set()
            command.outcome = type(results[0]).__name__
            command.ended_at = closed_at
            assert command.outcome in ("CancelledError", "StopRequestedError"), results
            return closed_at, closed_wall
        finally:
            release.set()
            await robot.close()

    run_and_judge(sim, proxy, issued, scenario)


def test_a_copy_the_gate_refuses_is_neither_sent_nor_logged_as_resent(
    sim: Simulator, proxy: FaultProxy, caplog: pytest.LogCaptureFixture
) -> None:
    """A stop request while the move's write is held: the write's answer never comes, and
    the gate refuses its copy (a stop was requested). Nothing was resent, so nothing is
    logged as resent, and the held frame, landing later, never runs."""
    release = threading.Event()
    issued: list[Issued] = [Issued(A, 0.0, 0.0, "done")]
    with Robot("127.0.0.1", proxy.port, **OPTIONS) as robot:
        try:
            robot.wait_until_ready(timeout_s=5)
            robot.move_to(A, speed=80)
            proxy.add(Rule("hold", function_code=16, address=9000, release=release))
            command = Issued(B, time.monotonic())
            issued.append(command)

            def stop_request_once_held() -> None:  # as soon as the proxy holds the write
                sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)
                robot.interrupt()

            threading.Thread(target=stop_request_once_held).start()
            with pytest.raises(TMMasterError) as failed:
                robot.move_to(B, speed=80)
            command.outcome, command.ended_at = type(failed.value).__name__, time.monotonic()
            given_up_wall = time.time()
            release.set()
            proxy.wait_held()
            judge(sim, issued, command.ended_at, given_up_wall)
            writes = [r for r in sim.request_log if r.function_code == 16 and r.address == 9000]
            assert len(writes) == 2, writes  # A's, and B's held frame: no copy of it
            assert "robot.command_resent" not in caplog.text
        finally:
            release.set()
