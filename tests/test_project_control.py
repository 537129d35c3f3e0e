"""The TMflow project: ready when the simulator says so, Play and Pause only when asked.

- ``Simulator.start()`` (and the banner after it) returns once the robot started up:
  a move written right after runs, over TCP and ``sim://``, at real time.
- ``robot.project_state()``, ``robot.play()``, ``robot.pause()``: read from Techman's
  table, pressed on the Play/Pause coil (7104) only when that does what was asked,
  through the command gate.
- A command on a stopped or paused project fails at once, in one line naming the fix;
  so does pick & place's start.
- ``tmmaster robot status|play|pause|stop``.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterator

import pytest

import tmmaster
from tmmaster import (
    ConfigError,
    EmergencyStopError,
    PollPolicy,
    Pose,
    ProjectPausedError,
    ProjectState,
    Robot,
    RobotFaultError,
    StopRequestedError,
    aio,
    connect,
)
from tmmaster._cli import main
from tmmaster.pickplace import Runner, pick_and_place, validate_config
from tmmaster.sim import Simulator, Timing

SimFactory = Callable[..., Simulator]

#: Techman's Play/Pause coil (TMflow 2.24 appendix C, p. 313).
PLAY_PAUSE_COIL = 7104
STOPPED = "the TMflow project is stopped: press Play on the robot, or robot.play()"
#: A short move from the simulator's home pose (250, 0, 300; 180, 0, 90).
NEARBY = Pose(250, 0, 280, 180, 0, 90)


def presses(sim: Simulator) -> list[object]:
    """Every write to the Play/Pause coil the simulator received."""
    return [
        r
        for r in sim.request_log
        if r.function_code in (5, 15) and r.address <= PLAY_PAUSE_COIL < r.address + r.count
    ]


@pytest.fixture
def sim(tm_simulator_factory: SimFactory) -> Simulator:
    """A tmflow simulator, in memory (the project is the subject, not TCP)."""
    return tm_simulator_factory("tmflow", listen=False)


@pytest.fixture
def robot(sim: Simulator) -> Iterator[Robot]:
    """A connected robot that polls often."""
    with connect(sim.url, polling=PollPolicy(interval_s=0.01)) as r:
        yield r


def stopped(sim: Simulator, robot: Robot) -> None:
    """Press Stop and wait until the simulator shows the project stopped."""
    robot.stop()
    sim.wait_for(lambda: not sim.field("project_running"), 2.0)


# -- ready when it says so -----------------------------------------------------------


@pytest.mark.parametrize("transport", ["tcp", "sim"])
def test_a_move_right_after_start_runs_at_real_time(transport: str) -> None:
    # The README's sample without wait_until_ready(): the project runs when start() returns.
    with Simulator("tmflow", listen=transport == "tcp") as sim:
        address = (sim.host, sim.port) if transport == "tcp" else (sim.url,)
        with connect(*address, polling=PollPolicy(interval_s=0.01)) as robot:
            assert robot.project_state() is ProjectState.RUNNING
            assert robot.status().ready
            robot.move_to(NEARBY, speed=100)
        assert sim.motion_log()[-1].target.is_close(NEARBY)


def test_an_awaited_robot_of_a_fleet_and_one_in_process_move_right_after_start() -> None:
    # The flaky test_aio case, at real time and without waiting: both robots just started.
    async def scenario() -> None:
        with tmmaster.Fleet() as fleet:
            own = aio.AsyncRobot(
                Robot(
                    tcp.host,
                    tcp.port,
                    polling=PollPolicy(interval_s=0.01),
                    link=fleet,
                )
            )
            async with (
                own,
                aio.connect(memory.url, polling=PollPolicy(interval_s=0.01)) as in_process,
            ):
                assert await in_process.project_state() is ProjectState.RUNNING
                await asyncio.gather(
                    own.move_to(NEARBY, speed=100), in_process.move_to(NEARBY, speed=100)
                )

    with Simulator("tmflow") as tcp, Simulator("tmflow", listen=False) as memory:
        asyncio.run(scenario())


def test_wait_ready_false_returns_while_the_robot_still_starts_up() -> None:
    with Simulator("tmflow", timing=Timing(init_time_s=1000.0), wait_ready=False) as sim:
        assert not sim.field("project_running")
        with connect(sim.url) as robot:
            assert robot.project_state() is ProjectState.STOPPED


# -- state, play, pause ----------------------------------------------------------------


def test_play_starts_a_stopped_project_and_a_move_runs_again(sim: Simulator, robot: Robot) -> None:
    stopped(sim, robot)
    assert robot.project_state() is ProjectState.STOPPED
    assert robot.play() is ProjectState.RUNNING
    assert sim.field("project_running")
    robot.move_to(NEARBY, speed=100)
    assert len(presses(sim)) == 1


def test_pause_then_play_and_each_only_when_it_does_what_was_asked(
    sim: Simulator, robot: Robot
) -> None:
    assert robot.play() is ProjectState.RUNNING  # running already: nothing pressed
    assert presses(sim) == []
    assert robot.pause() is ProjectState.PAUSED
    assert sim.field("paused")
    assert not robot.status().ready
    assert robot.pause() is ProjectState.PAUSED  # paused already: nothing pressed
    assert len(presses(sim)) == 1
    assert robot.play() is ProjectState.RUNNING
    assert len(presses(sim)) == 2


def test_pause_never_starts_a_stopped_project(sim: Simulator, robot: Robot) -> None:
    # The coil is a toggle: pressing it on a stopped project would start it.
    stopped(sim, robot)
    assert robot.pause() is ProjectState.STOPPED
    assert presses(sim) == []
    assert not sim.field("project_running")


def test_play_and_pause_pass_the_command_gate(sim: Simulator, robot: Robot) -> None:
    stopped(sim, robot)
    robot.interrupt()
    with pytest.raises(StopRequestedError):
        robot.play()
    assert presses(sim) == []
    robot.clear_stop_request()
    assert robot.play() is ProjectState.RUNNING


def test_play_is_refused_while_the_robot_is_in_error(sim: Simulator, robot: Robot) -> None:
    sim.press_estop()
    sim.wait_for(lambda: bool(sim.field("estop")), 2.0)
    assert robot.project_state() is ProjectState.ERROR
    with pytest.raises(EmergencyStopError, match="reset it on the robot first"):
        robot.play()
    assert presses(sim) == []


def test_the_article_profile_has_no_project(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("article", listen=False)
    with Robot(sim.url, profile="article") as robot:
        assert robot.status().project is None
        for call in (robot.play, robot.pause, robot.project_state):
            with pytest.raises(ConfigError, match="no TMflow project"):
                call()


def test_nothing_presses_play_on_its_own(sim: Simulator, robot: Robot) -> None:
    stopped(sim, robot)
    with pytest.raises(RobotFaultError):
        robot.move_to(NEARBY, speed=100)
    robot.close()
    assert presses(sim) == []
    assert not sim.field("project_running")


# -- a command on a stopped or paused project --------------------------------------------


def test_a_move_on_a_stopped_project_fails_at_once_naming_the_fix(
    sim: Simulator, robot: Robot
) -> None:
    stopped(sim, robot)
    with pytest.raises(RobotFaultError) as raised:
        robot.move_to(NEARBY, speed=100)
    assert str(raised.value) == STOPPED
    assert sim.motion_log() == ()


def test_a_move_on_a_paused_project_fails_at_once_naming_the_fix(
    sim: Simulator, robot: Robot
) -> None:
    robot.pause()
    with pytest.raises(ProjectPausedError, match=r"press Play on the robot, or robot\.play\(\)"):
        robot.move_to(NEARBY, speed=100)
    assert sim.motion_log() == ()


def test_a_ready_wait_that_runs_out_names_the_stopped_project(sim: Simulator, robot: Robot) -> None:
    stopped(sim, robot)
    with pytest.raises(tmmaster.MotionTimeoutError, match=STOPPED.replace("(", r"\(")[:40]):
        robot.wait_until_ready(0.05)


def test_pick_and_place_on_a_stopped_project_fails_at_once_naming_it(
    sim: Simulator, robot: Robot
) -> None:
    stopped(sim, robot)
    config = validate_config({"run": {"poll_interval_s": 0.01}})
    started = time.monotonic()
    result = Runner(robot, ready_timeout_s=30).run(pick_and_place(config))
    # The bound is the feature: not the 30 s ready wait.
    assert time.monotonic() - started < 10
    assert result.failure is not None
    assert STOPPED in str(result.failure.exception)
    assert isinstance(result.failure.exception, RobotFaultError)


# -- the command line -----------------------------------------------------------------


def test_the_robot_command_reads_and_presses(
    tm_simulator_factory: SimFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory("tmflow")
    where = ["--host", sim.host, "--port", str(sim.port)]
    assert main(["robot", "status", *where]) == 0
    assert "project  running" in capsys.readouterr().out
    assert main(["robot", "stop", *where]) == 0
    sim.wait_for(lambda: not sim.field("project_running"), 2.0)
    assert main(["robot", "pause", *where]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "project  stopped"
    assert main(["robot", "play", *where]) == 0
    assert capsys.readouterr().out == "project  running\n"
    assert main(["robot", "play", *where, "--profile", "article"]) in (2, 3, 4)
    assert "article" in capsys.readouterr().err
