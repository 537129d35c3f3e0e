"""An awaited tmflow command cancelled while its one command frame is held in the network.

``tests/test_aio_cancel.py`` and ``tests/test_hunt4_aio_gripper.py`` hold the write of a
cancelled ``move_to`` and ``gripper.close()``. Here the other awaited commands of an
``aio.AsyncRobot``: ``move_by`` (a pose read first, then the write), ``move_arc`` (the
same, with the arc's extension words in the one write), ``move_joints``, ``start_move``
(the call that only sends) and ``gripper.open()`` after a close. A FaultProxy holds the
command's FC16 (9000 for a move, 9014 for a gripper command), the awaiting task is
cancelled (``task.cancel()``, ``asyncio.wait_for``) while it is held, and the frame
lands only after the ``CancelledError`` (``TimeoutError``) reached the caller.

What must hold, judged on the simulator: nothing the robot does starts after the
cancelled call returned (no motion, no gripper action), the cancelled command never
runs, nothing runs twice (the motion log holds each completed move once), and the
robot's next awaited call works (a move to where the arm is, to the end).
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Coroutine, Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from test_aio import given_up, run, until
from tmmaster import PollPolicy, Pose, TimeoutPolicy, aio
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
START = Pose(300, -200, 200, 180, 0, 90)
VIA = Pose(350, -150, 200, 180, 0, 90)
END = Pose(400, -200, 200, 180, 0, 90)
JOINTS = (10.0, -5.0, 100.0, -5.0, 90.0, 10.0)
#: tmflow: where a move's one FC16 starts (its target), and a gripper command's (seq).
MOVE_BLOCK, GRIPPER_COMMAND = 9000, 9014

Call = Callable[[aio.AsyncRobot], Coroutine[Any, Any, Any]]
CALLS: dict[str, tuple[int, Call]] = {
    "move_by": (MOVE_BLOCK, lambda r: r.move_by(dz=-40, motion="line", speed=80)),
    "move_arc": (MOVE_BLOCK, lambda r: r.move_arc(VIA, END, speed_mm_s=400)),
    "move_joints": (MOVE_BLOCK, lambda r: r.move_joints(JOINTS, speed=80)),
    "start_move": (MOVE_BLOCK, lambda r: r.start_move(END, speed=80)),
    "gripper_open": (GRIPPER_COMMAND, lambda r: r.gripper.open()),
}


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=20.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


async def by_cancel(call: Coroutine[Any, Any, Any], proxy: FaultProxy) -> None:
    task = asyncio.ensure_future(call)
    await until(lambda: proxy.played("hold"))
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task


async def by_wait_for(call: Coroutine[Any, Any, Any], proxy: FaultProxy) -> None:
    with pytest.raises(TimeoutError):
        # The frame is held from the first 10 ms on, unloaded; move_arc's checks took over
        # 0.1 s once beside two busy processes. Below request_s: the held write's own
        # timeout must not end the call first.
        await asyncio.wait_for(call, 0.3)
    assert proxy.played("hold")


@pytest.mark.parametrize("cancel", [by_cancel, by_wait_for], ids=["cancel", "wait_for"])
@pytest.mark.parametrize("name", list(CALLS))
def test_a_command_cancelled_while_its_frame_is_held_never_runs_and_the_next_call_works(
    sim: Simulator,
    proxy: FaultProxy,
    name: str,
    cancel: Callable[[Coroutine[Any, Any, Any], FaultProxy], Coroutine[Any, Any, None]],
) -> None:
    address, call = CALLS[name]
    release = threading.Event()
    issued: list[Issued] = []

    async def scenario() -> float:
        async with aio.connect(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.5, ack_timeout_s=0.5, gripper_settle_s=0.05),
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            await robot.move_to(START, speed=80)
            issued.append(Issued(START, 0.0, 0.0, "done"))
            if address == GRIPPER_COMMAND:
                await robot.gripper.close()
            before = len(sim.motion_log())
            proxy.add(Rule("hold", function_code=16, address=address, release=release))
            await cancel(call(robot), proxy)
            ended_at, ended_wall = time.monotonic(), time.time()
            if address == MOVE_BLOCK:
                assert given_up(robot.last_motion), robot.last_motion
            release.set()  # the held frame lands now, after the master gave it up
            await asyncio.to_thread(proxy.wait_held)
            ticks = sim.ticks
            await until(lambda: sim.ticks >= ticks + 20)
            landed = [
                r
                for r in sim.request_log
                if r.function_code == 16
                and r.address == address
                and r.count > 2  # not a cancel record
                and r.time > ended_wall
            ]
            assert landed, "the held command never reached the robot"
            assert list(sim.motion_log()[before:]) == [], "the cancelled command ran"
            # The next awaited call works: the arm is still at START.
            await asyncio.wait_for(robot.move_to(START, speed=80), 5)
            return ended_at

    try:
        ended_at = run(scenario)
    finally:
        release.set()
    late = [m for m in sim.motion_log() if m.wall_time > ended_at and m.target != START]
    assert not late, f"started after the cancelled call returned: {late}"
    check(issued, [m for m in sim.motion_log() if m.target is not None][:1])
    assert [m.target for m in sim.motion_log() if m.target is not None].count(START) <= 2
