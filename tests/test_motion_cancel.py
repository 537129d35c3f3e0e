"""``Motion.cancel()``: a move started with ``start_move`` and not waited for, given up as
a wait that ends early gives it up: withdrawn while the robot has not taken it, the arm
stopped once it runs, nothing once it finished. The judge is the simulator's motion log
and its arm (tests/safety_invariant.py), never what the master believes.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

import pytest

from safety_invariant import Issued, check
from test_fleet import late_ack_over, ticks_pass
from tmmaster import MovePhase, PollPolicy, Pose, Robot, aio
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
PROFILES = ["tmflow", "article"]
A = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)


def robot_of(sim: Simulator, profile: str) -> Robot:
    return Robot(sim.url, profile=profile, polling=PollPolicy(interval_s=0.01))


def braked(sim: Simulator) -> Pose:
    """Where the arm rests: the first pose that two control ticks later is the same."""
    for _ in range(100):  # 100 x 2 ticks: far longer than any stop brakes
        before = sim.tcp_pose()
        ticks_pass(sim, 2)
        if sim.tcp_pose().distance_to(before) < 1e-6:
            return before
    raise AssertionError("the arm never came to rest")


@pytest.mark.parametrize("profile", PROFILES)
def test_a_move_cancelled_before_the_robot_took_it_never_runs(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # The acknowledgement would come 20 simulated s (0.5 s) after the write.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])
    with robot_of(sim, profile) as robot:
        robot.wait_until_ready(timeout_s=5)
        issued = [Issued(A, time.monotonic())]
        motion = robot.start_move(A, speed=60)
        assert motion.cancel() is True
        issued[0].ended_at, issued[0].outcome = time.monotonic(), "cancelled"
        assert (motion.withdrawn, motion.stop_delivered) == (True, None)
        assert (motion.abandoned, motion.phase) == (True, MovePhase.FAILED)
        sim.clear_faults()
        late_ack_over(sim, motion)  # a command still armed would have run by now
        assert sim.motion_log() == ()
        assert motion.cancel() is True  # given up once: nothing more to do
        robot.move_to(A.offset(dz=20), speed=60)  # the robot takes the next command
    check([*issued, Issued(A.offset(dz=20), 0.0, 1.0, "done")], sim.motion_log())


@pytest.mark.parametrize("profile", PROFILES)
def test_a_running_move_cancelled_is_stopped_short(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5.0)
    with robot_of(sim, profile) as robot:
        robot.move_to(A, speed=100)
        motion = robot.start_move(FAR, speed=10)
        sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)  # the arm is on its way
        assert motion.cancel() is True
        assert (motion.stop_delivered, motion.abandoned) == (True, True)
        stopped_at = braked(sim)
        assert not stopped_at.is_close(FAR)
        ticks_pass(sim, 10)
        assert sim.tcp_pose().is_close(stopped_at)  # stays stopped: never resumed


def test_a_finished_move_cancelled_is_left_as_it_is(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory()
    with robot_of(sim, "tmflow") as robot:
        motion = robot.move_to(A, speed=100)
        assert motion.cancel() is True
        assert (motion.done, motion.abandoned, motion.stop_delivered) == (True, False, None)


def finished_on_the_robot(sim: Simulator, profile: str, seq: int) -> bool:
    """The robot's own record of the command done: tmflow's done_seq, article's idle arm
    with the command register cleared."""
    if profile == "tmflow":
        return bool(sim.field("done_seq") == seq)
    return sim.field("command") == 0 and sim.field("motion_status") == 0


@pytest.mark.parametrize("profile", PROFILES)
def test_a_move_that_finished_unwatched_is_left_as_it_is(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # Never polled, the motion did not know its move had finished: the give-up took it for
    # one still running. On tmflow it pressed Stop (the project stopped: the next move was
    # refused, "the TMflow project is stopped"); on article it reported the move
    # withdrawn although it ran.
    sim = tm_simulator_factory(profile)
    with robot_of(sim, profile) as robot:
        robot.move_to(A, speed=100)
        motion = robot.start_move(A.offset(dz=20), speed=100)
        sim.wait_for(lambda: finished_on_the_robot(sim, profile, motion.ticket.seq), timeout=5.0)
        assert motion.done is False  # nothing polled it
        assert motion.cancel() is True
        assert (motion.done, motion.abandoned) == (True, False)
        assert (motion.withdrawn, motion.stop_delivered) == (None, None)
        robot.move_to(A, speed=100)  # the project still runs: the next move is taken
    assert len(sim.motion_log()) == 3


@pytest.mark.parametrize("profile", PROFILES)
def test_an_awaited_cancel_gives_the_move_up_on_the_robots_thread(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])

    async def scenario() -> None:
        async with aio.connect(
            sim.url, profile=profile, polling=PollPolicy(interval_s=0.01)
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            motion = await robot.start_move(A, speed=60)
            assert await motion.cancel() is True
            assert motion.motion.withdrawn is True

    asyncio.run(scenario())
    sim.clear_faults()
    assert sim.motion_log() == ()
