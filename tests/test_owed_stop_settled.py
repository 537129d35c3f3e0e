"""article: a Stop the master owed, once delivered, is owed no more.

A running move's Stop that the link could not carry is owed by the process, per robot
address (docs/safety.md): whichever ``Robot`` on that address calls next delivers it
first. Here ``close()`` delivers it once the link is back (it returns True). From then on
nothing is owed: a later ``Robot`` at that address sends no Stop for it, whatever that
robot now runs (here the address answers for a TMflow project, whose Stop would end it).
And a Robot settling its own debt never strikes off another Robot's: it delivers that
Stop too, before anything else.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

import tmmaster
from fault_proxy import FaultProxy, Rule
from safety_invariant import at_rest
from test_aio import until
from test_hunt3_lost_stop import (
    FAR,
    OUTAGE_S,
    START,
    TIME_SCALE,
    article_robot,
    lost_by_the_link,
    moving_then_cut,
    proxy_accepts,
    run_long,
    stops_short,
)
from tmmaster import Robot, aio
from tmmaster.sim import Cell, Simulator

Factory = Callable[..., Simulator]


def test_a_stop_that_close_delivered_is_never_sent_again(tm_simulator_factory: Factory) -> None:
    # moving_then_cut's pace (its move to FAR at test_hunt3_lost_stop's SLOW %).
    sim = tm_simulator_factory("article", time_scale=TIME_SCALE)
    with FaultProxy(sim.port) as proxy:

        async def given_up_then_closed() -> None:
            async with aio.AsyncRobot(article_robot(proxy, None, 0.5, gripper=None)) as robot:
                await lost_by_the_link(await moving_then_cut(sim, proxy, robot), proxy)
                await until(proxy_accepts(proxy), timeout_s=OUTAGE_S + 2)
                assert await robot.close(timeout_s=2.0) is True  # the owed Stop, delivered
            await stops_short(sim)

        run_long(given_up_then_closed)
        # The same address now answers for a TMflow project.
        other = tm_simulator_factory("tmflow", time_scale=20)
        proxy.target_port = other.port
        with Robot("127.0.0.1", proxy.port, profile="tmflow") as again:
            again.move_to(START, speed=100)  # no Stop first: the project runs it
        assert other.field("project_running") == 1


def test_a_robot_settling_its_own_stop_leaves_another_robots_debt_owed_and_delivers_it(
    tm_simulator_factory: Factory,
) -> None:
    # Two Robots on one arm. A's Stop fails (owed); B delivers it; B's own move is then
    # given up, its Stop fails too, and B is closed with it owed. A's next call settles
    # its own debt (delivered by B: nothing sent) and must leave B's owed, not strike it
    # off, so that the arm does not run on to B's target: it delivers it as well.
    sim = tm_simulator_factory("article", time_scale=2.0, cell=Cell(scene=[]))
    stop_writes = Rule("drop_request", function_code=16, address=519, times=1000)
    with FaultProxy(sim.port) as proxy, article_robot(proxy, None) as a:
        a.move_to(START, speed=100)
        given_up = a.start_move(FAR, speed=7)
        sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=20)
        proxy.add(stop_writes)
        with pytest.raises(tmmaster.MotionTimeoutError):
            given_up.wait(0.05)  # given up: its withdraw and Stop are dropped
        proxy.clear()
        with article_robot(proxy, None) as b:
            b.status()  # delivers A's Stop
            sim.wait_for(at_rest(sim), timeout=15, interval=0.05)
            sim.clear_error()
            b.wait_until_ready(timeout_s=5)
            at = sim.tcp_pose().y
            again = b.start_move(FAR, speed=5)  # seconds to go
            sim.wait_for(lambda: sim.tcp_pose().y > at + 10, timeout=10)
            proxy.add(stop_writes)
            with pytest.raises(tmmaster.MotionTimeoutError):
                again.wait(0.05)
            assert b.close(timeout_s=0.5) is False  # its Stop still owed
        proxy.clear()
        a.status()  # settles its own debt (nothing to send), then B's
        sim.wait_for(at_rest(sim), timeout=15, interval=0.05)
    assert sim.tcp_pose().distance_to(FAR) > 50, "B's given-up move ran on"
    assert [m.target for m in sim.motion_log()] == [START, FAR, FAR]
