"""The seam between Motion and its follower: abandon acts once; settings set later apply."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import (
    AcknowledgeTimeoutError,
    MovePhase,
    Pose,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
)
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
    assert motion.withdrawn is True
    assert motion.abandoned
