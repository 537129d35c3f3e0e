"""A live master and a second party on the same robot at the same time (hunt 36).

The second party is the operator's ``tmmaster robot pause|play|stop`` (in-process here,
through a fault proxy of its own: another endpoint, so it shares none of this process's
per-robot state, as another process would not). The master moves, gives up, or presses
Play while the operator presses. The Play/Pause coil (7104) is a toggle: on a stopped
project it is Play. The simulator runs the generated robot program; its motion log and
project flags are the judge (``safety_invariant.check``).

Found here (fail without their fix):

- ``robot pause`` while a live master moves: the master's wait sees the pause and presses
  Stop (its rule for a paused move), often before the operator's command reads the
  project again. ``pause()`` trusted only a pause it saw, so it waited its whole
  ``--timeout`` on the stopped project, pressed Stop again and exited 4 naming the
  remote-control settings, although the arm stood still, stopped.
- ``robot pause`` decided on a running project whose press landed after the master's
  Stop (a give-up): the toggle started the project over, and ``pause()`` waited its
  whole timeout on it before pressing Stop, while the master's next move ran to its end.

Found nothing (kept as regression tests): the master's Play crossing the operator's
Stop (a fresh start: the move it meant to resume never runs), ``robot play`` on a live
master's paused move (refused), an awaited move paused by the operator then Play, and
the operator's Stop and Play while the master's command frame is held in the network.
Also tried, not kept (slow, nothing found): a StatusMonitor on the master's own link at
100 Hz with 9-50 ms per read (the master's beats went out, its move finished), and the
article's ``robot stop`` mid-move (the master's move raised, never "done").
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy
from fault_proxy import Rule as FaultRule
from safety_invariant import Issued, attempt, check, wait_braked
from tmmaster import (
    Motion,
    PollPolicy,
    Pose,
    ProjectPausedError,
    ProjectState,
    Robot,
    RobotError,
    TimeoutPolicy,
    aio,
)
from tmmaster._cli import main
from tmmaster.sim import Simulator

#: Techman's Play/Pause coil (TMflow 2.24 appendix C, p. 313).
PLAY_PAUSE = 7104
#: The tmflow profile's command block (target, speed, command, seq: one FC16).
COMMAND_BLOCK = 9000


@pytest.fixture
def sim(tm_simulator_factory: Callable[..., Simulator]) -> Simulator:
    # Real time: a slow move still runs while the operator's command connects and presses.
    return tm_simulator_factory("tmflow", time_scale=1.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def master_on(port: int) -> Robot:
    """A master on ``port`` polling densely, its request timeout longer than any press the
    tests hold."""
    return Robot(
        "127.0.0.1",
        port,
        gripper=None,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(request_s=5.0),
    )


@pytest.fixture
def master(sim: Simulator) -> Iterator[Robot]:
    with master_on(sim.port) as robot:
        robot.wait_until_ready(timeout_s=5)
        yield robot


def operator(action: str, port: int, result: dict[str, Any], *extra: str) -> threading.Thread:
    """``tmmaster robot ACTION`` on ``port``, in a thread; its exit status in ``result``."""

    def run() -> None:
        result["code"] = main(["robot", action, "--host", "127.0.0.1", "--port", str(port), *extra])

    thread = threading.Thread(target=run)
    thread.start()
    return thread


def in_thread(call: Callable[[], Any], result: dict[str, Any]) -> threading.Thread:
    def run() -> None:
        try:
            result["value"] = call()
        except Exception as exc:
            result["value"] = exc

    thread = threading.Thread(target=run)
    thread.start()
    return thread


def moving(sim: Simulator, count: int) -> None:
    sim.wait_for(lambda: len(sim.motion_log()) >= count, timeout=5.0)


def stopped(sim: Simulator) -> None:
    sim.wait_for(lambda: not sim.field("project_running"), timeout=5.0)


def slow_move(robot: Robot, sim: Simulator, issued: list[Issued]) -> threading.Thread:
    """The master's 150 mm move at 5 % (seconds long), recorded; started on the robot."""
    target = robot.pose().offset(dz=-150)
    thread = in_thread(lambda: attempt(robot, target, issued, speed=5), {})
    moving(sim, 1)
    return thread


