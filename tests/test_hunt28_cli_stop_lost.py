"""``tmmaster robot stop`` never says "stop pressed" when the robot never took the Stop.

A store-and-forward gateway answers the master's Stop write (coil 7105) as done at once
and delivers it later, or never: the robot's project runs on. The arm was at rest (the
master between two moves), so the command's rest wait passed and it printed "stop
pressed; the arm is at rest", exit 0, while the TMflow project still ran and would take
the next move of any master: an operator walks into a cell that was never stopped. The
command now reads the project back once the arm is at rest; a project still running
is exit 4, saying so. The held frame is released when the test says, never on a time.

Found by hunt 28 (fails without its fix): exit 0, the project running.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy
from fault_proxy import Rule as FaultRule
from tmmaster._cli import main
from tmmaster.sim import Simulator

#: Techman's Stop coil (TMflow 2.24 appendix C, p. 313).
STOP = 7105


@pytest.fixture
def sim(tm_simulator_factory: Callable[..., Simulator]) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=1.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def test_a_stop_the_robot_never_took_is_not_reported_done(
    sim: Simulator, proxy: FaultProxy, capsys: pytest.CaptureFixture[str]
) -> None:
    release = threading.Event()
    proxy.add(FaultRule("hold", function_code=5, address=STOP, release=release, answer_now=True))
    try:
        code = main(["robot", "stop", "--host", "127.0.0.1", "--port", str(proxy.port)])
        assert sim.field("project_running") == 1  # the Stop is still held
    finally:
        release.set()
    proxy.wait_held()
    out, err = capsys.readouterr()
    assert code == 4
    assert "pressed" not in out
    assert "the project still running" in err


def test_a_stop_the_robot_took_is_reported_done(
    sim: Simulator, proxy: FaultProxy, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["robot", "stop", "--host", "127.0.0.1", "--port", str(proxy.port)]) == 0
    assert capsys.readouterr().out == "stop     pressed; the arm is at rest\n"
    assert sim.field("project_running") == 0
