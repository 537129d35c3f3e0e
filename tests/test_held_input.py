"""``[gripper] held_input``: the run reads the gripper's input itself, not a stale flag.

On ``tmflow`` the robot program writes ``grasp_status`` (9105) when a gripper command
ends: the grip input it read at the close, 0 at the open. Anything after that is not in
it. Hunt 19 left it wrong three ways, each judged on the simulator's world:

- an e-stop while the program waits out the close's settle time: the fingers closed on
  the part, the command never ended, ``grasp_status`` still 0 while the part is held. The
  next run, trusting it, opens the gripper at the start and drops the part there;
- an e-stop in the open's settle time: the part released, ``grasp_status`` still 1. The
  next run refuses to start ("the gripper holds a part") with an empty gripper;
- a controller restart clears the program's registers while a part is held: 0 again.

With ``held_input`` naming the end module's DI the program's gripper reads, the run
reads that input over the robot's Modbus table (FC 02): the first and the third are
seen as they are. The second is not: at the start a part counts as held when the flag
or the input says so (an input named wrongly must never have a held part dropped), so
the run refuses as before and ``release_held_part_at_start`` is the way out. (The part
lost on the way: tests/test_hunt19_part_lost_in_transport.py.)
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from pendant import press_play_pause
from sim_speeds import QUICK
from tmmaster import (
    ConfigError,
    PollPolicy,
    Pose,
    Robot,
    TimeoutPolicy,
    TMMasterError,
    robot_profile,
)
from tmmaster._io import GripperWiring
from tmmaster._robot_program import robot_program
from tmmaster.pickplace import (
    ARTICLE_PICK,
    ARTICLE_PLACE,
    Runner,
    RunResult,
    pick_and_place,
    robot_from_config,
    validate_config,
)
from tmmaster.sim import Cell, RobotSetup, Simulator, TableObject
from tmmaster.sim._script_project import simulated_tool

PICK = Pose.from_sequence(ARTICLE_PICK)
PLACE = Pose.from_sequence(ARTICLE_PLACE)
#: The program's settle: 60 s simulated, 0.6 s of wall time at QUICK's 100x, the window in
#: which the test presses the e-stop (the program sleeps it between DO and grasp_status).
SETTLE_MS = 60_000
#: What a controller restart leaves at 0: every register of the robot program
#: (tests/test_controller_restart.py), grasp_status among them.
RESTART_CLEARS = (
    *("command", "seq", "ext_seq", "command_session", "command_boot"),
    *("master_heartbeat", "master_ttl_ms", "master_session"),
    *("ack_seq", "done_seq", "robot_state", "result_code", "heartbeat", "grasp_status"),
    *("ack_session", "boot_id"),
)
FAST: dict[str, Any] = {
    "robot": {"profile": "tmflow"},
    "run": {"poll_interval_s": 0.01},
    "timeouts": {"ack_s": 0.5, "motion_margin_s": 0.5, "gripper_s": 5.0},
}


@pytest.fixture
def sim(tmp_path: Path) -> Iterator[Simulator]:
    """tmflow, running the generated program with a long settle, a part at the pick."""
    text = robot_program(
        robot_profile("tmflow"),
        tool=simulated_tool(None),
        gripper=GripperWiring(settle_ms=SETTLE_MS),
    )
    path = tmp_path / "program.tms"
    path.write_text(text, encoding="utf-8")
    cell = Cell(scene=[TableObject(name="part-1", pose=PICK)])
    with Simulator("tmflow", robot=RobotSetup(program=path), cell=cell, **QUICK) as simulator:
        yield simulator


def robot_of(sim: Simulator) -> Robot:
    return Robot(
        "127.0.0.1",
        sim.port,
        profile="tmflow",
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(gripper_timeout_s=5.0),
    )


def output_high(sim: Simulator) -> bool:
    """The end module's DO 0: the gripper's output, as the program last wrote it."""
    return bool(sim.do(0, module="end_module"))


def part_held(sim: Simulator) -> bool:
    (part,) = sim.objects()
    return part.held


def to_the_pick(robot: Robot) -> None:
    robot.move_to(PICK.offset(dz=100), speed=30)
    robot.move_to(PICK, speed=10, motion="line")


def estop_in_the_settle(sim: Simulator, robot: Robot, command: Callable[[], object]) -> None:
    """Run the gripper ``command``; press the e-stop once its DO changed (the program
    then sleeps its settle time, grasp_status not yet written); the operator then
    resets and presses Play."""
    before = output_high(sim)
    errors: list[BaseException] = []

    def run() -> None:
        try:
            command()
        except TMMasterError as exc:
            errors.append(exc)

    thread = threading.Thread(target=run, name="gripper")
    thread.start()
    sim.wait_for(lambda: output_high(sim) is not before, timeout=5, interval=0.002)
    sim.press_estop()
    thread.join(10)
    assert not thread.is_alive()
    assert errors, "the gripper command ended before the e-stop: set-up"
    restart_project(sim)


def restart_project(sim: Simulator, *, clear: tuple[str, ...] = ()) -> None:
    """The project stopped (if it is not), ``clear`` registers set to 0, reset, Play."""
    sim.call(lambda: sim._controller.bank.set("stop_project", True))
    sim.wait_for(lambda: not sim.field("project_running"), timeout=5)

    def zero() -> None:
        for name in clear:
            sim._controller.bank.set(name, 0)

    sim.call(zero)
    sim.clear_error()
    press_play_pause(sim)
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=5)
    beat = sim.field("heartbeat")
    sim.wait_for(lambda: sim.field("heartbeat") != beat, timeout=5)


def run_once(sim: Simulator, **gripper: Any) -> RunResult:
    config = validate_config({**FAST, "gripper": {"settle_s": 0.05, **gripper}})
    with robot_from_config(config, "127.0.0.1", sim.port) as robot:
        return Runner.from_config(robot, config).run(pick_and_place(config))


def assert_refused_untouched(result: RunResult, sim: Simulator, motions: int) -> None:
    """The run refused to start: nothing moved or opened, the part still in the fingers."""
    assert result.failure is not None
    assert result.failure.state == "IDLE"
    assert isinstance(result.failure.exception, ConfigError), result.failure
    assert "holds a part" in result.failure.message
    assert len(sim.motion_log()) == motions
    assert output_high(sim)
    assert part_held(sim)


def test_an_estop_in_the_close_leaves_grasp_status_0_and_the_held_input_refuses_the_start(
    sim: Simulator,
) -> None:
    with robot_of(sim) as robot:
        robot.wait_until_ready(5)
        to_the_pick(robot)
        estop_in_the_settle(sim, robot, robot.gripper.close)
    # The stale flag, on the robot: the part in the fingers, grasp_status 0.
    assert part_held(sim)
    assert output_high(sim)
    assert sim.field("grasp_status") == 0
    motions = len(sim.motion_log())

    result = run_once(sim, held_input=0)

    assert_refused_untouched(result, sim, motions)


def test_an_estop_in_the_open_leaves_grasp_status_1_and_the_start_still_refuses(
    sim: Simulator,
) -> None:
    # Not fixed, on purpose: at the start a part counts as held when the flag or the
    # input says so, so that an input named wrongly never has a held part dropped.
    with robot_of(sim) as robot:
        robot.wait_until_ready(5)
        to_the_pick(robot)
        robot.gripper.grip()
        estop_in_the_settle(sim, robot, robot.gripper.open)
    # The stale flag, on the robot: the part released at the pick, grasp_status 1.
    assert not part_held(sim)
    assert not output_high(sim)
    assert sim.field("grasp_status") == 1
    motions = len(sim.motion_log())

    refused = run_once(sim, held_input=0)
    assert refused.failure is not None
    assert isinstance(refused.failure.exception, ConfigError)
    assert "holds a part" in refused.failure.message
    assert len(sim.motion_log()) == motions
    # The operator's way out: release it at the start (an empty gripper drops nothing).
    result = run_once(sim, held_input=0, release_held_part_at_start=True)

    assert result.ok, result.failure
    (part,) = sim.objects()
    assert not part.held
    assert abs(part.pose.x - PLACE.x) < 2
    assert abs(part.pose.y - PLACE.y) < 2


def test_an_input_named_wrongly_never_has_a_held_part_dropped_at_the_start(
    sim: Simulator,
) -> None:
    with robot_of(sim) as robot:
        robot.wait_until_ready(5)
        to_the_pick(robot)
        robot.gripper.grip()
        robot.move_to(PICK.offset(dz=100), speed=10, motion="line")
    assert sim.field("grasp_status") == 1
    motions = len(sim.motion_log())

    result = run_once(sim, held_input=1)  # the end module's DI 1: wired to nothing

    assert_refused_untouched(result, sim, motions)


def test_a_restart_that_clears_grasp_status_with_a_part_held_refuses_the_start(
    sim: Simulator,
) -> None:
    with robot_of(sim) as robot:
        robot.wait_until_ready(5)
        to_the_pick(robot)
        robot.gripper.grip()
        robot.move_to(PICK.offset(dz=100), speed=10, motion="line")
    restart_project(sim, clear=RESTART_CLEARS)
    assert part_held(sim)
    assert output_high(sim)
    assert sim.field("grasp_status") == 0
    motions = len(sim.motion_log())

    result = run_once(sim, held_input=0)

    assert_refused_untouched(result, sim, motions)


def test_a_held_input_the_profile_has_not_is_refused_before_the_run() -> None:
    robot = Robot("127.0.0.1", 1, profile="tmflow")  # never connected
    with pytest.raises(ConfigError, match="end_module DI"):
        Runner(robot, held_input=4)
    with pytest.raises(ConfigError):
        Runner(Robot("127.0.0.1", 1, profile="article"), held_input=0)
