"""A gripper never ends in an older state than the one the master asked for last.

The article's gripper register is level-triggered (0 open, 1 close) and its write is
retried when the answer is lost, like a digital output. A fault proxy holds the first
write to that register (matched by its address) past the master's request timeout; the
master reconnects, retries, and later asks for the other state. The held frame lands
only once the simulator executed that later write (released on what the simulator did,
never on a time): the gripper must still end in the later state, as a digital output
does (``tests/test_io_stale.py``). The judge is the simulator's own motion log and
register. An AsyncRobot's close() cancelled during that watch ends it: once the
``CancelledError`` reached the caller, the master writes nothing more to the register
(the held frame, landing then, is the documented limit: no longer watched).
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy
from fault_proxy import Rule as FaultRule
from test_aio import run, until
from tmmaster import (
    PollPolicy,
    RegisterGripper,
    RetryPolicy,
    Robot,
    RobotError,
    TimeoutPolicy,
    aio,
)
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: The article map's gripper register (0 open, 1 close).
GRIPPER_REGISTER = 0x0210
#: The master's answer timeout, s: the held frame times out, the retry goes through.
TIMEOUT_S = 0.2
#: Its total time bounds how long a later write watches for the held frame (never
#: reached here: the frame lands as soon as the later write was executed).
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


def _release_when(condition: Callable[[], bool], release: threading.Event) -> threading.Thread:
    def watch() -> None:
        while not condition() and not release.wait(0.005):
            pass
        release.set()

    thread = threading.Thread(target=watch, name="release-held-gripper-frame")
    thread.start()
    return thread


def test_a_late_open_frame_never_leaves_a_closed_article_gripper_open(
    sim: Simulator, proxy: FaultProxy
) -> None:
    release = threading.Event()
    held = proxy.add(FaultRule("hold", address=GRIPPER_REGISTER, release=release))
    sim.clear_request_log()
    # The held open frame lands once the simulator executed the close.
    watcher = _release_when(lambda: 1 in register_writes(sim), release)
    try:
        with Robot(
            "127.0.0.1",
            proxy.port,
            profile="article",
            retry=RETRY,
            timeouts=TimeoutPolicy(request_s=TIMEOUT_S),
            polling=PollPolicy(interval_s=0.01),
            gripper=RegisterGripper(settle_s=0.1),
        ) as robot:
            robot.wait_until_ready(timeout_s=5)
            robot.gripper.open()  # times out, reconnects, retries: open
            assert held.times == 0  # the hold fired on that write
            robot.gripper.close()
            proxy.wait_held()
            sim.wait_for(lambda: register_writes(sim).count(0) >= 2, timeout=3)
            # The late open reached the robot after the close; the master undid it.
            assert register_writes(sim)[-1] == 1, register_writes(sim)
            assert sim.field("gripper_command") == 1
            kinds = [m.kind for m in sim.motion_log()]
            assert kinds[-1] == "gripper_close", kinds
    finally:
        release.set()
        watcher.join(5)


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
            timeouts=TimeoutPolicy(request_s=TIMEOUT_S),
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


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_gripper_command_while_the_arm_runs_a_move_is_refused(
    tm_simulator_factory: Factory, profile: str
) -> None:
    # A move of about 0.6 s wall time: the gripper command comes while it runs.
    sim = tm_simulator_factory(profile, time_scale=2.0)
    with Robot(sim.url, profile=profile, polling=PollPolicy(interval_s=0.01)) as robot:
        robot.wait_until_ready(timeout_s=5)
        motion = robot.start_move(robot.pose().offset(dz=-100), speed=10)
        sim.wait_for(lambda: len(sim.motion_log()) == 1, timeout=2)
        with pytest.raises(RobotError):
            robot.gripper.close()
        motion.wait()
    assert [m.kind for m in sim.motion_log()] == ["ptp"]
