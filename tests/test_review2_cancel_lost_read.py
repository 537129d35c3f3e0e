"""review2: a cancel() whose first poll loses one read is still a cancel to the owner.

67b3f6f made cancel()'s first poll a single attempt (``retry=False``): one lost read
now fails it where the retry policy used to absorb it. The failed poll's clean-up
(``_Following``) gives the motion up with that read's error as the reason, before
cancel() gives it up with StopRequestedError; since 7efbdd0 the owner's wait turns the
robot's report of the give-up into StopRequestedError only when the reason is a stop
request. So a thread waiting on the motion was told the robot failed (a fault of the
project, a refused or short move) when the user had cancelled it: a pick-and-place
report or a script then handles a user stop as a robot fault.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, check
from test_hunt22_cancel_threads import PROFILES, Owner
from test_lostreads_giveup import FAR, SLOW, TIME_SCALE
from test_lostreads_giveup import START as A
from tmmaster import PollPolicy, Robot, StopRequestedError, TimeoutPolicy
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]


@pytest.mark.parametrize("profile", PROFILES)
def test_a_cancel_whose_first_poll_lost_a_read_reaches_the_owner_as_a_cancel(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=TIME_SCALE)
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile=profile,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.3),
        )
        with robot:
            robot.move_to(A, speed=100)
            issued = [Issued(A, 0.0, 0.0, "done")]
            motion = robot.start_move(FAR, speed=SLOW)
            issued.append(Issued(FAR, time.monotonic()))
            sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)  # on its way
            channel = robot._follower._channel
            real_poll = channel.poll
            cancelled = threading.Event()
            owners: list[int | None] = []

            def held_poll(ticket: object, *retry: bool) -> object:
                # The owner's poll waits for the cancel to be over: only cancel() reads.
                if owners and threading.get_ident() == owners[0]:
                    cancelled.wait(10)
                return real_poll(ticket, *retry)  # type: ignore[arg-type]

            channel.poll = held_poll  # type: ignore[method-assign]
            owner = Owner(motion.wait, issued[1])
            owners.append(owner.thread.ident)
            # The next read (cancel()'s first poll, the owner being held) is lost.
            for function_code in (3, 4):
                proxy.add(Rule("drop_request", function_code=function_code))
            try:
                assert motion.cancel() is True
            finally:
                proxy.clear()
                cancelled.set()
            issued[1].ended_at, issued[1].outcome = time.monotonic(), "cancelled"
            owner.join()
            assert isinstance(owner.error, StopRequestedError), repr(owner.error)
            sim.wait_for(at_rest(sim), timeout=15, interval=0.1)
            assert sim.tcp_pose().distance_to(FAR) > 50  # stopped short, not run on
            check(issued, sim.motion_log())
