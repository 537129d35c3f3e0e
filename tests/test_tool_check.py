"""The tool with its mass, and the robot's TCP and base checked before every move.

``Robot(tool=Tool(pose, mass_kg))``: at connect the master reads the TCP value and mass
the robot works with (Techman's 7354-7366) and refuses a mismatch. Before every move,
the read the move makes anyway (7001-7060: flange, joints, TCP, both in the robot base)
shows whether the robot's TCP is still its flange x the master's tool: a TCP changed on
the robot after connect stops the next move before anything is written. The article
profile publishes none of it: a Robot with a tool refuses to connect unless the frame
check is switched off.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

import tmmaster
from tmmaster import Checks, ConfigError, FrameCheck, Pose, Robot, Tool, ToolMismatchError
from tmmaster._channels import REUSE_DONE_READ_S
from tmmaster.sim import Simulator

LEFT = Pose(300, -200, 200, 180, 0, 90)
LOWER = Pose(300, -200, 180, 180, 0, 90)
FLANGE = Pose(0, 0, 0, 0, 0, 0)
#: The simulated gripper's mass: what the simulated robot's tool weighs.
SIM_MASS_KG = 1.1


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(time_scale=40, listen=False) as simulator:
        yield simulator


def command_writes(sim: Simulator) -> list[object]:
    """Every write to the command block (9000-9029)."""
    return [r for r in sim.request_log if r.function_code == 16 and 9000 <= r.address < 9030]


def test_a_tool_is_a_frozen_pose_and_mass() -> None:
    tool = Tool(Pose(0, 0, 150, 0, 0, 0), mass_kg=1, name="Gripper_2FG7")
    assert (tool.mass_kg, tool.name) == (1.0, "Gripper_2FG7")
    with pytest.raises(AttributeError):
        tool.mass_kg = 2.0  # type: ignore[misc]
    for bad in (-0.1, 101, float("nan"), "1.1", True):
        with pytest.raises(ConfigError, match=r"tool\.mass_kg"):
            Tool(FLANGE, mass_kg=bad)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"tool\.pose"):
        Tool([0, 0, 150, 0, 0, 0], mass_kg=1.0)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"tool\.name"):
        Tool(FLANGE, mass_kg=1.0, name="")
    assert {"Tool", "ToolMismatchError"} <= set(tmmaster.__all__)
    assert issubclass(ToolMismatchError, ConfigError)


@pytest.mark.parametrize(("model", "rated"), [("tm5-700", 6.0), ("tm5-900", 4.0)])
def test_a_tool_over_the_arms_rated_payload_is_refused_before_any_connection(
    model: str, rated: float
) -> None:
    # TMflow refuses a TCP load over the arm's limit (appendix J, 0x0004003B); the port is
    # one nothing listens on: the refusal comes first.
    with pytest.raises(ConfigError, match=rf"tool\.mass_kg .* rated payload of {rated:g} kg"):
        Robot("127.0.0.1", 1, model=model, tool=Tool(FLANGE, mass_kg=rated + 0.5))
    Robot("127.0.0.1", 1, model=model, tool=Tool(FLANGE, mass_kg=rated)).close()


def test_the_robots_tool_and_mass_are_checked_at_connect(sim: Simulator) -> None:
    with Robot(sim.url, tool=Tool(FLANGE, mass_kg=SIM_MASS_KG)) as robot:
        robot.move_to(LEFT, speed=50)
        assert robot.tool == FLANGE
    heavier = Robot(sim.url, tool=Tool(FLANGE, mass_kg=2.5))
    with pytest.raises(ToolMismatchError, match=r"tcp_value_mass differs.* 1\.1 kg.* 2\.5 kg"):
        heavier.connect()
    off = Checks(frame=FrameCheck.off("the tool is checked on the pendant"))
    with Robot(sim.url, tool=Tool(FLANGE, mass_kg=2.5), checks=off):
        pass


def test_a_tool_set_after_the_robot_was_made_has_its_mass_checked_too(sim: Simulator) -> None:
    # A tool set in steps (robot.tool = Tool(...), then connect) is checked as
    # Robot(tool=Tool(...)) is: its mass against the robot's, and a Pose then has none.
    robot = Robot(sim.url)
    robot.tool = Tool(FLANGE, mass_kg=2.5)
    with pytest.raises(ToolMismatchError, match=r"tcp_value_mass differs.* 1\.1 kg.* 2\.5 kg"):
        robot.connect()
    robot = Robot(sim.url, tool=Tool(FLANGE, mass_kg=2.5))
    robot.tool = FLANGE  # the 2.5 kg tool replaced by one whose mass is not given
    with robot:
        robot.move_to(LEFT, speed=50)


def test_a_model_or_units_check_set_later_refuses_the_tool_the_robot_has() -> None:
    # The setters keep what the constructor refuses: a Tool over the new arm's rated
    # payload, a tool in metres once the units are checked. Refused, nothing is taken.
    robot = Robot("127.0.0.1", 1, model="tm5-700", tool=Tool(FLANGE, mass_kg=5))
    with pytest.raises(ConfigError, match=r"tool\.mass_kg 5 kg .* rated payload of 4 kg"):
        robot.model = tmmaster.robot_model("tm5-900")
    assert robot.model.name == "tm5-700"
    robot.close()
    robot = Robot("127.0.0.1", 1, tool=Pose(0, 0, 0.15, 0, 0, 0), checks=Checks(units=False))
    with pytest.raises(tmmaster.UnitsError, match="tool"):
        robot.check_units = True
    assert robot.check_units is False
    robot.close()


def test_a_tcp_changed_after_connect_stops_the_next_move_unsent(sim: Simulator) -> None:
    with Robot(sim.url, tool=Tool(FLANGE, mass_kg=SIM_MASS_KG)) as robot:
        robot.move_to(LEFT, speed=50)
        moves = len(sim.motion_log())
        # Someone sets a 150 mm TCP on the robot (a Flow project, the pendant).
        sim.call(lambda: sim.backend.set_tool(Pose(0, 0, 150, 0, 0, 0)))  # type: ignore[attr-defined]
        sim.wait_for(lambda: sim.field("tcp_z") < 100, timeout=2.0)
        # Past the window in which the last move's final read stands in for the next
        # one's (REUSE_DONE_READ_S): a change older than that is always seen.
        time.sleep(2 * REUSE_DONE_READ_S)
        sim.clear_request_log()
        with pytest.raises(ToolMismatchError, match=r"before this ptp command: tool z differs"):
            robot.move_to(LOWER, speed=50)
        assert command_writes(sim) == []
        assert len(sim.motion_log()) == moves


def test_the_check_before_each_move_costs_no_request(sim: Simulator) -> None:
    # The frames come with the pose and joints every move reads anyway: Techman's
    # 7001-7060 (flange, joints, TCP, the flange and TCP in the robot base) in one
    # request, never a read of its own.
    with Robot(sim.url, tool=Tool(FLANGE, mass_kg=SIM_MASS_KG)) as robot:
        robot.move_to(LEFT, speed=50)
        sim.clear_request_log()
        for target in (LOWER, LEFT, LOWER):
            robot.move_to(target, speed=50)
    frames = [(r.address, r.count) for r in sim.request_log if r.function_code == 4]
    frames = [(a, n) for a, n in frames if a < 7100]
    assert frames
    assert set(frames) == {(7001, 60)}
    assert not [r for r in sim.request_log if r.address == 7354]  # the TCP value: at connect


def test_the_article_profile_cannot_verify_a_tool_and_says_so() -> None:
    with Simulator(profile="article", time_scale=40, listen=False) as sim:
        robot = Robot(sim.url, profile="article", tool=Pose(0, 0, 150, 0, 0, 0))
        with pytest.raises(ConfigError, match=r"'article' publishes neither.*FrameCheck\.off"):
            robot.connect()
        off = Checks(frame=FrameCheck.off("the TCP was checked on the pendant"))
        with Robot(sim.url, profile="article", tool=Pose(0, 0, 150, 0, 0, 0), checks=off):
            pass
        with Robot(sim.url, profile="article"):  # no tool: nothing to verify
            pass
