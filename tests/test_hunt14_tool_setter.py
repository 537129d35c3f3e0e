"""``robot.tool = ...`` after the Robot was made: the checks ``Robot(tool=...)`` makes.

docs/robot-api.md: a ``tool`` that looks like metres or radians is refused
(``UnitsError``) when the Robot is made, and an ``article`` Robot with a tool refuses to
connect with the frame check on, since that profile publishes neither the flange nor
the TCP value: "a wrong tool puts every move off by its offset". ``Robot.tool`` has a
setter (a tool change between two jobs), and it took any value unchecked:

- ``Pose(0, 0, 0.15, 0, 0, 0)`` (150 mm written in metres) on either profile: the next
  move was planned and checked (the table plane, the workspace) for a TCP 0.15 mm off
  the flange, and ran. On ``tmflow`` the per-move frame check passes it too when the
  robot's own TCP is its flange (the pendant's tool not set): a 150 mm tool then ends
  150 mm past every target the master checked;
- on ``article``, any tool, with the frame check on: the move was planned for that tool,
  which nothing on the robot can confirm, the very thing ``connect()`` refuses;
- a tuple or a list: an ``AttributeError`` at the next move, not a ``ConfigError``.

Found by this hunt (each fails without its fix): the setter now runs the constructor's
checks, before anything is sent (the refused tool is not taken: the next move runs with
the tool the robot had). The judge is what the simulator ran (its motion log).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import Checks, ConfigError, FrameCheck, PollPolicy, Pose, Robot, UnitsError
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
START = Pose(300, -200, 200, 180, 0, 90)
TARGET = Pose(320, -180, 220, 180, 0, 90)
METRES = Pose(0, 0, 0.15, 0, 0, 0)
TOOL = Pose(0, 0, 150, 0, 0, 0)


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: Factory) -> Factory:
    return memory_simulator_factory


def _ready(factory: Factory, profile: str, **options: object) -> tuple[Simulator, Robot]:
    sim = factory(profile)
    robot = Robot(sim.url, profile=profile, polling=PollPolicy(interval_s=0.01), **options)  # type: ignore[arg-type]
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    robot.move_to(START, speed=100)
    sim.clear_request_log()
    return sim, robot


def _refused_then_moves(
    sim: Simulator, robot: Robot, value: object, error: type[Exception]
) -> None:
    with pytest.raises(error, match="tool"):
        robot.tool = value  # type: ignore[assignment]
    assert robot.tool is None  # not taken
    assert list(sim.request_log) == []
    robot.move_to(TARGET, speed=100)  # planned for the tool the robot has: none
    assert sim.motion_log()[-1].target == TARGET
    assert sim.tcp_pose().is_close(TARGET)


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_tool_set_in_metres_is_refused_as_the_constructor_refuses_it(
    tm_simulator_factory: Factory, profile: str
) -> None:
    # article: the frame check off, so that only the units are in question.
    off = Checks(frame=FrameCheck.off("the tool checked on the robot"))
    sim, robot = _ready(tm_simulator_factory, profile, checks=off)
    try:
        _refused_then_moves(sim, robot, METRES, UnitsError)
    finally:
        robot.close()


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_tool_that_is_no_pose_is_refused_naming_it(
    tm_simulator_factory: Factory, profile: str
) -> None:
    off = Checks(frame=FrameCheck.off("the tool checked on the robot"))
    sim, robot = _ready(tm_simulator_factory, profile, checks=off)
    try:
        _refused_then_moves(sim, robot, (0, 0, 150, 0, 0, 0), ConfigError)
    finally:
        robot.close()


def test_an_article_robot_refuses_a_tool_it_cannot_verify_as_connect_does(
    tm_simulator_factory: Factory,
) -> None:
    sim, robot = _ready(tm_simulator_factory, "article")
    try:
        _refused_then_moves(sim, robot, TOOL, ConfigError)
    finally:
        robot.close()


def test_a_tool_the_robot_can_verify_is_taken_and_checked_before_the_move(
    tm_simulator_factory: Factory,
) -> None:
    # tmflow: a valid tool is taken; the robot's own TCP (the flange: no tool set on the
    # pendant) then stops the next move before anything is written.
    sim, robot = _ready(tm_simulator_factory, "tmflow")
    try:
        robot.tool = TOOL
        assert robot.tool == TOOL
        moves = len(sim.motion_log())
        with pytest.raises(ConfigError, match="frame check"):
            robot.move_to(TARGET, speed=100)
        assert len(sim.motion_log()) == moves
    finally:
        robot.close()
