"""``Motion.cancel()`` from another thread while the owning thread waits on the motion.

``cancel()`` polls once (``progress()``), then gives the command up; the owner's
``wait()`` polls on its own thread meanwhile: two threads on one robot's link and one
ticket. What must hold, judged on the simulator's motion log and arm
(tests/safety_invariant.py), never on what the master believes:

- the command is withdrawn, or the arm is stopped short, and never runs (again) later;
- the owner's ``wait()`` never returns as if the move were done while it was given up
  short of its target: it raises, and a wait after it says the motion was given up;
- a second ``cancel()`` (from either thread) and a ``cancel()`` after the move finished
  change nothing on the robot.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from test_fleet import late_ack_over, ticks_pass
from test_motion_cancel import braked
from tmmaster import (
    Fleet,
    MovePhase,
    PollPolicy,
    Pose,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
    TMMasterError,
)
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
PROFILES = ["tmflow", "article"]
A = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)
#: The speed of the moves to FAR that a test cancels, %: 12.7 s simulated, 2.5 s of wall
#: time at 5x, so they still run when the cancel comes on a loaded machine (at 10 %,
#: 0.8 s, one was over first at 24 workers on two cores).
CANCELLED_SPEED = 3


def robot_of(sim: Simulator, profile: str) -> Robot:
    return Robot(sim.url, profile=profile, polling=PollPolicy(interval_s=0.01))


class Owner:
    """``motion.wait()`` on its own thread, recording how it ended."""

    def __init__(self, wait: Callable[[], None], issued: Issued) -> None:
        self.issued = issued
        self.error: BaseException | None = None
        self.started = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(wait,))
        self.thread.start()
        self.started.wait(5)

    def _run(self, wait: Callable[[], None]) -> None:
        self.started.set()
        try:
            wait()
        except TMMasterError as exc:
            self.error = exc
            self.issued.outcome = type(exc).__name__
        else:
            self.issued.outcome = "done"
        self.issued.ended_at = time.monotonic()

    def join(self) -> None:
        self.thread.join(15)
        assert not self.thread.is_alive(), "the owner's wait never ended"


@pytest.mark.parametrize("profile", PROFILES)
def test_a_running_move_cancelled_from_another_thread_is_stopped_and_its_wait_raises(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5.0)
    with robot_of(sim, profile) as robot:
        robot.move_to(A, speed=100)
        issued = [Issued(A, 0.0, 0.0, "done"), Issued(FAR, time.monotonic())]
        motion = robot.start_move(FAR, speed=CANCELLED_SPEED)
        owner = Owner(motion.wait, issued[1])
        sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)  # on its way
        assert motion.cancel() is True
        given_up_at = time.monotonic()
        owner.join()
        assert motion.stop_delivered is True
        assert motion.abandoned
        assert not motion.done
        # The owner's wait raised, saying the give-up (not blaming the robot for what
        # the give-up made it report: "the TMflow project is stopped" on tmflow, "robot
        # reported the move finished but the TCP is ... mm from the target" on article).
        assert isinstance(owner.error, StopRequestedError), repr(owner.error)
        assert "cancelled or given up" in str(owner.error)
        stopped_at = braked(sim)
        assert not stopped_at.is_close(FAR)
        ticks_pass(sim, 10)
        assert sim.tcp_pose().is_close(stopped_at)  # never resumed
        with pytest.raises(StopRequestedError):
            motion.wait()
        assert motion.cancel() is True  # twice: nothing more
    issued[1].ended_at = min(issued[1].ended_at or given_up_at, given_up_at)
    check(issued, sim.motion_log())


@pytest.mark.parametrize("profile", PROFILES)
def test_a_move_not_yet_taken_cancelled_from_another_thread_never_runs(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # The acknowledgement would come 60 simulated s (1.5 s) after the write: the owner
    # waits for it, polling, while the other thread cancels.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=60"])
    with robot_of(sim, profile) as robot:
        robot.wait_until_ready(timeout_s=5)
        issued = [Issued(A, time.monotonic())]
        motion = robot.start_move(A, speed=60)
        owner = Owner(motion.wait, issued[0])
        assert motion.cancel() is True
        given_up_at = time.monotonic()
        owner.join()
        # Before: "robot program rejected command 1: cancelled" (tmflow), "robot reported
        # the move finished but the TCP is at ..." (article, the withdraw's cleared register
        # read as the acknowledgement).
        assert isinstance(owner.error, StopRequestedError), repr(owner.error)
        assert motion.abandoned
        assert motion.phase is MovePhase.FAILED
        assert motion.withdrawn is True
        sim.clear_faults()
        late_ack_over(sim, motion)  # a command still armed would have run by now
    issued[0].ended_at = given_up_at
    issued[0].outcome = "cancelled"
    check(issued, sim.motion_log())
    assert sim.motion_log() == ()


@pytest.mark.parametrize("profile", PROFILES)
def test_two_threads_cancelling_at_once_give_it_up_once(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5.0)
    with robot_of(sim, profile) as robot:
        robot.move_to(A, speed=100)
        motion = robot.start_move(FAR, speed=CANCELLED_SPEED)
        sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)
        results: list[bool] = []
        go = threading.Barrier(2)

        def cancel() -> None:
            go.wait(5)
            results.append(motion.cancel())

        threads = [threading.Thread(target=cancel) for _ in range(2)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(15)
        assert results == [True, True]
        assert motion.stop_delivered is True
        stopped_at = braked(sim)
        assert not stopped_at.is_close(FAR)
        ticks_pass(sim, 10)
        assert sim.tcp_pose().is_close(stopped_at)
    assert len(sim.motion_log()) == 2


@pytest.mark.parametrize("profile", PROFILES)
def test_a_cancel_from_another_thread_after_the_owner_saw_it_done_changes_nothing(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    with robot_of(sim, profile) as robot:
        motion = robot.start_move(A, speed=100)
        issued = Issued(A, time.monotonic())
        owner = Owner(motion.wait, issued)
        owner.join()
        assert owner.error is None
        results: list[bool] = []
        other = threading.Thread(target=lambda: results.append(motion.cancel()))
        other.start()
        other.join(10)
        assert results == [True]
        assert (motion.done, motion.abandoned, motion.stop_delivered) == (True, False, None)
        robot.move_to(A.offset(dz=20), speed=100)  # the project still runs
    check([issued, Issued(A.offset(dz=20), 0.0, 1.0, "done")], sim.motion_log())


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("interval_s", [0.01, 1.0])
def test_a_cancel_while_a_fleets_loop_polls_the_owners_wait(
    tm_simulator_factory: SimFactory, profile: str, interval_s: float
) -> None:
    # In a Fleet the owner's wait is polled by the fleet's event loop; cancel() polls
    # and gives up on the calling thread meanwhile. At 1 s nominal polling, only the
    # give-up can end the owner's wait early.
    sim = tm_simulator_factory(profile, time_scale=5.0)
    with Fleet() as fleet:
        robot = Robot(
            "127.0.0.1",
            sim.port,
            profile=profile,
            link=fleet,
            gripper=None,
            polling=PollPolicy(interval_s=0.01, predictive=False),
        )
        with robot:
            robot.wait_until_ready(timeout_s=5)
            robot.move_to(A, speed=100)
            # The owner's wait polls at interval_s (a wait reads the policy as it starts);
            # the set-up above, not this test's subject, at 0.01 s instead of 1 s a poll.
            robot.polling = PollPolicy(interval_s=interval_s, predictive=False)
            issued = [Issued(A, 0.0, 0.0, "done"), Issued(FAR, time.monotonic())]
            motion = robot.start_move(FAR, speed=CANCELLED_SPEED)
            owner = Owner(motion.wait, issued[1])
            sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)
            assert motion.cancel() is True
            given_up_at = time.monotonic()
            owner.join()
            assert isinstance(owner.error, StopRequestedError), repr(owner.error)
            assert motion.stop_delivered is True
            stopped_at = braked(sim)
            assert not stopped_at.is_close(FAR)
            ticks_pass(sim, 10)
            assert sim.tcp_pose().is_close(stopped_at)
    issued[1].ended_at = min(issued[1].ended_at or given_up_at, given_up_at)
    check(issued, sim.motion_log())


def test_a_cancel_from_another_thread_while_the_command_write_is_held_runs_nothing(
    tm_simulator_factory: SimFactory,
) -> None:
    # tmflow: the move's write (FC16 to 9000) is held in the network; another thread takes
    # the command as robot.last_motion (recorded before its first byte) and cancels it
    # while the sending thread waits for the write's answer. The held frame lands only
    # after the cancel returned: its number is used up, it never runs then.
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    release = threading.Event()
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            gripper=None,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.3, ack_timeout_s=2.0),
        )
        outcome: list[str] = []
        try:
            robot.connect()
            robot.wait_until_ready(timeout_s=5)
            proxy.add(Rule("hold", function_code=16, address=9000, release=release))
            issued = [Issued(FAR, time.monotonic())]

            def move() -> None:
                try:
                    robot.move_to(FAR, speed=50)
                    outcome.append("done")
                except TMMasterError as exc:
                    outcome.append(type(exc).__name__)

            mover = threading.Thread(target=move)
            mover.start()
            sim.wait_for(lambda: proxy.played("hold"), timeout=5)
            motion = robot.last_motion
            assert motion is not None
            assert motion.target == FAR
            assert motion.cancel() is True
            issued[0].ended_at, issued[0].outcome = time.monotonic(), "cancelled"
            release.set()  # the held frame lands now, after the cancel returned
            mover.join(10)
            assert not mover.is_alive()
            assert outcome
            assert outcome != ["done"], "the move was reported done"
            proxy.wait_held()
            ticks_pass(sim, 20)
            if sim.motion_log():
                # The sender's copy of the frame (resent: the program takes a number at
                # most once) can land before the cancel record: the program takes it, the
                # cancel's answer shows it taken, and the arm is stopped (docs/safety.md).
                # It never starts after the cancel returned (check() below).
                # Before: the sender, its copy landed, renewed the session while the
                # cancel waited for the program's answer, which then read as another
                # master's: "withdrawn", the arm moving (stopped by the robot program
                # seeing another master). On a loaded machine the copy can be taken before
                # cancel()'s own poll, which then sees it running and stops it without
                # trying a withdraw (withdrawn None: none was tried).
                assert motion.withdrawn is not True
                assert motion.stop_delivered is True
                assert not braked(sim).is_close(FAR)
            else:
                assert motion.withdrawn is True
        finally:
            release.set()
            robot.close()
    check(issued, sim.motion_log())
