"""article: a Stop the master owed, once delivered, is owed no more.

A running move's Stop that the link could not carry is owed by the process, per robot
address (docs/safety.md): whichever ``Robot`` on that address calls next delivers it
first. Here ``close()`` delivers it once the link is back (it returns True). From then on
nothing is owed: a later ``Robot`` at that address sends no Stop for it, whatever that
robot now runs (here the address answers for a TMflow project, whose Stop would end it).
"""

from __future__ import annotations

from collections.abc import Callable

from fault_proxy import FaultProxy
from test_aio import until
from test_hunt3_lost_stop import (
    OUTAGE_S,
    START,
    article_robot,
    lost_by_the_link,
    moving_then_cut,
    proxy_accepts,
    run_long,
    stops_short,
)
from tmmaster import Robot, aio
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]


def test_a_stop_that_close_delivered_is_never_sent_again(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article", time_scale=2.0)
    with FaultProxy(sim.port) as proxy:

        async def given_up_then_closed() -> None:
            async with aio.AsyncRobot(article_robot(proxy, None, gripper=None)) as robot:
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
