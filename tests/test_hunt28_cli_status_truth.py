"""``tmmaster robot status`` says only what the robot reported.

The ``e-stop`` line said ``released`` on every robot that did not report an e-stop as
pressed, including one whose profile has no e-stop signal at all: the article's map
reports an e-stop as an error code in ``error_code`` (the simulator's 0x0200), so the
command printed "e-stop   released" next to "error    512" while the e-stop was
pressed. An operator reading the status to decide whether the cell is safe to enter
must not read a claim the robot never made.

Found by hunt 28 (fails without its fix): the article line read ``e-stop   released``.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster._cli import main
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]


def status_of(sim: Simulator, capsys: pytest.CaptureFixture[str]) -> dict[str, str]:
    where = ["--host", sim.host, "--port", str(sim.port), "--profile", sim.profile.name]
    assert main(["robot", "status", *where]) == 0
    return dict(line.split(None, 1) for line in capsys.readouterr().out.splitlines())


def test_the_article_never_says_its_e_stop_is_released(
    tm_simulator_factory: SimFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory("article")
    assert status_of(sim, capsys)["e-stop"] == "unknown"  # the map has no e-stop signal
    sim.press_estop()
    status = status_of(sim, capsys)
    assert status["e-stop"] == "unknown"
    assert status["mode"] == "error"


def test_tmflow_says_what_its_e_stop_signal_reads(
    tm_simulator_factory: SimFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory("tmflow")
    assert status_of(sim, capsys)["e-stop"] == "released"  # 7208 reads 0
    sim.press_estop()
    assert status_of(sim, capsys)["e-stop"] == "PRESSED"
