"""Regressions found by the review of this session's changes (docs/safety.md's guarantees).

Each test names what it guards; the robot's motion log and arm judge where it moved.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from safety_invariant import Issued
from test_hunt22_cancel_threads import FAR, PROFILES, A, Owner, robot_of
from test_motion_cancel import braked
from tmmaster import RobotFaultError, StopRequestedError
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]


@pytest.mark.parametrize("profile", PROFILES)
def test_a_robot_fault_a_cancel_only_saw_reaches_the_owner_as_the_fault(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    """The robot faults on its own while the owner waits; ``cancel()`` from another
    thread polls first and sees the fault. The owner's wait must say the fault (the
    robot is in error: nothing it runs goes on), not "cancelled": a give-up made the
    robot report nothing here."""
    sim = tm_simulator_factory(profile, time_scale=5.0)
    with robot_of(sim, profile) as robot:
        robot.move_to(A, speed=100)
        motion = robot.start_move(FAR, speed=10)
        sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)  # on its way
        channel = robot._follower._channel
        real_poll = channel.poll
        cancelled = threading.Event()
        owners: list[int | None] = []

        def held_poll(ticket: object) -> object:
            # The owner's poll waits for the cancel to be over: it sees the fault after.
            if owners and threading.get_ident() == owners[0]:
                cancelled.wait(10)
            return real_poll(ticket)  # type: ignore[arg-type]

        channel.poll = held_poll  # type: ignore[method-assign]
        owner = Owner(motion.wait, Issued(FAR, time.monotonic()))
        owners.append(owner.thread.ident)
        sim.call(lambda: sim._controller._enter_error(0x1F4, "a fault of its own"))
        braked(sim)
        motion.cancel()
        cancelled.set()
        owner.join()
        assert isinstance(owner.error, RobotFaultError), repr(owner.error)
        assert not isinstance(owner.error, StopRequestedError)
