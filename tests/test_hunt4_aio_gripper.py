"""An awaited gripper command cancelled (``asyncio.wait_for``, ``task.cancel()``).

docs/safety.md: an awaited call cancelled is given up as a sync wait ended by an
exception is (a command the robot has not taken is withdrawn, a running one stopped)
before the ``CancelledError`` propagates; a stand-alone gripper's move the master gives
up is stopped before the error reaches the caller. Here the gripper commands of an
``aio.AsyncRobot``:

- on ``tmflow`` a gripper command goes through the robot program's sequence handshake
  like a move: its FC16 to the command block is held by a FaultProxy, the awaited
  ``close()`` is cancelled (``asyncio.wait_for``, ``task.cancel()``) while it is held,
  and the frame lands only after the ``CancelledError`` (or ``TimeoutError``) reached
  the caller: the program must never run it;
- a tmflow gripper close cancelled while the program runs it ends the project (so
  Play cannot resume it), and the operator's Play afterwards never runs it again;
- a stand-alone blog-2fg7's move cancelled while its fingers travel must be stopped
  short of its target (the gripper's stop written before the ``CancelledError``).

The judge is the simulator: its motion log and the simulated fingers.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Coroutine, Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from pendant import press_play_pause
from sim_speeds import SUITE_TICK_HZ
from test_aio import run, until
from tmmaster import (
    Blog2FG7Gripper,
    GripperLink,
    PollPolicy,
    RetryPolicy,
    Robot,
    TimeoutPolicy,
    aio,
    gripper_profile,
)
from tmmaster.sim import RobotSetup, Simulator, Timing

Factory = Callable[..., Simulator]
#: tmflow: where a gripper command's one FC16 starts (seq, then the command words).
GRIPPER_COMMAND = 9014


def gripper_actions(sim: Simulator) -> list[tuple[str, float]]:
    """The gripper actions the robot program started, with their wall times."""
    return [(m.kind, m.wall_time) for m in sim.motion_log() if m.kind.startswith("gripper")]


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=20.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


async def by_wait_for(call: Coroutine[Any, Any, Any], proxy: FaultProxy) -> None:
    with pytest.raises(TimeoutError):
        await asyncio.wait_for(call, 0.2)
    assert proxy.played("hold")


async def by_cancel(call: Coroutine[Any, Any, Any], proxy: FaultProxy) -> None:
    task = asyncio.ensure_future(call)
    await until(lambda: proxy.played("hold"))
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task


#: The long case's heartbeat: a 1 s TTL (master_ttl_ms), not the default 2 s, so that a
#: write held longer than it is waited out in half the time; not less: a loaded machine
#: once kept a beat from running for that long (tests/test_heartbeat.py).
SHORT_TTL = {"heartbeat_s": 0.25, "heartbeat_ttl_s": 1.0}


@pytest.mark.parametrize("cancel", [by_wait_for, by_cancel], ids=["wait_for", "cancel"])
@pytest.mark.parametrize("request_s", [0.5, 1.5])
def test_a_cancelled_tmflow_gripper_close_whose_write_was_held_never_runs(
    sim: Simulator,
    proxy: FaultProxy,
    cancel: Callable[[Coroutine[Any, Any, Any], FaultProxy], Coroutine[Any, Any, None]],
    request_s: float,
) -> None:
    # request_s 0.5: the write's own timeout ends inside the cancellation's clean-up (the
    # default 2 s TTL, as before); 1.5 s: longer than the program's master_ttl_ms (SHORT_TTL's
    # 1 s; was 3 s against the default 2 s). Two safeguards each keep the late frame from
    # running at 0.5 s: the cancel record, and the new session a master beats with once a
    # command it meant to resend ended; both taken out, it runs.
    heartbeat = SHORT_TTL if request_s > 1 else {}
    release = threading.Event()

    async def scenario() -> float:
        async with aio.connect(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=request_s, gripper_settle_s=0.05, **heartbeat),
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            await robot.gripper.open()
            opened = len(gripper_actions(sim))
            # A gripper command is written from seq on (9014: no target words).
            proxy.add(Rule("hold", function_code=16, address=GRIPPER_COMMAND, release=release))
            await cancel(robot.gripper.close(), proxy)
            ended_at, ended_wall = time.monotonic(), time.time()
            release.set()  # the held close lands now, after the master gave it up
            proxy.wait_held()
            start = sim.ticks
            await until(lambda: sim.ticks >= start + 20)
            landed = [
                r
                for r in sim.request_log
                if r.function_code == 16
                and r.address == GRIPPER_COMMAND
                and r.count > 2  # not a cancel record
                and r.time > ended_wall
            ]
            assert landed, "the held gripper command never reached the robot"
            assert [k for k, _ in gripper_actions(sim)[opened:]] == [], sim.motion_log()
            return ended_at

    try:
        ended_at = run(scenario)
    finally:
        release.set()
    late = [m for m in sim.motion_log() if m.wall_time > ended_at]
    assert not late, f"started after the cancelled close ended: {late}"


def fingers(sim: Simulator) -> tuple[bool, float]:
    state = sim.call(lambda: sim.backend.gripper_state())
    return bool(state.moving), float(state.width_mm)


@pytest.mark.parametrize("how", ["cancel", "wait_for"])
def test_a_cancelled_stand_alone_gripper_close_is_stopped_before_the_error(how: str) -> None:
    # blog-2fg7 at 100 mm/s, real time: 39 -> 0 mm takes about 0.39 s.
    timing = Timing(tick_hz=SUITE_TICK_HZ, init_time_s=0.0)  # ready at once: not the subject
    sim = Simulator("tmflow", robot=RobotSetup(gripper="blog-2fg7"), time_scale=1.0, timing=timing)
    sim.start()
    try:
        assert sim.gripper_port is not None
        retry = RetryPolicy(attempts=5, total_time_s=2.0, initial_backoff_s=0.01, jitter_s=0.0)
        device = GripperLink("127.0.0.1", sim.gripper_port, poll_interval_s=0.01, retry=retry)
        gripper = Blog2FG7Gripper(gripper_profile("blog-2fg7"), device)
        robot = Robot("127.0.0.1", sim.port, gripper=gripper, polling=PollPolicy(interval_s=0.01))
        widths: list[float] = []

        async def scenario() -> None:
            async with aio.AsyncRobot(robot) as arobot:
                await arobot.wait_until_ready(timeout_s=5)
                if how == "cancel":
                    task = asyncio.ensure_future(arobot.gripper.close())
                    await until(lambda: fingers(sim)[0])
                    task.cancel()
                    with pytest.raises(asyncio.CancelledError):
                        await task
                else:
                    with pytest.raises(TimeoutError):
                        await asyncio.wait_for(arobot.gripper.close(), 0.1)
                # Stopped before the error: a few ticks on, the fingers are at rest.
                start = sim.ticks
                await until(lambda: sim.ticks >= start + 3)
                moving, width = fingers(sim)
                widths.append(width)
                assert not moving, f"fingers still moving after the cancelled close ({width} mm)"

        run(scenario)
        start = sim.ticks
        sim.wait_for(lambda: sim.ticks >= start + 20, timeout=5)
        moving, width = fingers(sim)
        assert not moving
        assert width > 15.0, f"the cancelled close went on to {width:.1f} mm"
        assert abs(width - widths[0]) < 0.5, (widths[0], width)
    finally:
        sim.close()


@pytest.mark.parametrize(
    ("how", "ack"), [("cancel", "prompt"), ("wait_for", "prompt"), ("wait_for", "late")]
)
def test_a_tmflow_gripper_close_cancelled_while_it_runs_never_runs_again(
    tm_simulator_factory: Factory, how: str, ack: str
) -> None:
    # Half real time: the program's gripper close takes a while (as in
    # tests/test_hunt2_gripper_restart.py). Cancelled while it runs, it is given up
    # before the error reaches the caller; the operator's Play afterwards never runs it
    # again, and nothing starts after the error. "late": the program takes the close 1 s
    # late, so wait_for's 50 ms give it up before it runs (withdrawn, as a loaded
    # machine did once): the project runs on.
    faults = ["late_ack:delay_s=0.5"] if ack == "late" else []
    sim = tm_simulator_factory("tmflow", time_scale=0.5, faults=faults)

    async def scenario() -> tuple[float, bool]:
        async with aio.connect(
            "127.0.0.1",
            sim.port,
            profile="tmflow",
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(gripper_settle_s=0.05),
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            if how == "cancel":
                task = asyncio.ensure_future(robot.gripper.close(timeout_s=5.0))
                await until(lambda: [k for k, _ in gripper_actions(sim)] == ["gripper_close"])
                task.cancel()
                with pytest.raises(asyncio.CancelledError):
                    await task
            else:
                with pytest.raises(TimeoutError):
                    await asyncio.wait_for(robot.gripper.close(timeout_s=5.0), 0.05)
            ended_at = time.monotonic()
            motion = robot.last_motion
            assert motion is not None
            assert motion.abandoned
            return ended_at, motion.stop_delivered is True

    ended_at, stop_sent = run(scenario)
    sim.clear_faults()
    closes = [k for k, _ in gripper_actions(sim)]
    possible = ([],) if ack == "late" else ([], ["gripper_close"])
    assert closes in possible, closes
    if closes or stop_sent:
        # It ran (or its withdraw went unanswered), so it was stopped: the Stop (or the
        # program's watchdog on the cancel record) ended the project, so that Play cannot
        # resume it. The operator starts the project again.
        sim.wait_for(lambda: not sim.field("project_running"), timeout=3)
        press_play_pause(sim)
    # Else withdrawn before it ran (wait_for's 50 ms, on a loaded machine): the project
    # runs on, and the toggle would pause it.
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2)
    beat = sim.field("heartbeat")
    sim.wait_for(lambda: sim.field("heartbeat") != beat, timeout=2)
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + 20, timeout=5)
    assert [k for k, _ in gripper_actions(sim)] == closes, sim.motion_log()
    late = [m for m in sim.motion_log() if m.wall_time > ended_at]
    assert not late, f"started after the cancelled close ended: {late}"
