"""The seam between Motion and its follower: abandon acts once; settings set later apply."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from types import SimpleNamespace

import pytest

import tmmaster._command as command_module
import tmmaster._following as following_module
import tmmaster._poller as poller_module
from tmmaster import (
    AcknowledgeTimeoutError,
    MovePhase,
    PollPolicy,
    Pose,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
)
from tmmaster._channels import Command, CommandKind, Observation, Ticket
from tmmaster._command import Motion, _MotionFollower
from tmmaster._logging import get_logger
from tmmaster._planning import Plan
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
APPROACH = Pose(300, -200, 200, 180, 0, 90)


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: SimFactory) -> SimFactory:
    """Simulators in memory: TCP is not the subject here."""
    return memory_simulator_factory


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_abandon_acts_once_and_never_after_the_move_finished(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=20)
    robot = robots(sim)
    reason = StopRequestedError("given up by the test")
    done = robot.move_to(APPROACH, speed=30)
    assert done.ticket.command is done.command
    robot._follower.abandon(done, reason)  # nothing left to withdraw or stop
    assert not done.abandoned
    assert (done.withdrawn, done.stop_delivered) == (None, None)
    assert done.phase is MovePhase.DONE

    # A slow move (about 2 s of wall time), given up on once acknowledged: it is stopped.
    running = robot.start_move(Pose(300, 200, 100, 180, 0, 90), speed=1)
    sim.wait_for(lambda: sim.field("motion_status" if profile == "article" else "robot_state") == 1)
    assert running.progress().phase is MovePhase.RUNNING
    robot._follower.abandon(running, reason)
    assert running.abandoned
    assert running.phase is MovePhase.FAILED
    assert (running.withdrawn, running.stop_delivered) == (None, True)
    running.stop_delivered = None
    robot._follower.abandon(running, reason)  # a second caller (close(), a wait) does nothing
    assert (running.withdrawn, running.stop_delivered) == (None, None)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_timeouts_assigned_after_construction_bound_the_wait(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # The acknowledgement comes 20 s of wall time late; the policy set afterwards says 0.1 s.
    sim = tm_simulator_factory(profile, time_scale=5, faults=["late_ack:delay_s=100"])
    robot = robots(sim)
    robot.timeouts = TimeoutPolicy(ack_timeout_s=0.1)
    assert robot.timeouts.ack_timeout_s == 0.1
    motion = robot.start_move(APPROACH, speed=30)
    with pytest.raises(AcknowledgeTimeoutError, match=r"within 0\.1 s"):
        motion.wait()
    # Withdrawn (article); tmflow's program answers its cancel as late as the command:
    # unanswered within the bound, the project is stopped instead.
    assert motion.withdrawn is True or motion.stop_delivered is True
    assert motion.abandoned


class FakeClock:
    """A monotonic clock that moves only when a poll or a sleep spends time."""

    def __init__(self) -> None:
        self.now = 100.0

    def monotonic(self) -> float:
        return self.now


class ClockEvent:
    """A stop event never set: waiting on it spends the fake clock's time."""

    def __init__(self, clock: FakeClock) -> None:
        self._clock = clock

    def is_set(self) -> bool:
        return False

    def wait(self, timeout: float) -> bool:
        self._clock.now += timeout
        return False


class TimedChannel:
    """A robot whose every poll takes ``poll_s``; it takes the command at once and
    reports the end from ``end_at`` on (a poll that starts then sees it)."""

    can_stop = False

    def __init__(self, clock: FakeClock, poll_s: float, end_at: float) -> None:
        self._clock = clock
        self._poll_s = poll_s
        self._end_at = end_at
        self.poll_starts: list[float] = []

    def poll(self, ticket: Ticket) -> Observation:
        started = self._clock.now
        self.poll_starts.append(started)
        self._clock.now += self._poll_s
        if not ticket.acknowledged:
            ticket.acknowledged = True
            ticket.acknowledged_at = self._clock.now
        return Observation(True, started >= self._end_at, None, None)


@pytest.mark.parametrize("poll_s", [0.0005, 0.003, 0.012])
def test_polls_are_paced_from_each_polls_start_not_its_end(
    monkeypatch: pytest.MonkeyPatch, poll_s: float
) -> None:
    clock = FakeClock()
    fake_time = SimpleNamespace(monotonic=clock.monotonic)
    monkeypatch.setattr(command_module, "time", fake_time)
    monkeypatch.setattr(poller_module, "time", fake_time)
    monkeypatch.setattr(following_module, "time", fake_time)
    policy = PollPolicy()
    expected_s = 1.0
    sent_at = clock.now
    # The robot reports the end 5 ms after the expected end, inside the dense window.
    ack_at = sent_at + poller_module.ACK_DELAY_S + poll_s
    end_at = ack_at + expected_s + 0.005
    channel = TimedChannel(clock, poll_s, end_at)
    follower = _MotionFollower(
        channel,  # type: ignore[arg-type]
        ClockEvent(clock),  # type: ignore[arg-type]
        get_logger("tmmaster.test_following").bind(robot="timed"),
        polling=policy,
        timeouts=TimeoutPolicy(),
        position_tolerance_mm=0.1,
        orientation_tolerance_deg=0.1,
    )
    ticket = Ticket(Command(CommandKind.GRIPPER_CLOSE), [], sent_at)
    plan = Plan(start=None, joints=None, target=None, expected_s=expected_s, timeout_s=10)
    motion = Motion(follower, ticket, plan)
    follower.wait(motion, None)
    assert motion.done
    assert motion.reported_finished_at == clock.now
    starts = channel.poll_starts
    dense = [b - a for a, b in itertools.pairwise(starts) if b > end_at - 0.02]
    assert dense, "no poll in the window around the expected end"
    # Start to start: the dense interval, or back to back when a poll takes longer.
    for gap in dense:
        assert gap == pytest.approx(max(poller_module.DENSE_S, poll_s))
    # The end is seen at most one interval plus one poll after the robot reported it.
    assert clock.now - end_at <= max(poller_module.DENSE_S, poll_s) + poll_s + 1e-9
    # Never more than one poll per dense interval, however long the polls take.
    assert (
        min(b - a for a, b in itertools.pairwise(starts))
        >= min(poller_module.DENSE_S, poll_s) - 1e-9
    )
