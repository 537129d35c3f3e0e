"""What hours of running leave behind: Robots opened per cycle and never closed, a
heartbeat restarted at every lost link, a simulator serving a cell for days.

A script that opens a Robot every cycle and forgets ``close()`` (``robot =
tmmaster.connect(...)`` in a loop) drops each one with its link open and, on ``tmflow``,
its heartbeat running. A dropped Robot must be garbage: its heartbeat stops (the robot
program expires anything it left), its link closes and its share of the process's
default driver is given back. Kept alive instead (an exit hook holding it), every one of
them goes on beating its own session: the robot program sees its master replaced again
and again, refuses the next Robot's commands as ``another_master`` and stops a running
one; and each holds a socket (a robot's Modbus server serves only a few clients).
Invariants only: what is garbage, what is left open once the loop had its turn, what a
process holds after many rounds (finalizers, motion records).
"""

from __future__ import annotations

import asyncio
import gc
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from typing import Any

import pytest

import tmmaster._robot as robot_module
from leaks import left_open, open_sockets
from sim_speeds import QUICK
from tmmaster import Fleet, PollPolicy, Pose, Robot, StatusMonitor, TransportClosedError
from tmmaster._fleet import _DEFAULT, LoopTransport
from tmmaster.aio import AsyncRobot
from tmmaster.sim import Simulator
from tmmaster.sim import _controller as sim_controller

SimFactory = Callable[..., Simulator]

APPROACH = Pose(300, -200, 200, 180, 0, 90)
PICK = Pose(300, -200, 150, 180, 0, 90)


def made(sim: Simulator, link: Fleet | str | None) -> Robot:
    """A Robot of ``sim``: over TCP (the default driver, or a Fleet), or in process."""
    if isinstance(link, str):  # "in-process"
        return Robot(sim.url, profile=sim.profile, polling=PollPolicy(interval_s=0.01))
    return Robot(
        sim.host, port=sim.port, profile=sim.profile, link=link, polling=PollPolicy(interval_s=0.01)
    )


def forgotten_robot(sim: Simulator, link: Fleet | str | None, target: Pose) -> weakref.ref[Robot]:
    """A Robot connected, moved once (it claims the robot and beats), never closed."""
    robot = made(sim, link)
    robot.connect()
    robot.move_to(target, speed=80)
    return weakref.ref(robot)


def collected(refs: list[weakref.ref[Any]]) -> list[bool]:
    """Whether each of ``refs`` is garbage, once collections found them (2 s at most: a
    thread may hold one a moment longer, e.g. the call it just answered)."""
    deadline = time.monotonic() + 2.0
    while any(ref() is not None for ref in refs) and time.monotonic() < deadline:
        gc.collect()  # the collection that would come on its own
        time.sleep(0.02)
    return [ref() is None for ref in refs]


@pytest.fixture(params=["driver", "fleet", "in-process"])
def link(request: pytest.FixtureRequest) -> Iterator[Fleet | str | None]:
    """The dropped Robots' link: the default driver, a Fleet of the test's, or sim://."""
    if request.param == "fleet":
        with Fleet() as fleet:
            yield fleet
        return
    yield None if request.param == "driver" else request.param


def test_a_robot_dropped_without_close_is_garbage(
    tm_simulator_factory: SimFactory, link: Fleet | str | None
) -> None:
    sim = tm_simulator_factory()
    # Another Robot stays open all along: its driver keeps running.
    with made(sim, link) as keeper:
        before = open_sockets()
        # Each garbage before the next moves: until collected, a dropped Robot still beats,
        # and the robot program takes the next Robot's command for another master's
        # (rejected; seen with 24 workers on two cores, a thread holding the Robot longer).
        dropped = []
        for target in (APPROACH, PICK, APPROACH):
            dropped.append(forgotten_robot(sim, link, target))
            assert collected(dropped) == [True] * len(dropped)
        keeper.status()
        # Their links closed (the client's socket and the simulator's end of it), while
        # the driver runs on: a robot's Modbus server has a slot free for the next one.
        assert left_open(before, set(threading.enumerate()))[1] == set()


async def forgotten_async_robot(sim: Simulator, target: Pose) -> weakref.ref[AsyncRobot]:
    """An AsyncRobot connected, moved once (its thread started), never closed."""
    robot = AsyncRobot(made(sim, None))
    await robot.connect()
    await robot.move_to(target, speed=80)
    return weakref.ref(robot)


