"""article: two live Robots of one process on one robot, one owing a Stop the other delivered.

docs/safety.md: a running move's Stop the link could not carry is owed by the process
(``_command._STOPS_OWED``): whichever ``Robot`` on that robot calls next delivers it
first. Here both ``Robot`` objects stay open (a commander and a second one, reading or
commanding in turn): the first gives a long move up while a proxy outage cuts the link
(its Stop fails, owed), the second's first call after the outage delivers the Stop, the
operator resets the robot, and the second starts a move of its own. Then the first
``Robot`` makes a call (a status read) and is closed, or is closed at once.

What must hold, judged on the simulator: the Stop is delivered once the link is back
(the arm does not run on to the target given up), and the debt, once delivered, is
settled for the whole process: the first Robot's next call and its ``close()`` send no
second Stop, which
would halt the second Robot's move and put the robot in error. The second Robot's move
ends done, at its target.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

import tmmaster
from fault_proxy import FaultProxy
from safety_invariant import at_rest
from test_hunt6_owed_stop_new_robot import FAR, OUTAGE_S, PATIENT, START, article_robot
from test_hunt6_owed_stop_new_robot import RETRY as SHORT
from tmmaster import Pose
from tmmaster.sim import Cell, Simulator

Factory = Callable[..., Simulator]

LOWER = Pose(300, -200, 120, 180, 0, 90)


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    # No part on the table: where the given-up move stops depends on when the link is
    # back, and from some of those poses the way down to LOWER brushes the default part
    # (a collision error that is not this test's subject).
    return tm_simulator_factory("article", time_scale=2.0, cell=Cell(scene=[]))


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


@pytest.mark.parametrize("then", ["status", "close"])
def test_a_stop_one_robot_owed_and_another_delivered_is_not_sent_again(
    sim: Simulator, proxy: FaultProxy, then: str
) -> None:
    with article_robot(proxy, SHORT) as first, article_robot(proxy, PATIENT) as second:
        first.wait_until_ready(timeout_s=5)
        second.wait_until_ready(timeout_s=5)
        first.move_to(START, speed=100)
        given_up = first.start_move(FAR, speed=7)  # about 3.5 s to go at 2x
        sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=20)
        proxy.outage(OUTAGE_S)
        with pytest.raises(tmmaster.TransportError):
            given_up.wait()  # given up: the link is gone, and with it the Stop
        if given_up.stop_delivered is not False:
            raise RuntimeError("set-up: the Stop was delivered during the outage")
        second.status()  # the first call once the link is back: delivers the Stop
        sim.wait_for(at_rest(sim), timeout=15, interval=0.05)
        assert sim.tcp_pose().distance_to(FAR) > 50, "the given-up move ran on"
        sim.clear_error()  # the operator resets the robot the Stop left in error
        second.wait_until_ready(timeout_s=5)
        move = second.start_move(LOWER, speed=10)
        sim.wait_for(lambda: sim.tcp_pose().z < 190, timeout=10)
        if then == "status":
            first.status()  # must not send the delivered Stop again
        if not sim.field("motion_status"):
            raise RuntimeError("set-up: the second Robot's move ended before the first closed")
        first.close()  # nor may its close
        move.wait()
        assert sim.tcp_pose().is_close(LOWER), sim.tcp_pose()
        assert not sim.field("error_code")
