"""Ctrl-C while ``tmmaster robot play`` or ``pause`` waits: exit 130, one line, and no
press left to land later as a resume.

A store-and-forward gateway answers the Play/Pause press (coil 7104) at once and holds
the frame: the command waits for the project's new state. The operator's Ctrl-C comes
while it waits (sent once the proxy holds the press: an event, not a delay). The
command presses Stop before it exits, so the held toggle, landing afterwards on the
stopped project, starts it from the beginning, where nothing pending runs. The
simulator's arm and motion log are the judge.

Found by hunt 28 (the last test fails without its fix): a Ctrl-C that came after the
press was answered and before the wait began (as the press was logged) left the press
without a Stop behind it. The operator then paused the master's move on the pendant,
and the held Pause, landing on the paused project, was Play: the move ran on.
"""

from __future__ import annotations

import _thread
import logging
import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy
from fault_proxy import Rule as FaultRule
from pendant import press_play_pause
from tmmaster import Pose, Robot
from tmmaster._cli import main
from tmmaster.sim import Simulator

#: Techman's Play/Pause coil (TMflow 2.24 appendix C, p. 313).
PLAY_PAUSE = 7104


@pytest.fixture
def sim(tm_simulator_factory: Callable[..., Simulator]) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=1.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


@pytest.mark.parametrize("action", ["play", "pause"])
def test_ctrl_c_while_waiting_for_the_project_exits_130_with_the_project_stopped(
    sim: Simulator, proxy: FaultProxy, action: str, capsys: pytest.CaptureFixture[str]
) -> None:
    if action == "play":
        press_play_pause(sim)  # the operator paused the idle project
        sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
    release = threading.Event()
    proxy.add(
        FaultRule("hold", function_code=5, address=PLAY_PAUSE, release=release, answer_now=True)
    )

    def ctrl_c_once_held() -> None:
        sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)
        _thread.interrupt_main()

    operator = threading.Thread(target=ctrl_c_once_held)
    operator.start()
    try:
        where = ["--host", "127.0.0.1", "--port", str(proxy.port), "--timeout", "30"]
        code = main(["robot", action, *where])
    finally:
        operator.join(5.0)
    assert code == 130
    assert capsys.readouterr().err.strip().endswith("interrupted [exit 130]")
    sim.wait_for(lambda: not sim.field("project_running"), timeout=2.0)  # Stop was pressed
    pose = sim.tcp_pose()
    release.set()  # the held toggle lands on the stopped project: a fresh start
    proxy.wait_held()
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2.0)
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 10, timeout=2.0)
    assert sim.motion_log() == ()
    assert sim.tcp_pose().is_close(pose, mm=1e-6, deg=1e-6)


class CtrlCAsThePressIsLogged(logging.Handler):
    """The operator's Ctrl-C, at the moment the command logs its answered press."""

    def emit(self, record: logging.LogRecord) -> None:
        if "robot.project_button" in record.getMessage():
            _thread.interrupt_main()


def let_run(sim: Simulator, ticks: int) -> None:
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


def test_ctrl_c_right_after_an_answered_pause_never_lets_the_press_resume_a_move(
    sim: Simulator, proxy: FaultProxy, capsys: pytest.CaptureFixture[str]
) -> None:
    release = threading.Event()
    proxy.add(
        FaultRule("hold", function_code=5, address=PLAY_PAUSE, release=release, answer_now=True)
    )
    ctrl_c = CtrlCAsThePressIsLogged()
    with Robot("127.0.0.1", sim.port, gripper=None) as master:
        master.wait_until_ready(timeout_s=5)
        start = master.pose()
        master.start_move(start.offset(dz=-150), speed=5)  # seconds long, real time
        sim.wait_for(lambda: sim.tcp_pose().distance_to(start) > 2, timeout=5.0)
        logging.getLogger("tmmaster.robot").addHandler(ctrl_c)
        try:
            code = main(["robot", "pause", "--host", "127.0.0.1", "--port", str(proxy.port)])
        finally:
            logging.getLogger("tmmaster.robot").removeHandler(ctrl_c)
        assert code == 130
        let_run(sim, 5)  # the robot took whatever landed
        if sim.field("project_running") and not sim.field("paused"):
            press_play_pause(sim)  # the operator pauses the running move on the pendant
            sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        let_run(sim, 20)  # braked to rest
        held: Pose = sim.tcp_pose()
        release.set()  # the command's Pause lands now
        proxy.wait_held()
        let_run(sim, 20)
        assert sim.tcp_pose().is_close(held, mm=1e-6, deg=1e-6), (held, sim.tcp_pose())
        assert sim.motion_log()[0].done_wall_time is None  # never ran to its end
        master.interrupt()
    capsys.readouterr()
