"""Hunt 40: one robot, or the user's own code, starving the others on a shared driver.

Every network robot of a process shares one event-loop thread (the default driver, or a
``Fleet``): its links, the polls of its waits and its heartbeat's task. What else runs
on that thread, and what does not:

- an ``AsyncRobot``'s caller's loop is another thread: a coroutine that blocks it (a
  ``time.sleep`` by mistake, a long computation) for longer than the heartbeat's TTL
  holds up no robot's heartbeat nor its polls;
- one robot's link that stalls (its answers held in the network) holds up no other
  robot: the loop awaits its answer;
- a ``logging`` handler does run there, for the events the loop logs
  (``robot.command_acknowledged`` among them): one that blocks holds every robot of the
  driver, and past ``heartbeat_ttl_s`` the robot program expires every live command.
  That is the documented limit (docs/robot-api.md, "Logging"); what it must never do is
  leave a master believing a move done, or run a command given up.

The judges are the simulators: their motion logs (``safety_invariant.check``), their
Display() texts and their heartbeat writes.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable, Coroutine, Iterator
from typing import Any, TypeVar

import pytest

import tmmaster
from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from sim_speeds import SUITE_TICK_HZ
from tmmaster import Fleet, PollPolicy, Pose, Robot, TimeoutPolicy, aio
from tmmaster.sim import Simulator, Timing

SimFactory = Callable[..., Simulator]
T = TypeVar("T")

A = Pose(300, -200, 200, 180, 0, 90)
B = Pose(300, 200, 200, 180, 0, 90)  # a long turn of J1 from A
C = Pose(300, -200, 160, 180, 0, 90)

#: A short heartbeat: a silence of half a second expires a command.
FAST = TimeoutPolicy(heartbeat_s=0.05, heartbeat_ttl_s=0.5, gripper_settle_s=0.05)
EXPIRED = "the master heartbeat stopped"
HEARTBEAT = 9050


def beats(sim: Simulator) -> int:
    """Heartbeat writes the simulator received."""
    return sum(1 for r in sim.request_log if r.function_code == 16 and r.address == HEARTBEAT)


def expired(sim: Simulator) -> bool:
    """True once the robot program expired a command for its master's silence."""
    return any(EXPIRED in text for text in sim.displayed())


def slow_sim(factory: SimFactory) -> Simulator:
    """A tmflow simulator at 4x: the turn A -> B lasts 1 s of wall time at 10 %, 1.9 s at 5 %
    (the robot program's TTL is in wall time)."""
    return factory("tmflow", time_scale=4.0, timing=Timing(tick_hz=SUITE_TICK_HZ))


def run(scenario: Callable[[], Coroutine[Any, Any, T]]) -> T:
    """The scenario in ``asyncio.run``, bounded (a hang fails instead of blocking the suite)."""

    async def bounded() -> T:
        async with asyncio.timeout(30):
            return await scenario()

    return asyncio.run(bounded())


def test_a_user_coroutine_blocking_its_loop_past_the_ttl_starves_no_async_robot(
    tm_simulator_factory: SimFactory,
) -> None:
    sims = [slow_sim(tm_simulator_factory) for _ in range(2)]
    issued: list[list[Issued]] = [[], []]

    async def scenario() -> None:
        robots = [
            aio.connect(
                "127.0.0.1",
                sim.port,
                gripper=None,
                timeouts=FAST,
                polling=PollPolicy(interval_s=0.01),
                name=f"r{i}",
            )
            for i, sim in enumerate(sims)
        ]
        for robot in robots:
            await robot.connect()
        try:
            await asyncio.gather(*(robot.move_to(A, speed=100) for robot in robots))
            for mine in issued:
                mine.append(Issued(A, 0.0, 0.0, "done"))
            motions = [await robot.start_move(B, speed=5) for robot in robots]
            for mine in issued:
                mine.append(Issued(B, time.monotonic()))
            # The caller's loop blocked (a mistaken blocking call in a coroutine) until
            # every robot beat for longer than the TTL, its move running meanwhile.
            span = round(FAST.heartbeat_ttl_s / FAST.heartbeat_s) + 4  # periods
            needs = [beats(sim) + span + 1 for sim in sims]
            sims[0].wait_for(
                lambda: all(beats(s) >= n for s, n in zip(sims, needs, strict=True)), timeout=10
            )
            # The moves still run: each command was live through all those beats. A machine
            # so loaded that a move outlived none of it tested nothing: skipped, not failed.
            if not all(sim.tcp_pose().distance_to(B) > 1.0 for sim in sims):
                pytest.skip("a move ended before the loop's block outlasted the TTL")
            for mine, motion in zip(issued, motions, strict=True):
                try:
                    await motion
                except tmmaster.TMMasterError as exc:
                    mine[-1].outcome = type(exc).__name__
                else:
                    mine[-1].outcome = "done"
                mine[-1].ended_at = time.monotonic()
        finally:
            for robot in robots:
                await robot.close()

    run(scenario)
    for sim, mine in zip(sims, issued, strict=True):
        assert not expired(sim), sim.displayed()
        assert [c.outcome for c in mine] == ["done", "done"]
        check(mine, sim.motion_log())
        assert sim.tcp_pose().distance_to(B) < 0.5


@pytest.fixture
def fleet() -> Iterator[Fleet]:
    own = Fleet()
    yield own
    own.close()


