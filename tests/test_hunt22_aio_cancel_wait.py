"""``await motion.cancel()`` (``tmmaster.aio``) while another task awaits the same motion.

Every call of an ``AsyncRobot`` runs on the robot's thread, one at a time. A cancel
awaited while another task's ``await motion`` (its wait) ran there was queued behind
that wait: the move ran to its end at the target, and only then did the cancel run,
find it finished and return True. A task that cancels a running move got a move done.
Now the cancel makes a running wait on its motion give up first (as a cancelled wait
does: the robot's stop request, the arm stopped), then runs. The judge is the
simulator: the arm stopped short, never resumed, and its motion log
(tests/safety_invariant.py).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

import pytest

from safety_invariant import Issued, check
from test_fleet import late_ack_over, ticks_pass
from test_motion_cancel import braked
from tmmaster import PollPolicy, Pose, StopRequestedError, aio
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
PROFILES = ["tmflow", "article"]
A = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)


@pytest.mark.parametrize("profile", PROFILES)
def test_a_cancel_while_another_task_awaits_the_move_stops_it_short(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5.0)
    issued = [Issued(A, 0.0, 0.0, "done")]

    async def scenario() -> None:
        async with aio.connect(
            sim.url, profile=profile, polling=PollPolicy(interval_s=0.01)
        ) as robot:
            await robot.move_to(A, speed=100)
            issued.append(Issued(FAR, time.monotonic()))
            motion = await robot.start_move(FAR, speed=10)
            waiter = asyncio.ensure_future(motion.wait())
            while len(sim.motion_log()) < 2:  # the arm is on its way
                await asyncio.sleep(0.002)
            assert await motion.cancel() is True
            issued[1].ended_at, issued[1].outcome = time.monotonic(), "cancelled"
            # Before: the cancel came after the move had ended at FAR, done.
            assert motion.motion.abandoned
            assert not motion.motion.done
            assert motion.motion.stop_delivered is True
            with pytest.raises(StopRequestedError):
                await waiter
            stopped_at = braked(sim)
            assert not stopped_at.is_close(FAR)
            ticks_pass(sim, 10)
            assert sim.tcp_pose().is_close(stopped_at)  # never resumed

    asyncio.run(scenario())
    check(issued, sim.motion_log())


@pytest.mark.parametrize("profile", PROFILES)
def test_a_cancel_while_another_task_awaits_the_acknowledgement_withdraws_it(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # The acknowledgement would come 60 simulated s (1.5 s) after the write.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=60"])
    issued: list[Issued] = []

    async def scenario() -> None:
        async with aio.connect(
            sim.url, profile=profile, polling=PollPolicy(interval_s=0.01)
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(A, time.monotonic()))
            motion = await robot.start_move(A, speed=60)
            waiter = asyncio.ensure_future(motion.wait())
            await asyncio.sleep(0)  # the wait is submitted first
            assert await motion.cancel() is True
            issued[0].ended_at, issued[0].outcome = time.monotonic(), "cancelled"
            assert motion.motion.abandoned
            with pytest.raises(StopRequestedError):
                await waiter
            sim.clear_faults()
            late_ack_over(sim, motion.motion)

    asyncio.run(scenario())
    check(issued, sim.motion_log())
    assert sim.motion_log() == ()


@pytest.mark.parametrize("profile", PROFILES)
def test_a_cancel_with_no_wait_running_still_runs_in_turn(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # The control: no wait on the motion runs; a cancel of a finished move is nothing.
    sim = tm_simulator_factory(profile)

    async def scenario() -> None:
        async with aio.connect(
            sim.url, profile=profile, polling=PollPolicy(interval_s=0.01)
        ) as robot:
            motion = await robot.start_move(A, speed=100)
            await motion
            assert await motion.cancel() is True
            assert motion.motion.done
            assert not motion.motion.abandoned
            await robot.move_to(A.offset(dz=20), speed=100)  # the project still runs

    asyncio.run(scenario())
    assert len(sim.motion_log()) == 2
