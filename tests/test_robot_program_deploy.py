"""The robot program as it must be to load on a real robot, and a simulator that fails like one.

The tool is set with its mass; the program uses only documented TMscript, checks every
write and stops the project when one fails; a command expires with its master's
heartbeat, even one paused mid-move; an unreachable move is an error stop with
Techman's code; profiles the program cannot serve are refused naming the field. The
simulated robot is driven through its registers (no master), as a master would write
them.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest

import tmmaster
from test_script_project import open_robot
from test_sim_controller import DT, FAR, HOME, run, run_until, send_tmflow, tmflow
from test_tmscript_execution import FakeHost
from tmmaster import Pose, _cli
from tmmaster._profiles import profile_from_data, robot_profile
from tmmaster._registers import Table
from tmmaster._robot_program import ToolSetting, robot_program
from tmmaster.sim import RobotSetup, Simulator
from tmmaster.sim._controller import RobotController
from tmmaster.sim._script_project import (
    TM_IK_INTERPOLATION,
    TM_IK_WORKING_RANGE,
    TM_PTP_JOINT_BOUNDARY,
    ScriptProjectController,
)
from tmmaster.tmscript import Execution, parse

TOOL = ToolSetting(tcp=Pose(0, 0, 0, 0, 0, 0), mass_kg=1.1)
CANCELLED, MOTION_FAILED, GRIPPER_FAILED = 5, 3, 4


def program_text(**options: Any) -> str:
    return robot_program(robot_profile("tmflow"), tool=options.pop("tool", TOOL), **options)


# -- 1. the tool with its mass --------------------------------------------------------------


def test_the_program_sets_the_tool_with_its_mass_and_inertia() -> None:
    tool = ToolSetting(
        tcp=Pose(0, 0, 150, 0, 0, 90),
        mass_kg=1.1,
        inertia=(2000, 500.5, 500, 0, 0, 60, 0, 0, 0),
    )
    text = program_text(tool=tool)
    assert "float[] tool = {0.0, 0.0, 150.0, 0.0, 0.0, 90.0}" in text
    assert "float[] inertia = {2000.0, 500.5, 500.0, 0.0, 0.0, 60.0, 0.0, 0.0, 0.0}" in text
    assert "if (!ChangeTCP(tool, 1.1, inertia))" in text
    named = program_text(tool=ToolSetting(name="Gripper_2FG7"))
    assert 'if (!ChangeTCP("Gripper_2FG7"))' in named
    assert "float[] tool" not in named
    parse(text)
    parse(named)


class ToolRecorder(FakeHost):
    """A host that records each ChangeTCP."""

    def __init__(self) -> None:
        super().__init__()
        self.tools: list[tuple[object, float | None, list[float] | None]] = []

    def change_tcp(
        self,
        value: str | Sequence[float],
        mass: float | None = None,
        inertia: Sequence[float] | None = None,
    ) -> None:
        shown = value if isinstance(value, str) else list(value)
        self.tools.append((shown, mass, None if inertia is None else list(inertia)))


def test_the_interpreter_takes_every_changetcp_syntax_with_its_mass() -> None:
    # TMscript 2.24 §13.6, pp. 327-329: the manual's own examples of syntaxes 1-7.
    script = """
