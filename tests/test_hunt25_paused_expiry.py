"""A paused command of a dead master never resumes, whether or not the run time counts
through the pause.

The program measures the master's silence with ``GetNowStamp(true)``, "the total run
time of the current project" (TMscript 2.24 §4.39, p. 128). The manual does not say
whether a project's run time counts while it is paused. If a real TM does not count
it, a master that dies while its command is paused would never look silent to the
watchdog (a non-pause thread: it runs, but ``now - beatAt`` stays put), and the
operator's Play would resume the move (TMflow 2.24 Table 5, pp. 53-55). These tests
run the generated program on the simulator as it is (the run time counts through a
pause) and on one deliberately off in that one respect: its ``GetNowStamp`` stops
while the project is paused. The arm's pose and the simulator's motion log judge.
The program's second clock, the controller's Up Time, must not expire a live master's
paused command early either, however fast the simulator runs.
"""

from __future__ import annotations

import dataclasses
import itertools
import weakref
from collections.abc import Iterator
from pathlib import Path

import pytest

from pendant import press_play_pause, runs_again_without_moving
from tmmaster import Pose, Robot, TimeoutPolicy, robot_profile
from tmmaster._robot_program import robot_program
from tmmaster.sim import RobotSetup, Simulator
from tmmaster.sim._script_project import simulated_tool
from tmmaster.tmscript import BUILTINS
from tmmaster.tmscript._builtins import Runtime
from tmmaster.tmscript._types import Value

LEFT = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)  # from LEFT: a long turn of J1
#: A short time-to-live (wall time), so that an expiry is seen within seconds.
FAST = TimeoutPolicy(heartbeat_s=0.05, heartbeat_ttl_s=0.5)
#: Tells apart the program texts of the off simulators: the simulator parses (and
#: compiles, binding each built-in) a program text once per process.
_OFF_RUNS = itertools.count()


def _robot_s(sim: Simulator) -> float:
    """The simulated robot's clock in wall seconds (simulated seconds / time_scale): the
    clock the master's heartbeat and time-to-live keep."""
    return float(sim.call(lambda: sim._controller._time_s)) / sim.time_scale


def _stamp_stopped_while_paused(monkeypatch: pytest.MonkeyPatch) -> None:
    """GetNowStamp as a TM would count it if a project's run time stopped while paused:
    the clock holds at its value when the program first read it paused, and goes on
    from there after Play."""
    real = BUILTINS["GetNowStamp"]
    assert real.impl is not None
    impl = real.impl
    # Per start of the project: [ms paused in all, the stamp when the pause began].
    held: weakref.WeakKeyDictionary[Runtime, list[float | None]] = weakref.WeakKeyDictionary()

    def stopped(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
        stamp = impl(rt, [True], ("bool",))
        assert isinstance(stamp, float)
        state = held.setdefault(rt, [0.0, None])
        total, paused_at = state
        assert total is not None
        if rt.host._c.project_paused:  # type: ignore[attr-defined]
            if paused_at is None:
                state[1] = paused_at = stamp
            value = paused_at - total
        else:
            if paused_at is not None:
                state[0] = total = total + stamp - paused_at
                state[1] = None
            value = stamp - total
        return value if args else int(value)

    monkeypatch.setitem(BUILTINS, "GetNowStamp", dataclasses.replace(real, impl=stopped))


@pytest.fixture(params=["run time counts while paused", "run time stops while paused"])
def sim(
    request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> Iterator[Simulator]:
    setup = RobotSetup()
    if request.param == "run time stops while paused":
        _stamp_stopped_while_paused(monkeypatch)
        # The generated program as it is, under a text of its own: compiled afresh, with
        # the GetNowStamp above.
        text = robot_program(robot_profile("tmflow"), tool=simulated_tool(None))
        path = tmp_path / "program.tms"
        path.write_text(f"{text}\n// off simulator {next(_OFF_RUNS)}\n", encoding="utf-8")
        setup = RobotSetup(program=path)
    with Simulator(time_scale=6, robot=setup) as simulator:
        yield simulator


def test_a_paused_move_of_a_dead_master_never_resumes_whatever_the_run_time_does(
    sim: Simulator,
) -> None:
    robot = Robot(sim.url, timeouts=FAST)
    with robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)
        start = sim.tcp_pose()
        robot.start_move(FAR, speed=10)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(start) > 20, timeout=5.0)
        press_play_pause(sim)  # the operator pauses the project mid-move
        sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        robot._heartbeat.stop()  # the master is gone: nothing beats any more
        # Well past the time-to-live (0.5 s) and the margin of a clock counted in whole
        # seconds, on the robot's clock: the watchdog has stopped the project by then,
        # or never will.
        paused_at = _robot_s(sim)
        sim.wait_for(
            lambda: not sim.field("project_running") or _robot_s(sim) > paused_at + 3,
            timeout=10.0,
        )
        held = sim.tcp_pose()
        press_play_pause(sim)  # the operator presses Play
        # The program loops again (it beats), or the arm moves: whichever comes first.
        sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2.0)
        beat = sim.field("heartbeat")
        sim.wait_for(
            lambda: sim.field("heartbeat") != beat or sim.tcp_pose().distance_to(held) > 1.0,
            timeout=5.0,
        )
        assert sim.tcp_pose().distance_to(held) < 1e-6, "Play resumed the dead master's move"
        runs_again_without_moving(sim, held, moves=2)
        assert any("heartbeat" in line for line in sim.displayed())
        robot.interrupt()


@pytest.mark.parametrize("time_scale", [100])
def test_a_paused_move_of_a_live_master_resumes_in_a_fast_simulator(time_scale: int) -> None:
    """The controller clock the program reads besides GetNowStamp never expires a live
    master's command early, however fast the simulator runs."""
    with Simulator(time_scale=time_scale) as sim:
        robot = Robot(sim.url, timeouts=FAST)
        with robot:
            robot.wait_until_ready()
            robot.move_to(LEFT, speed=50)
            start = sim.tcp_pose()
            motion = robot.start_move(FAR, speed=1)
            sim.wait_for(lambda: sim.tcp_pose().distance_to(start) > 5, timeout=5.0)
            press_play_pause(sim)
            sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
            # Paused well past the time-to-live and a whole-second clock's margin, on the
            # robot's clock, while the master beats.
            paused_at = _robot_s(sim)
            sim.wait_for(lambda: _robot_s(sim) > paused_at + 3, timeout=10.0)
            assert sim.field("project_running")
            press_play_pause(sim)
            sim.wait_for(lambda: not sim.field("paused"), timeout=2.0)
            motion.wait()
            assert sim.tcp_pose().is_close(FAR, mm=1.0, deg=1.0)