def test_an_async_robot_dropped_without_close_is_garbage(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory()

    async def cycles() -> list[weakref.ref[AsyncRobot]]:
        return [await forgotten_async_robot(sim, t) for t in (APPROACH, PICK)]

    with made(sim, None) as keeper:
        before, threads = open_sockets(), set(threading.enumerate())
        dropped = asyncio.run(cycles())
        assert collected(dropped) == [True, True]
        keeper.status()
        # Each robot's own thread ended, its link closed, while the driver runs on.
        assert left_open(before, threads) == ([], set())


#: How long the collecting thread may take before it counts as waiting for itself.
DEADLOCK_AFTER_S = 30.0


def test_a_link_collected_while_the_default_driver_is_being_taken_lets_it_go() -> None:
    # A collection can run inside any allocation, so also while a thread holds the
    # default driver's lock to make a new driver (Fleet() allocates plenty). A link
    # collected there, a Fleet's dropped unclosed, gives its share back through that
    # same lock, on the same thread: it must not wait for itself.
    done = threading.Event()

    def collect_while_taking_the_driver() -> None:
        with Fleet() as fleet:
            link = LoopTransport(
                fleet, "127.0.0.1", 1, device_id=1, timeout=1.0, retry=None, name="dropped"
            )
            link.self_cycle = link  # type: ignore[attr-defined]  # garbage only for gc
            del link
            with _DEFAULT._lock:
                gc.collect()  # the collection an allocation there could start
        done.set()

    worker = threading.Thread(target=collect_while_taking_the_driver, daemon=True)
    worker.start()
    # A deadlock never ends; a full collection of a test worker's heap on a loaded
    # machine takes about a second (2 s was once too short in a full run).
    worker.join(DEADLOCK_AFTER_S)
    assert done.is_set(), "the collection waited for the lock its own thread holds"


def finalizers() -> int:
    """How many weakref.finalize callbacks this process holds (alive, not yet run)."""
    return sum(1 for o in gc.get_objects() if isinstance(o, weakref.finalize) and o.alive)


def test_an_in_process_heartbeat_started_again_and_again_holds_one_finalizer(
    tm_simulator_factory: SimFactory,
) -> None:
    # A heartbeat stops while a give-up is owed (the link down) and starts again with the
    # next claim: on a long-lived in-process robot that is once per lost link, for hours.
    sim = tm_simulator_factory()
    with made(sim, "in-process") as robot:
        robot.move_to(APPROACH, speed=80)  # claims: the heartbeat's thread runs
        before = finalizers()
        for target in (PICK, APPROACH) * 5:
            robot._heartbeat.stop()  # what the command path's silence() does
            robot.move_to(target, speed=80)  # claims again: a new session, a new thread
        assert finalizers() - before < 5


def test_a_simulator_serving_for_days_keeps_the_latest_motions(
    tm_simulator_factory: SimFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The request log keeps the latest 100,000 requests; the motion log the latest
    # MOTION_LOG_LIMIT motions: a simulator serving a cell all week does not grow with
    # every move. Here a limit of 5 and 8 moves.
    monkeypatch.setattr(sim_controller, "MOTION_LOG_LIMIT", 5, raising=False)
    sim = tm_simulator_factory(listen=False, **QUICK)
    targets = [APPROACH.offset(dx=10 * i) for i in range(8)]
    with made(sim, "in-process") as robot:
        for target in targets:
            robot.move_to(target, speed=80)
    log = sim.motion_log()
    assert [m.number for m in log] == [4, 5, 6, 7, 8]
    assert [m.target for m in log] == targets[3:]
    # Each kept record still notes when its move was reported done.
    assert all(m.done_wall_time is not None for m in log)


def test_a_status_monitor_dropped_without_close_stops_polling(
    tm_simulator_factory: SimFactory,
) -> None:
    # A dashboard that starts a StatusMonitor per view and forgets close(): each one
    # left running polls the robot for ever (its thread, its socket, up to 600 requests
    # a second at 100 Hz) unless a dropped monitor is garbage and its loop ends.
    sim = tm_simulator_factory()

    def forgotten_monitor() -> weakref.ref[StatusMonitor]:
        monitor = StatusMonitor(rate_hz=50)
        monitor.add("cell", sim.host, sim.port, profile=sim.profile)
        monitor.start()
        return weakref.ref(monitor)

    before, threads = open_sockets(), set(threading.enumerate())
    assert collected([forgotten_monitor(), forgotten_monitor()]) == [True, True]
    assert left_open(before, threads) == ([], set())


@pytest.mark.parametrize("watch_hz", [None, 20.0], ids=["unwatched", "watched"])
def test_a_fleet_dropped_without_close_with_its_robots_ends_its_loop(
    tm_simulator_factory: SimFactory, watch_hz: float | None
) -> None:
    # A job that makes a Fleet and its robots per batch and forgets close(): each one
    # left running keeps its loop thread and its sockets for the life of the process
    # unless a dropped Fleet, once its robots are gone too, is garbage and its loop ends.
    sim = tm_simulator_factory()

    def forgotten_fleet() -> weakref.ref[Fleet]:
        fleet = Fleet(watch_hz=watch_hz)
        forgotten_robot(sim, fleet, APPROACH)
        return weakref.ref(fleet)

    before, threads = open_sockets(), set(threading.enumerate())
    assert collected([forgotten_fleet(), forgotten_fleet()]) == [True, True]
    assert left_open(before, threads) == ([], set())


def test_a_robot_subclass_that_is_not_hashable_connects_and_is_closed_at_exit(
    tm_simulator_factory: SimFactory,
) -> None:
    # A subclass that compares by value (a dataclass, an __eq__ of its own) has no hash:
    # the exit hook's record of open Robots must not need one.
    class CellRobot(Robot):
        __hash__ = None  # type: ignore[assignment]

    sim = tm_simulator_factory()
    robot = CellRobot(sim.url, profile=sim.profile)
    try:
        robot.connect()
        robot_module._close_at_exit()  # what the interpreter's exit runs
        with pytest.raises(TransportClosedError):
            robot.status()  # it was closed there
    finally:
        robot.close()