define
{
    float[] Tool1 = {0,0,150,0,0,90}
    float[] COM1 = {2,0.5,0.5,0,0,-80,0,0,0}
}
main
{
    ChangeTCP("RobotEndFlange")
    ChangeTCP(Tool1)
    ChangeTCP(Tool1,2)
    ChangeTCP(Tool1,2,COM1)
    ChangeTCP(0,0,150,0,0,90)
    ChangeTCP(0,0,150,0,0,90,2)
    ChangeTCP(0,0,150,0,0,90,2, 2,0.5,0.5,0,0,-80,0,0,0)
}
"""
    host = ToolRecorder()
    Execution(parse(script), host).run_to_end(timeout_s=5)
    tcp = [0.0, 0.0, 150.0, 0.0, 0.0, 90.0]
    com = [2.0, 0.5, 0.5, 0.0, 0.0, -80.0, 0.0, 0.0, 0.0]
    assert host.tools == [
        ("RobotEndFlange", None, None),
        (tcp, None, None),
        (tcp, 2.0, None),
        (tcp, 2.0, com),
        (tcp, None, None),
        (tcp, 2.0, None),
        (tcp, 2.0, com),
    ]


def test_the_simulated_robot_publishes_the_mass_the_program_set() -> None:
    # TMflow publishes the TCP value with its mass at 7354-7385, mass at 7366 (appendix C,
    # p. 313): the simulator serves what the program's ChangeTCP set.
    ctl, bank, _, _ = tmflow()
    assert isinstance(ctl, ScriptProjectController)
    run_until(ctl, lambda: ctl.tool_mass_kg is not None, limit_s=1.0)
    assert ctl.tool_mass_kg == pytest.approx(1.1)
    (mass,) = struct.unpack(">f", struct.pack(">HH", *bank.read(Table.INPUT, 7366, 2)))
    assert mass == pytest.approx(1.1)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        ([], "needs the tool"),
        (["--tool", "0,0,150,0,0,0"], "--tool-mass"),
        (["--tool", "1e20,0,0,0,0,0", "--tool-mass", "1"], "tool x"),
        (["--tool", "0,0,150,0,0,0", "--tool-mass", "1e20"], "tool mass_kg"),
        (["--tool", "0,0,150,0,0,0", "--tool-mass", "-1"], "tool mass_kg"),
        (
            ["--tool", "0,0,150,0,0,0", "--tool-mass", "1", "--tool-inertia", "1,2"],
            "needs 9 values",
        ),
        (
            ["--tool", "0,0,1,0,0,0", "--tool-mass", "1", "--tool-inertia", "1,1,1,0,0,1e9,0,0,0"],
            "tool inertia cz",
        ),
        (["--tool-name", "Gripper", "--tool-mass", "1"], "takes the tool's values from TMflow"),
        (["--tool-name", 'a"b'], "tool name"),
    ],
)
def test_a_tool_without_mass_or_out_of_range_is_exit_2_naming_the_field(
    argv: list[str], needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _cli.main(["robot-program", *argv]) == 2
    err = capsys.readouterr().err
    assert needle in err
    assert len(err.strip().splitlines()) == 1


def test_tool_values_are_float_literals_a_32_bit_script_reads() -> None:
    text = program_text(tool=ToolSetting(tcp=Pose(1999.5, -3, 1e-7, 0, 0, -360), mass_kg=35))
    assert "float[] tool = {1999.5, -3.0, 0.0, 0.0, 0.0, -360.0}" in text
    assert "ChangeTCP(tool, 35.0)" in text
    with pytest.raises(tmmaster.ConfigError, match="tool mass_kg is required"):
        ToolSetting(tcp=Pose(0, 0, 150, 0, 0, 0))


# -- 2. only documented constructs, every write checked ----------------------------------


@pytest.mark.parametrize("gripper", ["io", "none"])
def test_the_program_uses_only_documented_constructs(gripper: str) -> None:
    from tmmaster._robot_program import GripperWiring

    text = program_text(gripper=GripperWiring(gripper))
    code = "\n".join(line.split("//")[0] for line in text.splitlines())
    # [] indexes an array variable only (TMscript 2.24 p. 19), never a call's result.
    assert not re.search(r"\)\s*\[", code)
    # Every modbus_write's result is used: assigned, or tested.
    calls = [m.start() for m in re.finditer(r"modbus_write\(", code)]
    assert calls
    for at in calls:
        before = code[:at].rstrip()
        assert before.endswith(("=", "!")), code[at - 40 : at + 40]
    # The device has a timeout well inside the 12 s of closestop/errorstop (pp. 30-31, 414).
    (timeout,) = re.findall(r'ModbusTCP TM = "127\.0\.0\.1", 502, (\d+)', code)
    assert int(timeout) <= 2000


@pytest.mark.parametrize("gripper", ["io", "none"])
def test_a_start_up_call_that_fails_stops_the_project_with_its_reason(gripper: str) -> None:
    # ChangeTCP returns false when refused (TMscript 2.24 13.6, p. 327); ThreadRun returns
    # an ID <= 0 when the thread was not created (3.12.1, pp. 47-48): without the watchdog
    # thread no command of a master gone would be given up, so neither is ignored.
    from tmmaster._robot_program import GripperWiring

    text = program_text(gripper=GripperWiring(gripper))
    assert re.search(r"if \(ThreadRun\(Watch\(\), true\) <= 0\)\s*\{\s*Abort\(", text)
    assert re.search(r"if \(!ChangeTCP\([^\n]*\)\)\s*\{\s*Abort\(", text)
    assert not re.search(r"^\s*ThreadRun\(", text, re.MULTILINE)


def test_a_write_the_slave_refuses_stops_the_project_with_its_reason() -> None:
    # The robot's slave gives 127.0.0.1 read permission only (its IP filter): the
    # program's first feedback write fails, and the project stops at once with the
    # reason on the pendant, before it takes any command.
    ctl, bank, _, _ = tmflow(initialise=False)
    assert isinstance(ctl, ScriptProjectController)
    ctl.refused_writes = {(Table.HOLDING, 9102)}  # robot_state
    run_until(ctl, lambda: any("fbState failed" in line for line in ctl.displayed), limit_s=1.0)
    assert bank.get("project_running") is False
    send_tmflow(bank, 1, target=FAR)
    run(ctl, 1.0)
    assert ctl.motion_log == ()
    assert bank.get("ack_seq") == 0


# -- 3. a command expires with its master ----------------------------------------------------


class Master:
    """A master reduced to its heartbeat: master_heartbeat changed every 0.2 s while alive."""

    def __init__(self, ctl: RobotController, ttl_ms: int = 2000) -> None:
        self.ctl = ctl
        self.bank = ctl._bank
        self.alive = True
        self.beat = 0
        self.since = 0.0
        self.bank.set("master_ttl_ms", ttl_ms)

    def tick(self, dt: float) -> None:
        self.since += dt
        if self.alive and self.since >= 0.2:
            self.since = 0.0
            self.beat = self.beat % 32767 + 1
            self.bank.set("master_heartbeat", self.beat)
        self.ctl.tick(dt)

    def run_until(self, done: Callable[[], bool], limit_s: float = 10.0) -> None:
        for _ in range(round(limit_s / DT)):
            self.tick(DT)
            if done():
                return
        raise AssertionError(f"not done after {limit_s} simulated seconds")


def press_play_pause(master: Master) -> None:
    master.bank.set("play_pause", True)
    master.tick(DT)


@pytest.mark.parametrize("master_dies", [True, False])
def test_a_paused_move_whose_master_is_gone_never_moves_again(master_dies: bool) -> None:
    ctl, bank, backend, _ = tmflow()
    master = Master(ctl)
    master.run_until(lambda: bank.get("robot_state") == 0)
    send_tmflow(bank, 1, target=FAR, speed=10)
    master.run_until(lambda: len(ctl.motion_log) == 1, limit_s=2.0)
    master.run_until(lambda: backend.tcp_pose().distance_to(HOME) > 20)
    press_play_pause(master)  # Pause, mid-move
    assert bank.get("paused") is True
    master.run_until(backend.is_settled, limit_s=1.0)  # the arm brakes to rest
    held = backend.tcp_pose()
    master.alive = not master_dies
    for _ in range(round(4.0 / DT)):  # twice the time-to-live, paused
        master.tick(DT)
    bank.set("play_pause", True)  # the operator presses Play
    for _ in range(round(6.0 / DT)):
        master.tick(DT)
    if master_dies:
        assert backend.tcp_pose() == held  # not a micron
        assert len(ctl.motion_log) == 1  # nothing started again
        assert (bank.get("done_seq"), bank.get("result_code")) == (0, CANCELLED)
        # The project was stopped while paused; Play started it again from main.
        assert bank.get("project_running") is True
        assert any("heartbeat stopped" in line for line in ctl.displayed)
    else:
        master.run_until(lambda: bank.get("done_seq") == 1)
        assert backend.tcp_pose() == FAR


@pytest.mark.parametrize("ttl_ms", [2000, 0])
def test_a_command_written_after_its_master_went_silent_is_consumed_as_cancelled(
    ttl_ms: int,
) -> None:
    # master_ttl_ms 0: a master that keeps no heartbeat; its commands never expire.
    ctl, bank, backend, _ = tmflow()
    master = Master(ctl, ttl_ms=ttl_ms)
    master.run_until(lambda: bank.get("robot_state") == 0)
    master.alive = False
    for _ in range(round(3.0 / DT)):
        master.tick(DT)
    send_tmflow(bank, 1, target=FAR)
    master.run_until(lambda: bank.get("ack_seq") == 1, limit_s=2.0)
    if ttl_ms:
        run(ctl, 0.5)
        assert bank.get("result_code") == CANCELLED
        assert ctl.motion_log == ()
        assert backend.tcp_pose().is_close(HOME, mm=1e-6, deg=1e-6)
    else:
        run_until(ctl, lambda: bank.get("done_seq") == 1)
        assert backend.tcp_pose() == FAR


# -- 4. the simulated robot fails like the robot ----------------------------------------------


def test_a_move_the_arm_cannot_make_is_an_error_stop_with_techmans_code() -> None:
    # A joint target beyond J1's +-270 deg: "Target of PtP Motion is Out of Joint
    # Boundary" (0x1C, TMflow 2.24 appendix J, p. 349). PTP returns true (the command
    # is well formed, TMscript p. 331): the robot stops in error, errorstop reports it.
    ctl, bank, backend, _ = tmflow()
    run_until(ctl, lambda: bank.get("robot_state") == 0)
    send_tmflow(bank, 1, command=5, target=Pose(300, 0, 90, 0, 90, 0))
    run_until(ctl, lambda: bank.get("error") is True, limit_s=2.0)
    assert bank.get("last_error_code") == TM_PTP_JOINT_BOUNDARY
    run_until(ctl, lambda: bank.get("project_running") is False, limit_s=2.0)
    assert (bank.get("ack_seq"), bank.get("done_seq")) == (1, 0)
    assert (bank.get("result_code"), bank.get("robot_state")) == (MOTION_FAILED, 2)
    assert ctl.motion_log == ()
    assert backend.tcp_pose().is_close(HOME, mm=1e-6, deg=1e-6)


def test_an_interrupted_gripper_command_is_reported_gripper_failed() -> None:
    ctl, bank, _, _ = tmflow()
    run_until(ctl, lambda: bank.get("robot_state") == 0)
    send_tmflow(bank, 1, command=4)  # gripper_close: the program waits its settle time
    run_until(ctl, lambda: bank.get("ack_seq") == 1, limit_s=1.0)
    bank.set("stop_project", True)  # the Stop button, before it reports
    run_until(ctl, lambda: bank.get("project_running") is False, limit_s=1.0)
    run(ctl, 0.2)
    assert (bank.get("result_code"), bank.get("done_seq")) == (GRIPPER_FAILED, 0)


def test_a_line_whose_path_the_arm_cannot_follow_is_an_error_stop() -> None:
    ctl, bank, _, _ = tmflow()
    run_until(ctl, lambda: bank.get("robot_state") == 0)
    # Reachable (inversekin answers), but the straight path passes the J1 axis.
    send_tmflow(bank, 1, command=2, target=Pose(-300, 200, 200, 180, 0, 90))
    run_until(ctl, lambda: bank.get("error") is True, limit_s=2.0)
    assert bank.get("last_error_code") == TM_IK_INTERPOLATION


def test_the_master_sees_the_error_stop_of_a_target_the_arm_cannot_reach(
    tm_simulator_factory: Callable[..., Simulator], tmp_path: Path
) -> None:
    # A program without the inversekin check hands PTP a target the simulated arm cannot
    # reach (the master's TM5-700 reaches 700 mm; the simulated one, the same chain, only
    # 600 mm): the robot stops in error with 0x0001, and the master raises
    # RobotFaultError naming Techman's code. (Without the check there are no solved
    # joints to give the PTP as its reference: its Syntax 1, no posture.)
    text = program_text()
    check = "        joints = inversekin(target)\n        if (Length(joints) != 6)\n"
    ptp = 'PTP("CPP", target, speed, accel, 0, false, joints)'
    assert check in text
    assert ptp in text
    text = text.replace(check, "        if (false)\n", 1).replace(ptp, ptp.replace(", joints", ""))
    program = tmp_path / "no_reach_check.tms"
    program.write_text(text, encoding="utf-8")
    short = tmmaster.robot_model("tm5-700").model_copy(update={"reach_mm": 600.0})
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(model=short, program=program))
    robot = open_robot(sim)
    try:
        with pytest.raises(tmmaster.RobotFaultError, match="0x0001") as info:
            robot.move_to(Pose(300, -570, 300, 180, 0, 90), speed=30, timeout=10)
        assert info.value.error_code == TM_IK_WORKING_RANGE
        assert sim.motion_log() == ()
    finally:
        robot.close()


# -- 5. profile checks -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fields", "needle"),
    [
        ({"done_seq": {"address": 9106}, "grasp_status": {"address": 9107}}, "done_seq"),
        ({"heartbeat": {"address": 8999}}, "heartbeat"),
        ({"result_code": {"address": 10003}}, "result_code"),
    ],
)
def test_a_sequence_profile_the_program_cannot_serve_is_refused_naming_the_field(
    fields: dict[str, Any], needle: str
) -> None:
    with pytest.raises(tmmaster.RegisterMapError, match=needle):
        profile_from_data({"extends": "tmflow", "fields": fields})
