"""A running move whose Stop the link could not carry is stopped once the link is back.

docs/safety.md: a move the master gives up because the link was lost is "stopped, once
the link is back". On ``tmflow`` a give-up the link could not carry stays owed (the
cancel record). The ``article`` profile has no cancel record: its Stop is what ends a
running move. The link is cut (a proxy outage, started once the arm moves) for longer
than the retry policy rides out: the wait gives up and its Stop fails too. The arm runs
on meanwhile (nothing can reach it); but once the link is back, the master's next call
must deliver that Stop before anything else, not leave the arm to finish the move the
master gave up. The judge is the simulator's TCP and motion log.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

import tmmaster
from fault_proxy import FaultProxy
from safety_invariant import at_rest
from tmmaster import Fleet, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

START = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)
#: The outage outlasts the poll's retries and the Stop's (0.3 s each).
OUTAGE_S = 1.5
RETRY = RetryPolicy(attempts=2, total_time_s=0.3, initial_backoff_s=0.05, jitter_s=0)


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("article", time_scale=1.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def answered(robot: Robot) -> Callable[[], bool]:
    """True once ``robot.status()`` returns (a call of the master's, not a probe)."""

    def call() -> bool:
        try:
            robot.status()
        except tmmaster.TMMasterError:
            return False
        return True

    return call


def test_a_stop_lost_with_the_link_is_delivered_by_the_next_call(
    sim: Simulator, proxy: FaultProxy, driver_or_fleet: Fleet | None
) -> None:
    with Robot(
        "127.0.0.1",
        proxy.port,
        profile="article",
        link=driver_or_fleet,
        polling=PollPolicy(interval_s=0.02),
        retry=RETRY,
        timeouts=TimeoutPolicy(request_s=0.2),
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(START, speed=100)
        motion = robot.start_move(FAR, speed=5)  # about 8 s to go
        sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=20)
        proxy.outage(OUTAGE_S)
        with pytest.raises(tmmaster.TransportError):
            motion.wait()  # given up: the link is gone, and with it the Stop
        # The master's next calls: refused while the Stop still cannot be delivered
        # (CommandStateUnknownError), then, the link back, the Stop goes first.
        sim.wait_for(answered(robot), timeout=OUTAGE_S + 5, interval=0.1)
        sim.wait_for(at_rest(sim), timeout=15, interval=0.1)  # to FAR: about 8 s
        rest = sim.tcp_pose()
        assert rest.distance_to(FAR) > 100, f"the given-up move ran on to {rest}"
        assert motion.stop_delivered is True
    assert [m.target for m in sim.motion_log()] == [START, FAR]
