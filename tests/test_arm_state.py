"""What the master learns from the robot at connect and before each plan (tmflow profile).

* The robot's joints (Techman's 7013-7024) seed inverse kinematics and motion times, so
  the master plans on the branch the arm is actually on, however it got there.
* The frame check: the robot's TCP (7025-7036) must be its flange (7001-7012) times the
  master's tool, else the master refuses to connect.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from pathlib import Path

import pytest

import tmmaster
from sim_speeds import QUICK
from tmmaster import Checks, ConfigError, FrameCheck, MotionType, Pose, Robot, Workspace
from tmmaster._profiles import robot_profile
from tmmaster._robot_program import ToolSetting, robot_program
from tmmaster.sim import Cell, KinematicBackend, RobotSetup, Simulator

SimFactory = Callable[..., Simulator]
TM5 = tmmaster.robot_model("tm5-700")
TOOL = Pose(0, 0, 150, 0, 0, 0)


def around(theta_deg: float, radius: float = 350.0, z: float = 250.0) -> Pose:
    """Tool down, ``radius`` mm from the J1 axis at ``theta_deg`` round it, facing out."""
    t = math.radians(theta_deg)
    rz = (90.0 + theta_deg + 180.0) % 360.0 - 180.0
    return Pose(radius * math.cos(t), radius * math.sin(t), z, 180, 0, rz)


#: PTPs that carry the arm round the base, each from the last: J1 ends near +250 deg,
#: where the same pose solved from the ready posture has J1 near -110 deg.
WINDING = [around(theta) for theta in (60, 120, 180, 230)]


class RecordingBackend(KinematicBackend):
    """The kinematic arm, keeping the duration of every motion it started (simulated s)."""

    def __init__(self) -> None:
        super().__init__(TM5)
        self.durations: list[float] = []

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        duration = super().start_motion(
            target, motion=motion, speed_percent=speed_percent, accel_time_s=accel_time_s
        )
        self.durations.append(duration)
        return duration

    def wind(self) -> tuple[float, ...]:
        """Run the WINDING moves now (before a simulator drives it); the joints reached."""
        for pose in WINDING:
            self.start_motion(pose, motion=MotionType.PTP, speed_percent=100, accel_time_s=0.2)
            self.step(10.0)
        self.durations.clear()
        joints = self.joint_positions_deg()
        assert joints is not None
        return joints


def off_by(a: tuple[float, ...], b: tuple[float, ...] | None) -> float:
    assert b is not None
    return max(abs(x - y) for x, y in zip(a, b, strict=True))


# -- joints ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "theta",
    [
        # Near the wound arm: the same joints but J1 (+220 on the robot, -140 or another
        # branch from the ready posture).
        200,
        # J1 cannot stay wound (-60 + 360 is past +270): the robot unwinds 290 deg, where
        # from the ready posture it would turn 60.
        -60,
    ],
)
def test_a_fresh_master_plans_from_the_joints_the_robot_reports(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot], theta: float
) -> None:
    backend = RecordingBackend()
    wound = backend.wind()
    assert wound[0] > 240
    sim = memory_simulator_factory("tmflow", cell=backend, **QUICK)
    target = around(theta)
    robot = robots(sim, gripper=None)
    predicted = robot.validate_move(target, 50)  # seeded from the joints read at connect
    motion = robot.move_to(target, speed=50)
    actual = sim.call(backend.joint_positions_deg)
    assert off_by(predicted, actual) <= 0.05
    # The joints planned before the write (what the next move starts from).
    assert off_by(robot.validate_move(target, 50), actual) <= 0.05
    (simulated,) = backend.durations
    assert motion.expected_s == pytest.approx(simulated, rel=0.10)


def test_the_joints_are_read_again_before_each_plan(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    # The master connects and moves; then someone else (another master) winds the arm
    # round the base. The master's next plan starts from where the arm really is.
    backend = RecordingBackend()
    sim = memory_simulator_factory("tmflow", cell=backend, **QUICK)
    robot = robots(sim, gripper=None)
    robot.move_to(around(0), speed=100)
    # One commanding master at a time: the robot program runs only the commands of the
    # session that beats. This one falls silent (as the operator jogs the arm) and claims
    # the robot again with its next command.
    robot._heartbeat.stop()  # type: ignore[attr-defined]
    other = robots(sim, gripper=None, name="other")
    for pose in WINDING:
        other.move_to(pose, speed=100)
    other.close()
    wound = sim.call(backend.joint_positions_deg)
    assert wound is not None
    assert wound[0] > 240
    backend.durations.clear()
    target = around(-60)
    motion = robot.move_to(target, speed=50)
    actual = sim.call(backend.joint_positions_deg)
    assert off_by(robot.validate_move(target, 50), actual) <= 0.05
    (simulated,) = backend.durations
    assert simulated > 2.0  # the long way round
    assert motion.expected_s == pytest.approx(simulated, rel=0.10)


def test_where_the_profile_publishes_no_joints_the_ready_posture_is_assumed(
    memory_simulator_factory: SimFactory,
) -> None:
    # The article's map has no joints: nothing more is read at connect, and the first
    # plan starts from the model's ready posture (docs/kinematics.md).
    backend = RecordingBackend()
    backend.wind()
    sim = memory_simulator_factory("article", cell=backend, **QUICK)
    # No table: the subject is the posture the plan starts from, not the cell.
    checks = Checks(workspace=Workspace(floor_z_mm=None))
    with Robot(sim.url, profile="article", gripper=None, checks=checks) as robot:
        assert sim.request_log == []
        target = around(200)
        assert robot.validate_move(target, 50) == TM5.inverse(target)


# -- frame check ----------------------------------------------------------------------


def test_a_robot_whose_tcp_is_not_the_masters_is_refused_at_connect(
    memory_simulator_factory: SimFactory,
) -> None:
    sim = memory_simulator_factory("tmflow", cell=Cell(tool=TOOL), **QUICK)
    robot = Robot(sim.url, profile="tmflow", gripper=None)  # no tool: TCP = flange
    with pytest.raises(ConfigError, match=r"tool offset of \(0, 0, 150, 0, 0, 0\)") as caught:
        robot.connect()
    assert "this Robot's tool is none" in str(caught.value)
    assert robot.state is tmmaster.ConnectionState.CLOSED
    assert [r.function_code for r in sim.request_log if r.is_write] == []


def test_a_master_with_the_robots_tool_connects_and_moves(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = memory_simulator_factory("tmflow", cell=Cell(tool=TOOL), **QUICK)
    robot = robots(sim, gripper=None, tool=TOOL)
    robot.move_to(around(0), speed=100)
    assert sim.tcp_pose().is_close(around(0), mm=1e-3, deg=1e-3)


def test_the_check_switched_off_connects_and_logs_why(
    memory_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    caplog: pytest.LogCaptureFixture,
) -> None:
    sim = memory_simulator_factory("tmflow", cell=Cell(tool=TOOL), **QUICK)
    with caplog.at_level(logging.WARNING, "tmmaster"):
        robots(
            sim,
            gripper=None,
            checks=Checks(frame=FrameCheck.off("bench test: TCP taught elsewhere")),
        )
    assert "robot.frame_check_off" in caplog.text
    assert "bench test: TCP taught elsewhere" in caplog.text


def test_the_tcp_the_program_sets_is_what_is_checked(
    tm_simulator_factory: SimFactory, tmp_path: Path
) -> None:
    # The simulator has no tool, but its program (made for a 150 mm tool) sets one with
    # ChangeTCP when the project starts: the robot's TCP is then 150 mm off the flange.
    program = tmp_path / "program.tms"
    text = robot_program(robot_profile("tmflow"), tool=ToolSetting(tcp=TOOL, mass_kg=1.1))
    program.write_text(text, encoding="utf-8")
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(program=program))
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    with pytest.raises(ConfigError, match=r"tool offset of \(0, 0, 150, 0, 0, 0\)"):
        Robot("127.0.0.1", sim.port, profile="tmflow", gripper=None).connect()
    with Robot("127.0.0.1", sim.port, profile="tmflow", gripper=None, tool=TOOL) as robot:
        robot.wait_until_ready(timeout_s=5)


def test_a_tcp_in_another_base_is_refused(memory_simulator_factory: SimFactory) -> None:
    # A map whose robot-base TCP (7049-7060 in Techman's table) points at the robot-base
    # flange (7037-7048), and the other way round: to the master, the robot reports its
    # TCP in a base 150 mm off.
    data = robot_profile("tmflow").model_dump(by_alias=True)
    for axis in ("x", "y", "z", "rx", "ry", "rz"):
        data["fields"][f"robot_base_tcp_{axis}"]["address"] -= 12
        data["fields"][f"robot_base_flange_{axis}"]["address"] += 12
    shifted = tmmaster.RobotProfile.model_validate({**data, "name": "tmflow-shifted"})
    sim = memory_simulator_factory("tmflow", cell=Cell(tool=TOOL), **QUICK)
    robot = Robot(sim.url, profile=shifted, gripper=None, tool=TOOL)
    with pytest.raises(ConfigError, match="base other than the robot base"):
        robot.connect()


def test_the_check_is_typed_and_off_needs_a_reason() -> None:
    with pytest.raises(ConfigError, match=r"checks\.frame"):
        Checks(frame=False)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="reason"):
        FrameCheck.off("  ")
    with pytest.raises(ValueError, match="reason"):
        FrameCheck(enabled=False)
    assert FrameCheck().enabled
    assert FrameCheck.off("why").reason == "why"


# -- the frame check in the pick & place configuration ----------------------------------


def test_the_pick_and_place_configuration_switches_the_frame_check_off_only_with_a_reason() -> None:
    from tmmaster.pickplace import robot_from_config, validate_config

    default = robot_from_config(validate_config({"robot": {"host": "127.0.0.1"}}))
    assert default.frame_check.enabled
    off = validate_config(
        {
            "robot": {
                "host": "127.0.0.1",
                "frame_check": {"enabled": False, "reason": "the project sets the tool"},
            }
        }
    )
    robot = robot_from_config(off)
    assert not robot.frame_check.enabled
    assert robot.frame_check.reason == "the project sets the tool"
    with pytest.raises(ConfigError, match="reason"):
        validate_config({"robot": {"frame_check": {"enabled": False}}})
