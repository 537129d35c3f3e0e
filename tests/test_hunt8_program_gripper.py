"""The tmflow robot program's gripper (``Grip()``) given up, stopped or e-stopped.

The robot program runs a gripper command as ``Grip()``: the ``io`` wiring (the
default, ``robot_program_grip_io.tms``) sets the end-module DO, sleeps ``settle_ms``,
reads the grip input and reports the command done; the ``none`` wiring refuses it
(``gripper_failed``). The simulator runs the generated program through its TMscript
interpreter (``RobotSetup(program=...)`` for another one), and its gripper follows the
end-module DO.

Attacked here, against a sync ``Robot``:

- the gripper close given up (``interrupt()``), the project stopped from the pendant,
  or the e-stop pressed while ``Grip()`` sleeps its settle time (the DO already high);
  then the operator resets and presses Play;
- a ``Grip()`` edited with a step before its DO write (the template says "Edit this
  function for another gripper"), the command given up the moment the program took it,
  with the master's Stop accepted (short step), or refused (Manual mode: the cancel
  record is all that stops the program; a step longer than the watchdog's 100 ms);
- the ``none`` wiring: a gripper command is refused, and the next move runs.

What must hold, judged on the simulator: the DO never toggles after the master's call
returned (a toggle of the command given up comes before, or never), the gripper command
never runs again after Play, and the robot's next command works.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

import tmmaster
from pendant import press_play_pause
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy, robot_profile
from tmmaster._robot_program import GripperWiring, robot_program
from tmmaster.sim import RobotSetup, Simulator, Timing
from tmmaster.sim._script_project import simulated_tool

Factory = Callable[..., Simulator]
START = Pose(300, -200, 200, 180, 0, 90)
#: The TMflow Stop coil (the master's Stop when it gives a taken command up).
STOP_COIL = robot_profile("tmflow").field("stop_project").address


def program(tmp_path: Path, *, wiring: GripperWiring | None = None, pre_step_ms: int = 0) -> Path:
    """The generated program (its Grip() with a step of ``pre_step_ms`` before the DO)."""
    text = robot_program(robot_profile("tmflow"), tool=simulated_tool(None), gripper=wiring)
    if pre_step_ms:
        edited = text.replace(
            "    ok = false\n    if (cmd ==",
            f"    ok = false\n    Sleep({pre_step_ms})\n    if (cmd ==",
            1,
        )
        assert edited != text, "set-up: the template's Grip() changed"
        text = edited
    path = tmp_path / "program.tms"
    path.write_text(text, encoding="utf-8")
    return path


def simulator(path: Path | None = None) -> Simulator:
    setup = RobotSetup(program=path) if path is not None else RobotSetup()
    # Ready at once: the robot's start-up (0.2 s at 1x) is not these tests' subject.
    timing = Timing(tick_hz=100.0, init_time_s=0.0)
    return Simulator("tmflow", robot=setup, time_scale=1.0, timing=timing)


@pytest.fixture
def robot_of() -> Iterator[Callable[[Simulator], Robot]]:
    robots: list[Robot] = []

    def make(sim: Simulator) -> Robot:
        robot = Robot(
            "127.0.0.1",
            sim.port,
            profile="tmflow",
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(gripper_settle_s=0.05),
        ).connect()
        robots.append(robot)
        robot.wait_until_ready(timeout_s=5)
        return robot

    yield make
    for robot in robots:
        robot.close()


def output_high(sim: Simulator) -> bool:
    return bool(sim.call(lambda: sim._controller._gripper_output_high))


def gripper_actions(sim: Simulator) -> list[tuple[str, float]]:
    return [(m.kind, m.wall_time) for m in sim.motion_log() if m.kind.startswith("gripper")]


class Closing:
    """``robot.gripper.close()`` on a thread: its exception, and when it returned."""

    def __init__(self, robot: Robot) -> None:
        self.error: BaseException | None = None
        self.ended_at = 0.0
        self._thread = threading.Thread(target=self._run, args=(robot,), name="close")
        self._thread.start()

    def _run(self, robot: Robot) -> None:
        try:
            robot.gripper.close()
        except BaseException as exc:  # judged by the test
            self.error = exc
        self.ended_at = time.monotonic()

    def join(self) -> None:
        self._thread.join(10)
        assert not self._thread.is_alive(), "the gripper close never returned"


def press_stop(sim: Simulator) -> None:
    sim.call(lambda: sim._controller.bank.set("stop_project", True))


ENDS: dict[str, Callable[[Simulator, Robot], None]] = {
    "interrupt": lambda sim, robot: robot.interrupt(),
    "stop button": lambda sim, robot: press_stop(sim),
    "e-stop": lambda sim, robot: sim.press_estop(),
}


@pytest.mark.parametrize("end", list(ENDS))
def test_a_gripper_close_ended_in_its_settle_never_runs_again_after_play(
    robot_of: Callable[[Simulator], Robot], end: str
) -> None:
    with simulator() as sim:
        robot = robot_of(sim)
        closing = Closing(robot)
        sim.wait_for(lambda: output_high(sim), timeout=5, interval=0.002)  # Grip() settles
        ENDS[end](sim, robot)
        closing.join()
        assert isinstance(closing.error, tmmaster.TMMasterError), closing.error
        assert [t for _, t in gripper_actions(sim) if t > closing.ended_at] == []
        sim.wait_for(lambda: not sim.field("project_running"), timeout=5)
        sim.clear_error()
        press_play_pause(sim)
        sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2)
        beat = sim.field("heartbeat")
        sim.wait_for(lambda: sim.field("heartbeat") != beat, timeout=2)
        assert [k for k, _ in gripper_actions(sim)] == ["gripper_close"]  # never again
        assert output_high(sim)  # where the command given up left it
        robot.clear_stop_request()
        robot.gripper.open()  # the next command works
        assert not output_high(sim)


@pytest.mark.parametrize(("stop", "pre_step_ms"), [("accepted", 30), ("refused", 500)])
def test_a_gripper_command_given_up_as_it_is_taken_toggles_nothing_after_the_call(
    tmp_path: Path, robot_of: Callable[[Simulator], Robot], stop: str, pre_step_ms: int
) -> None:
    # Refused with a step shorter than the watchdog's period, the DO may toggle after the
    # call returned (the watchdog has not yet read the cancel record): a race, not tested.
    with simulator(program(tmp_path, pre_step_ms=pre_step_ms)) as sim:
        robot = robot_of(sim)
        if stop == "refused":  # Manual mode: the TM Stop coil cannot be written
            sim.inject(f"modbus_exception:table=coil,start={STOP_COIL},end={STOP_COIL},code=4")
        taken = sim.field("ack_seq")
        closing = Closing(robot)
        sim.wait_for(lambda: sim.field("ack_seq") != taken, timeout=5, interval=0.001)
        robot.interrupt()  # the program is in Grip()'s step before its DO write
        closing.join()
        assert isinstance(closing.error, tmmaster.StopRequestedError), closing.error
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 30, timeout=5)
        late = [(k, t) for k, t in gripper_actions(sim) if t > closing.ended_at]
        assert late == [], f"the DO toggled after the call returned: {late}"
        assert output_high(sim) == bool(gripper_actions(sim))


def test_the_none_wiring_refuses_a_gripper_command_and_the_next_move_runs(
    tmp_path: Path, robot_of: Callable[[Simulator], Robot]
) -> None:
    with simulator(program(tmp_path, wiring=GripperWiring("none"))) as sim:
        robot = robot_of(sim)
        with pytest.raises(tmmaster.TMMasterError, match="gripper_failed"):
            robot.gripper.close()
        assert gripper_actions(sim) == []
        assert not output_high(sim)
        robot.move_to(START, speed=100)
        assert sim.tcp_pose().is_close(START)