def test_robot_pause_overtaken_by_the_live_masters_stop_reports_the_stopped_project(
    sim: Simulator, proxy: FaultProxy, master: Robot, capsys: pytest.CaptureFixture[str]
) -> None:
    """The operator's Pause lands mid-move; its answer is held until the master, whose
    wait saw the pause, has pressed Stop: the command's next read finds the project
    stopped, never paused. Paused or stopped, the arm is halted: exit 0 at once."""
    issued: list[Issued] = []
    mover = slow_move(master, sim, issued)
    release = threading.Event()
    proxy.add(FaultRule("delay_answer", function_code=5, address=PLAY_PAUSE, release=release))
    result: dict[str, Any] = {}
    pause = operator("pause", proxy.port, result, "--timeout", "3")
    try:
        mover.join()  # the master saw the pause, gave the move up and pressed Stop
        stopped(sim)
    finally:
        release.set()
    pause.join()
    wait_braked(sim)
    assert issued[0].outcome == "ProjectPausedError"
    assert (result["code"], capsys.readouterr().out) == (0, "project  stopped\n")
    assert not sim.field("project_running")
    check(issued, sim.motion_log())
    assert sim.motion_log()[0].done_wall_time is None  # stopped short, never resumed


def test_robot_pause_landing_after_the_masters_stop_never_lets_the_project_run_on(
    sim: Simulator, proxy: FaultProxy, master: Robot, capsys: pytest.CaptureFixture[str]
) -> None:
    """The operator's Pause, decided on the running project, is held until the master
    gave its move up (Stop pressed, the project stopped): landing there, the toggle is
    Play and starts the project over. The master moves on at once. ``robot pause``
    presses Stop as soon as it reads the new run, not a timeout later: the master's next
    move never runs to its end."""
    issued = [Issued(master.pose().offset(dz=-150), time.monotonic())]
    first = master.start_move(issued[0].target, speed=5)
    moving(sim, 1)
    release = threading.Event()
    proxy.add(FaultRule("hold", function_code=5, address=PLAY_PAUSE, release=release))
    result: dict[str, Any] = {}
    pause = operator("pause", proxy.port, result, "--timeout", "30")
    try:
        sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)  # decided, held
        first.cancel()  # the master gives the move up: Stop pressed, the project stops
        issued[0].outcome, issued[0].ended_at = "cancelled", time.monotonic()
        stopped(sim)
    finally:
        release.set()
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=5.0)  # started over
    outcome = attempt(master, master.pose().offset(dz=150), issued, speed=5)
    pause.join()
    wait_braked(sim)
    assert outcome != "done"
    assert all(m.done_wall_time is None for m in sim.motion_log())  # none ran to its end
    assert not sim.field("project_running")
    assert result["code"] == 4
    assert "a press crossed this one): Stop pressed" in capsys.readouterr().err
    check(issued, sim.motion_log())


def test_the_masters_play_crossing_the_operators_stop_never_runs_the_given_up_move(
    sim: Simulator, proxy: FaultProxy, capsys: pytest.CaptureFixture[str]
) -> None:
    """The master presses Play to resume its own paused move; its press is held until the
    operator's ``robot stop`` finished (exit 0). Landing on the stopped project, the
    toggle starts it over: ``play()`` did what it is documented to do on a stopped
    project, and the move it meant to resume never runs (the start-up rule): its wait
    fails, never "done". Found nothing (a regression test)."""
    with master_on(proxy.port) as robot:
        robot.wait_until_ready(timeout_s=5)
        motion: Motion = robot.start_move(robot.pose().offset(dz=-150), speed=5)
        moving(sim, 1)
        assert robot.pause() is ProjectState.PAUSED
        release = threading.Event()
        proxy.add(FaultRule("hold", function_code=5, address=PLAY_PAUSE, release=release))
        played: dict[str, Any] = {}
        play = in_thread(robot.play, played)
        try:
            sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)  # decided, held
            result: dict[str, Any] = {}
            operator("stop", sim.port, result).join()
        finally:
            release.set()
        play.join()
        assert result["code"] == 0
        assert "the arm is at rest" in capsys.readouterr().out
        assert played["value"] is ProjectState.RUNNING
        with pytest.raises(RobotError):
            motion.wait()
        wait_braked(sim)
        assert len(sim.motion_log()) == 1
        assert sim.motion_log()[0].done_wall_time is None


