"""The simulated tmflow robot runs the robot program: what only a program can show.

The simulator executes the Script Project that ``tmmaster robot-program`` writes (or a
user's own, ``program=``) through the TMscript interpreter. These tests check what the
robot did (its motion log, its TCP and flange), with the faults a real controller could
bring: a slow link between the program and its slave, a TCP configured on the robot that
the master does not know, and a user's own program.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import tmmaster
from tmmaster import Checks, ConfigError, FrameCheck, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster._profiles import robot_profile
from tmmaster._robot_program import robot_program
from tmmaster.sim import Cell, RobotSetup, Simulator
from tmmaster.sim import __main__ as sim_main
from tmmaster.sim._script_project import simulated_tool

SimFactory = Callable[..., Simulator]

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(250, 0, 160, 180, 0, 90)


def open_robot(sim: Simulator, **options: Any) -> Robot:
    options.setdefault("gripper", None)
    options.setdefault("polling", PollPolicy(interval_s=0.01))
    robot = Robot("127.0.0.1", sim.port, profile="tmflow", **options)
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    return robot


def without_compare_and_ack(text: str) -> str:
    """The program as a flow guide would build it: it acknowledges from the block it read."""
    reread = 'again = Byte_ToInt16Array(modbus_read("TM", 1, "RO", 9014, 2), 1, 0)'
    take = text.index("void Take()")
    head, body = text[:take], text[take:]
    assert body.count(reread) == 2
    return head + body.replace(reread, "again = {cmd, seq}")


@pytest.mark.parametrize("compare_and_ack", [True, False])
def test_a_cancel_that_lands_between_the_programs_read_and_its_ack_is_never_run(
    tm_simulator_factory: SimFactory, tmp_path: Path, compare_and_ack: bool
) -> None:
    # The program reads the new command, then its link to the slave is slow for 6
    # simulated s (0.15 s): the master gives the command up meanwhile and writes its
    # cancel record. The generated program reads the command again before and after
    # acknowledging it and consumes the cancel; a program that acknowledges from the
    # block it read runs the move the master gave up (the master then stops it).
    text = robot_program(robot_profile("tmflow"), tool=simulated_tool(None))
    if not compare_and_ack:
        text = without_compare_and_ack(text)
    program = tmp_path / "program.tms"
    program.write_text(text, encoding="utf-8")
    sim = tm_simulator_factory(
        "tmflow", robot=RobotSetup(program=program), faults=["late_ack:delay_s=6"]
    )
    robot = open_robot(sim, timeouts=TimeoutPolicy(ack_timeout_s=1.0))
    try:
        motion = robot.start_move(A, speed=30)
        threading.Timer(0.05, robot.interrupt).start()
        with pytest.raises(tmmaster.StopRequestedError):
            motion.wait()
        start = sim.ticks
        sim.wait_for(lambda: sim.ticks >= start + 25, timeout=5)  # 10 simulated s
        if compare_and_ack:
            assert motion.withdrawn is True
            assert sim.motion_log() == ()
            assert sim.field("result_code") == 5  # consumed as cancelled
        else:
            assert motion.withdrawn is False  # the program answered "taken"
            assert motion.stop_delivered is True
            assert len(sim.motion_log()) == 1  # it moved after the master gave up
    finally:
        robot.close()


@pytest.mark.parametrize("change_tcp", [True, False])
def test_the_program_sets_the_masters_tcp_whatever_the_robot_had(
    tm_simulator_factory: SimFactory, tmp_path: Path, change_tcp: bool
) -> None:
    # A TCP of 150 mm is configured on the robot; the master plans without a tool. The
    # program sets the TCP the master plans with (ChangeTCP at start), so the flange goes
    # where the master's kinematics put it. Without it, the robot reaches the same TCP
    # pose with its own tool: the flange (and every joint) 150 mm from the master's plan,
    # which the master's frame check refuses at connect (switched off here to show it).
    text = robot_program(robot_profile("tmflow"), tool=simulated_tool(None))
    if not change_tcp:
        change = (
            "    if (!ChangeTCP(tool, 1.1))\n"
            '    {\n        Abort("ChangeTCP refused the tool")\n    }\n'
        )
        assert change in text
        text = text.replace(change, "")
    program = tmp_path / "program.tms"
    program.write_text(text, encoding="utf-8")
    sim = tm_simulator_factory(
        "tmflow", cell=Cell(tool=Pose(0, 0, 150, 0, 0, 0)), robot=RobotSetup(program=program)
    )
    # The program's ChangeTCP runs when the project starts: the master connects after it.
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    options: dict[str, Any] = {}
    if not change_tcp:
        with pytest.raises(ConfigError, match=r"tool offset of \(0, 0, 150, 0, 0, 0\)"):
            open_robot(sim)
        options["checks"] = Checks(frame=FrameCheck.off("the test shows where the flange goes"))
    robot = open_robot(sim, **options)
    try:
        joints = robot.validate_move(B, 50)
        robot.move_to(B, speed=50)
        flange = sim.call(sim.backend.flange_pose)
        assert flange is not None
        actual = sim.call(sim.backend.joint_positions_deg)
        assert actual is not None
        off = max(abs(a - b) for a, b in zip(actual, joints, strict=True))
        if change_tcp:
            assert flange.is_close(B, mm=0.05, deg=0.05)
            assert off < 0.05
        else:
            assert flange.distance_to(B) > 100
            assert off > 1
    finally:
        robot.close()


USER_PROJECT = """define
{
    ModbusTCP me = "127.0.0.1", 502
    int n = 0
}
main
{
    Display("hello from a user's project")
    PTP("CPP", {300, -200, 150, 180, 0, 90}, 50, 200, 0, false)
    QueueTag(1, 1)
    n = modbus_read_int16("me", 1, "RO", 9000, 1)[0]
    Display("register 9000 reads " + n)
    Exit()
}
closestop
{
    Display("closestop ran")
}
"""


def test_a_users_own_script_project_runs(tm_simulator_factory: SimFactory, tmp_path: Path) -> None:
    program = tmp_path / "mine.tms"
    program.write_text(USER_PROJECT, encoding="utf-8")
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(program=program))
    sim.wait_for(lambda: "closestop ran" in sim.displayed(), timeout=5)
    assert sim.displayed() == [
        "hello from a user's project",
        "register 9000 reads 0",
        "closestop ran",
    ]
    assert [m.target for m in sim.motion_log()] == [A]
    assert not sim.field("project_running")  # Exit() stopped it


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("main\n{\n    int x = \n}\n", "line"),
        ("main\n{\n    Frobnicate(1)\n}\n", "Frobnicate"),
        ('main\n{\n    PTP("CPP", 1, 2)\n}\n', "PTP"),
    ],
)
def test_a_bad_program_is_refused_before_the_simulator_starts(
    tmp_path: Path, text: str, needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    program = tmp_path / "bad.tms"
    program.write_text(text, encoding="utf-8")
    with pytest.raises(tmmaster.TMScriptSyntaxError, match=needle):
        Simulator("tmflow", robot=RobotSetup(program=program), listen=False)
    assert sim_main.main(["--program", str(program), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert needle in err
    assert f"{program}:" in err  # the file, then its line and column


def test_a_program_is_refused_on_a_profile_without_sequence_numbers(tmp_path: Path) -> None:
    program = tmp_path / "p.tms"
    program.write_text("main\n{\n}\n", encoding="utf-8")
    with pytest.raises(tmmaster.ConfigError, match="sequence"):
        Simulator("article", robot=RobotSetup(program=program), listen=False)
    with pytest.raises(tmmaster.ConfigError, match="cannot read"):
        Simulator("tmflow", robot=RobotSetup(program=tmp_path / "missing.tms"), listen=False)


def test_the_start_up_rule_of_the_program_cancels_a_command_written_while_stopped(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow")
    robot = open_robot(sim)
    try:
        robot.move_to(A, speed=50)
        robot.stop()  # the Stop coil: the project stops (closestop runs)
        sim.wait_for(lambda: not sim.field("project_running"), timeout=5)
        seq = int(sim.field("ack_seq")) + 1
        # A master writes a command while the project is stopped...
        robot._transport.write_fields(  # type: ignore[attr-defined]
            [(robot.profile.field("command"), 1), (robot.profile.field("seq"), seq)],
            retry=False,
        )
        sim.press_play()  # ... and the operator starts the project: main runs StartUp()
        sim.wait_for(lambda: int(sim.field("ack_seq")) == seq, timeout=5)
        time.sleep(0.1)
        assert sim.field("result_code") == 5
        assert len(sim.motion_log()) == 1
    finally:
        robot.close()


def test_a_programs_own_pause_waits_for_play(
    tm_simulator_factory: SimFactory, tmp_path: Path
) -> None:
    program = tmp_path / "pause.tms"
    program.write_text(
        'main\n{\n    Display("before")\n    Pause()\n    Display("after")\n}\n',
        encoding="utf-8",
    )
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(program=program))
    sim.wait_for(lambda: bool(sim.field("paused")), timeout=5)
    assert sim.displayed() == ["before"]
    sim.press_play()
    sim.wait_for(lambda: "after" in sim.displayed(), timeout=5)
    assert not sim.field("paused")