class _HeldOnTheLoop(logging.Handler):
    """A handler that blocks the thread that logs (a log shipper whose server stopped
    answering): on the driver's loop thread, at ``robot``'s acknowledgement, until
    ``until()`` holds (bounded)."""

    def __init__(self, loop_thread: threading.Thread, robot: str, until: Callable[[], bool]):
        super().__init__(logging.INFO)
        self._loop_thread = loop_thread
        self._wanted = ("robot.command_acknowledged", f"robot={robot} ")
        self._until = until
        self.held = 0

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        if threading.current_thread() is not self._loop_thread or self.held:
            return
        if not all(part in message for part in self._wanted):
            return
        self.held += 1
        deadline = time.monotonic() + 10.0
        while not self._until() and time.monotonic() < deadline:
            time.sleep(0.01)


def waited(motion: tmmaster.Motion, command: Issued) -> None:
    """``motion.wait()``, its outcome recorded in ``command``."""
    try:
        motion.wait()
    except tmmaster.TMMasterError as exc:
        command.outcome = type(exc).__name__
    else:
        command.outcome = "done"
    command.ended_at = time.monotonic()


def test_a_log_handler_that_blocks_on_the_drivers_loop_expires_every_robots_command_safely(
    tm_simulator_factory: SimFactory, fleet: Fleet
) -> None:
    # The documented limit (docs/robot-api.md, "Logging"): a handler that blocks on the
    # loop, at one robot's event, holds every robot of the driver. The robot programs then
    # expire the live commands (the cell stops for nothing); no master may take its move
    # for done, and nothing given up may run later.
    sims = [slow_sim(tm_simulator_factory) for _ in range(2)]
    robots = [
        Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST, link=fleet, name=name)
        for sim, name in zip(sims, ("mover", "logged"), strict=True)
    ]
    issued: list[list[Issued]] = [[], []]
    std = logging.getLogger("tmmaster.robot")
    level = std.level
    loop_thread = fleet.start()._runner.thread
    assert loop_thread is not None
    handler = _HeldOnTheLoop(loop_thread, "logged", lambda: all(map(expired, sims)))
    try:
        for robot, mine in zip(robots, issued, strict=True):
            robot.connect()
            robot.move_to(A, speed=100)
            mine.append(Issued(A, 0.0, 0.0, "done"))
        std.addHandler(handler)
        std.setLevel(logging.INFO)
        motions = []
        for robot, mine in zip(robots, issued, strict=True):
            mine.append(Issued(B, time.monotonic()))
            motions.append(robot.start_move(B, speed=5))  # 1.9 s: outlasts the TTL
        # The mover's wait on a thread of its own; the logged robot's acknowledgement is
        # noted on the loop, where the handler holds it.
        mover = threading.Thread(target=waited, args=(motions[0], issued[0][-1]))
        mover.start()
        waited(motions[1], issued[1][-1])
        mover.join(30.0)
    finally:
        std.removeHandler(handler)
        std.setLevel(level)
        for robot in robots:
            robot.close()
    assert handler.held == 1, "the acknowledgement was not logged on the loop"
    for sim, mine in zip(sims, issued, strict=True):
        assert expired(sim), "the loop was held past the TTL: the program expires the move"
        assert mine[-1].gave_up, f"{mine[-1].outcome}: an expired move must not read as done"
        assert sim.tcp_pose().distance_to(B) > 1.0
        check(mine, sim.motion_log())


def test_one_robots_stalled_link_holds_up_no_other_robot_on_the_driver(
    tm_simulator_factory: SimFactory, fleet: Fleet
) -> None:
    stalled_sim = tm_simulator_factory("tmflow")
    sims = [slow_sim(tm_simulator_factory) for _ in range(2)]
    release = threading.Event()
    with FaultProxy(stalled_sim.port) as proxy:
        stalled = Robot(
            "127.0.0.1",
            proxy.port,
            gripper=None,
            link=fleet,
            name="stalled",
            timeouts=TimeoutPolicy(heartbeat_s=0.05, heartbeat_ttl_s=0.5, request_s=5.0),
        )
        robots = [
            Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST, link=fleet, name=f"r{i}")
            for i, sim in enumerate(sims)
        ]
        issued: list[list[Issued]] = [[], []]
        try:
            stalled.connect()
            stalled.move_to(A, speed=100)
            for robot in robots:
                robot.connect()
                robot.move_to(A, speed=100)
            for mine in issued:
                mine.append(Issued(A, 0.0, 0.0, "done"))
            # The stalled robot's next heartbeat gets no answer until released, nor does
            # anything after it on that link (TCP keeps order).
            proxy.add(Rule("delay_answer", 16, HEARTBEAT, release=release))
            stalled_sim.wait_for(lambda: proxy.played("delay_answer"), timeout=5.0)
            motions = [robot.start_move(B, speed=10) for robot in robots]
            for mine in issued:
                mine.append(Issued(B, time.monotonic()))
            for mine, motion in zip(issued, motions, strict=True):
                try:
                    motion.wait()
                except tmmaster.TMMasterError as exc:
                    mine[-1].outcome = type(exc).__name__
                else:
                    mine[-1].outcome = "done"
                mine[-1].ended_at = time.monotonic()
            assert proxy.played("delay_answer")
        finally:
            release.set()
            for robot in robots:
                robot.close()
            stalled.close()
    for sim, mine in zip(sims, issued, strict=True):
        assert not expired(sim), sim.displayed()
        assert [c.outcome for c in mine] == ["done", "done"]
        check(mine, sim.motion_log())
