"""examples/many_robots.py says when a robot's give-up could not be confirmed, not only
after Ctrl-C: a robot whose withdraw or stop did not get through may still be moving.

Robot 1's second command write is held in the network and its link goes down right
behind it (every reconnect refused): the master cannot know whether the robot took the
command, and cannot deliver its withdraw or stop. ``Robot.close()`` then returns False.

Found by hunt 29 ("the code users copy"); the test fails without the fix: the example
kept close()'s answer only for its Ctrl-C message, so the run's report said "FAILED
after 1 move(s): <the link error>" and nothing about an arm that may still be moving
toward a target the master had given up.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterator
from types import ModuleType

import pytest

from examples_support import load_example
from fault_proxy import FaultProxy, Rule
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: tmflow's command block (the move's FC16 write).
COMMAND = 9000


@pytest.fixture(scope="module")
def example() -> ModuleType:
    return load_example("many_robots")


@pytest.fixture
def proxy(tm_simulator_factory: Factory) -> Iterator[FaultProxy]:
    sim = tm_simulator_factory()
    with FaultProxy(sim.port) as p:
        yield p


def link_down_behind_the_second_move(proxy: FaultProxy) -> threading.Thread:
    proxy.add(Rule("hold", function_code=16, address=COMMAND, nth=2))

    def cut() -> None:
        deadline = time.monotonic() + 30.0
        while not proxy.played("hold") and time.monotonic() < deadline:
            time.sleep(0.005)
        proxy.outage(600.0)  # every connection closed, every reconnect refused

    thread = threading.Thread(target=cut)
    thread.start()
    return thread


def test_an_unconfirmed_give_up_is_reported_and_fails_the_run(
    tm_simulator_factory: Factory,
    proxy: FaultProxy,
    example: ModuleType,
    capsys: pytest.CaptureFixture[str],
) -> None:
    healthy = tm_simulator_factory()
    cutter = link_down_behind_the_second_move(proxy)
    try:
        reports = example.run([healthy.port, proxy.port], moves=3, watch_hz=0, retry_s=0.3)
    finally:
        cutter.join(10.0)
    assert [r.moves_done for r in reports] == [3, 1]
    assert [r.unconfirmed for r in reports] == [False, True]
    assert example.print_reports(reports) == 1
    out = capsys.readouterr().out
    assert "robot1: could NOT confirm that it gave its command up: check the arm" in out
    assert "robot0: could NOT" not in out
    # The same from a child process (--processes): the parent learns it too.
    back = example.report_from_json(json.loads(json.dumps(example.report_to_json(reports[1]))))
    assert back.unconfirmed
