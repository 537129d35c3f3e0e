"""Cancelling an awaited gripper call during its watch leaves no write of ours behind.

The article gripper's register is watched like a digital output: a close() written
while an earlier open frame may still land reads the register back, and writes the
close again when that frame lands (``tests/test_hunt_gripper.py``). An AsyncRobot's
call cancelled during that watch must end it: once the ``CancelledError`` reached the
caller, the master writes nothing more to the register (the held frame, landing then,
is the documented limit: the master no longer watches). The judge is the simulator's
request log.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy
from fault_proxy import Rule as FaultRule
from test_aio import run, until
from tmmaster import PollPolicy, RegisterGripper, RetryPolicy, TimeoutPolicy, aio
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: The article map's gripper register (0 open, 1 close).
GRIPPER_REGISTER = 0x0210
#: The held open frame times out; the watch could last the retry policy's 3 s.
RETRY = RetryPolicy(attempts=4, total_time_s=3.0, initial_backoff_s=0.01, jitter_s=0)


def register_writes(sim: Simulator) -> list[int]:
    """Every value the simulator executed into the gripper register, in order."""
    return [
        int(r.values[0])
        for r in sim.request_log
        if r.function_code in (6, 16) and r.address == GRIPPER_REGISTER and r.values
    ]


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("article")


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def test_a_gripper_close_cancelled_during_its_watch_writes_nothing_after(
    sim: Simulator, proxy: FaultProxy
) -> None:
    release = threading.Event()
    held = proxy.add(FaultRule("hold", function_code=16, address=GRIPPER_REGISTER, release=release))
    sim.clear_request_log()

    async def scenario() -> list[int]:
        async with aio.connect(
            "127.0.0.1",
            proxy.port,
            profile="article",
            retry=RETRY,
            timeouts=TimeoutPolicy(request_s=0.2),
            polling=PollPolicy(interval_s=0.01),
            gripper=RegisterGripper(settle_s=0.1),
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            await robot.gripper.open()  # the first frame held: retried, answered
            assert held.times == 0
            task = asyncio.create_task(robot.gripper.close())
            # The close executed: its watch for the held open frame runs now.
            await until(lambda: 1 in register_writes(sim))
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            after_cancel = len(register_writes(sim))
            release.set()  # the held open lands, unwatched
            proxy.wait_held()
            await asyncio.sleep(0.1)  # room for a write that would still be going
            return register_writes(sim)[after_cancel:]

    try:
        later = run(scenario)
    finally:
        release.set()
    assert later == [0], later  # the late frame only: no write of the master's