def test_robot_play_never_resumes_a_live_masters_paused_move(
    sim: Simulator, master: Robot, capsys: pytest.CaptureFixture[str]
) -> None:
    """The master's move paused on the pendant, the master alive and not polling: the
    operator's ``robot play`` refuses (press Stop); only the master resumes it. Found
    nothing (a regression test)."""
    motion = master.start_move(master.pose().offset(dz=-150), speed=5)
    moving(sim, 1)
    sim.call(lambda: sim._controller.bank.set("play_pause", True))  # the pendant's Pause
    sim.wait_for(lambda: bool(sim.field("paused")), timeout=5.0)
    wait_braked(sim)  # paused shows at once; the arm brakes to rest after it (CI: 0.02 mm)
    held: Pose = sim.tcp_pose()
    result: dict[str, Any] = {}
    operator("play", sim.port, result).join()
    assert result["code"] == 4
    assert "press Stop" in capsys.readouterr().err
    assert sim.field("paused")
    assert sim.tcp_pose().is_close(held, mm=0.01, deg=0.01)
    motion.cancel()
    assert len(sim.motion_log()) == 1


def test_an_awaited_move_paused_by_the_operator_never_resumes_at_the_operators_play(
    sim: Simulator, capsys: pytest.CaptureFixture[str]
) -> None:
    """``tmmaster.aio``: the operator's ``robot pause`` mid-move ends the awaited move
    with ProjectPausedError (the master pressed Stop on it); the operator's ``robot
    play`` after that starts the project over and the move never runs on. Before the
    pause fix above, ``robot pause`` here often waited out its timeout and exited 4."""
    issued: list[Issued] = []

    async def scenario() -> None:
        async with aio.connect(
            "127.0.0.1", sim.port, gripper=None, polling=PollPolicy(interval_s=0.01)
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued((await robot.pose()).offset(dz=-150), time.monotonic()))
            handle = await robot.start_move(issued[0].target, speed=5)
            await asyncio.to_thread(moving, sim, 1)
            paused: dict[str, Any] = {}
            await asyncio.to_thread(operator("pause", sim.port, paused).join)
            assert paused["code"] == 0
            with pytest.raises(ProjectPausedError):
                await handle.wait()
            issued[0].outcome, issued[0].ended_at = "ProjectPausedError", time.monotonic()
            played: dict[str, Any] = {}
            await asyncio.to_thread(operator("play", sim.port, played).join)
            assert played["code"] == 0  # the project was stopped: started over

    asyncio.run(scenario())
    assert capsys.readouterr().out.splitlines()[-1] == "project  running"
    held = sim.tcp_pose()
    wait_braked(sim)
    assert sim.tcp_pose().is_close(held, mm=1e-6, deg=1e-6)
    assert sim.motion_log()[0].done_wall_time is None
    check(issued, sim.motion_log())


def test_the_operators_stop_and_play_while_the_masters_command_is_on_its_way_run_nothing(
    sim: Simulator, proxy: FaultProxy, capsys: pytest.CaptureFixture[str]
) -> None:
    """The master's command block (FC16, 9000) is held in the network while the operator
    runs ``robot stop`` then ``robot play`` (a new start of the project); it lands after
    both. Its start is not the program's now: consumed unrun, and the master's move
    ends in an error, never "done". Found nothing (a regression test)."""
    with master_on(proxy.port) as robot:
        robot.wait_until_ready(timeout_s=5)
        release = threading.Event()
        proxy.add(FaultRule("hold", function_code=16, address=COMMAND_BLOCK, release=release))
        issued: list[Issued] = []
        target = robot.pose().offset(dz=-150)
        mover = in_thread(lambda: attempt(robot, target, issued, speed=5), {})
        try:
            sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)  # written, held
            for action in ("stop", "play"):
                result: dict[str, Any] = {}
                operator(action, sim.port, result).join()
                assert result["code"] == 0, action
        finally:
            release.set()
        mover.join()
    assert capsys.readouterr().out.splitlines()[-1] == "project  running"
    assert issued[0].outcome == "CommandRejectedError"
    wait_braked(sim)
    assert sim.motion_log() == ()
    check(issued, sim.motion_log())
