"""A Play/Pause press left unanswered is logged, as docs/safety.md says.

docs/safety.md ("A Play/Pause press left unanswered") promises that the master, before
the error reaches the caller, presses Stop and logs ``robot.project_button_unanswered``.
Since the press moved inside the wait's guard (commit 37a2403) nothing was logged for
it: the answered press logs ``robot.project_button``, the Stop that ended the project
logged nothing, so an operator's log did not say why the project stopped. Judged on the
simulator (the project stopped: the Stop went) and on the log record.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy
from test_hunt_project_press import hold_the_next_press, robot_through, slow_move
from tmmaster import TransportError
from tmmaster.sim import Simulator


@pytest.fixture
def sim(tm_simulator_factory: Callable[..., Simulator]) -> Simulator:
    # Real time, as tests/test_hunt_project_press.py: the move runs while the press times out.
    return tm_simulator_factory("tmflow", time_scale=1.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def test_an_unanswered_play_press_is_logged_after_its_stop(
    sim: Simulator, proxy: FaultProxy, caplog: pytest.LogCaptureFixture
) -> None:
    with robot_through(proxy) as robot:
        slow_move(robot, sim)
        robot.pause()
        release = hold_the_next_press(proxy)
        try:
            with caplog.at_level(logging.ERROR), pytest.raises(TransportError):
                robot.play()  # the press is held: no answer, the call gives it up
            sim.wait_for(lambda: not sim.field("project_running"), timeout=2)  # the Stop went
        finally:
            release.set()
        proxy.wait_held()
    events = [r.getMessage() for r in caplog.records]
    assert any("robot.project_button_unanswered" in e and "play" in e for e in events), events
