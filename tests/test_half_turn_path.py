"""A Line or an arc that turns the TCP by (nearly) half a turn is refused unsent.

A half turn has no shorter way round: both directions are 180 degrees. The master
checks one of them; the robot starts from the pose it actually holds, within its own
rounding of the float32 target it reads, and may turn the other way: there, from
J6 = 114 deg, J6 would pass its +270 deg limit. The master refuses such a path before any write.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import ConfigError, Pose, Robot, robot_model
from unsent_moves import SimFactory, command_writes, robot_at

#: Tool down, J6 = 114 deg on a TM5-700.
START = Pose(300, 0, 250, 180, 0, 0)
#: START turned by exactly 180 deg about the tool's axis, 50 mm lower.
HALF_TURN = Pose(300, 0, 200, 180, 0, 180)


def test_a_line_that_turns_half_a_turn_is_refused_before_the_write(
    robots: Callable[..., Robot], memory_simulator_factory: SimFactory
) -> None:
    # Either way round is possible: 0.01 deg past the half turn, the arm's other way
    # takes J6 past its range.
    arm = robot_model("tm5-700")
    joints = arm.inverse(START)
    other_way = Pose(300, 0, 200, 180, 0, -179.99)
    with pytest.raises(ConfigError, match="jumps"):
        arm.line_joints(START, other_way, start_joints_deg=joints)
    sim, robot = robot_at(robots, memory_simulator_factory, START)
    with pytest.raises(ConfigError, match="half a turn"):
        robot.check_move(HALF_TURN, speed=30, motion="line", start=START)
    with pytest.raises(ConfigError, match="half a turn"):
        robot.move_to(HALF_TURN, speed=30, motion="line")
    with pytest.raises(ConfigError, match="half a turn"):
        robot.move_arc(Pose(320, 0, 225, 180, 0, 0), HALF_TURN, speed_mm_s=100)
    assert command_writes(sim) == []
    # 178 deg: one way round is the shorter, the robot's and the master's alike.
    near = Pose(300, 0, 200, 180, 0, 178)
    robot.move_to(near, speed=30, motion="line")
    assert robot.status().pose.is_close(near, mm=0.5, deg=0.5)
    # A PTP turns the joints, not the TCP along a path: taken.
    robot.move_to(START, speed=100)
    robot.move_to(HALF_TURN, speed=30)
    assert robot.status().pose.is_close(HALF_TURN, mm=0.5, deg=0.5)
