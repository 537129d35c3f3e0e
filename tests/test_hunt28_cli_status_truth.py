"""``tmmaster robot status`` says only what the robot reported.

The ``e-stop`` line said ``released`` on every robot that did not report an e-stop as
pressed, including one whose profile has no e-stop signal at all: the article's map
reports an e-stop as an error code in ``error_code`` (the simulator's 0x0200), so the
command printed "e-stop   released" next to "error    512" while the e-stop was
pressed. An operator reading the status to decide whether the cell is safe to enter
must not read a claim the robot never made.

The ``moving`` line on ``tmflow`` was the robot program's state, which leaves busy as
soon as the project stops, while the arm still brakes (docs/safety.md): "moving   no"
was printed while the arm went on for 10 mm during the read and 30 mm after it. It now
also reads Techman's Joint Speed (7949-7960), as ``robot stop``'s rest wait does.

Found by hunt 28 (fail without their fixes): the article line read ``e-stop
released``; the braking arm read ``moving   no``.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import Pose, Robot
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


def test_a_braking_arm_is_never_said_to_stand_still(
    tm_simulator_factory: SimFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    # A quarter of real time: the arm brakes for over a second of wall time, the read
    # takes milliseconds.
    sim = tm_simulator_factory("tmflow", time_scale=0.25)
    with Robot(sim.host, sim.port, gripper=None) as master:
        start = master.pose()
        master.start_move(Pose(300, 200, 200, 180, 0, 90), speed=100)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(start) > 20, timeout=10.0)
        sim.call(lambda: sim._controller.bank.set("stop_project", True))  # the Stop button
        sim.wait_for(lambda: not sim.field("project_running"), timeout=5.0)
        before = sim.tcp_pose()
        moving = status_of(sim, capsys)["moving"]
        after = sim.tcp_pose()
        if not after.is_close(before, mm=0.01, deg=0.01):  # it moved while being read
            assert moving == "yes"
        master.interrupt()
