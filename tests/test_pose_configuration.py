"""A Cartesian target the arm reaches only in another pose configuration is refused unsent.

The robot program solves a Cartesian target with ``inversekin(target)``, which answers
"by the current pose configuration" and returns an empty array when that fails
(TMscript 2.24, 6.35, p. 207): the program then answers "unreachable". The master
refuses such a target before any write and names the way there: a joint move.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import Pose, Robot, UnreachablePoseError, robot_model
from tmmaster._planning import _configuration
from unsent_moves import SimFactory, command_writes, robot_at

#: Tool down in front of the arm: shoulder in front, J3 > 0, J5 > 0.
START = Pose(250, 0, 200, 180, 0, 90)
#: Tool down near the base on the left: a TM5-700 reaches it only with J5 < 0 (the
#: wrist flipped), no solution in START's configuration.
NEAR_BASE_LEFT = Pose(0, 200, 100, 180, 0, 90)


def test_a_ptp_that_needs_another_configuration_is_refused_before_the_write(
    robots: Callable[..., Robot], memory_simulator_factory: SimFactory
) -> None:
    sim, robot = robot_at(robots, memory_simulator_factory, START)
    with pytest.raises(UnreachablePoseError, match=r"inversekin, p\. 207") as caught:
        robot.check_move(NEAR_BASE_LEFT, speed=30)
    assert caught.value.reason == "configuration"
    with pytest.raises(UnreachablePoseError, match="move_joints"):
        robot.move_to(NEAR_BASE_LEFT, speed=30)
    assert command_writes(sim) == []
    # The model alone finds joints for it, with the wrist flipped (J5 < 0). The way
    # there: a joint move into that configuration, then the PTP is the arm's own.
    arm = robot_model("tm5-700")
    joints = arm.inverse(NEAR_BASE_LEFT, seed_deg=robot.status().joints)
    assert arm.configuration(robot.status().joints) == (True, True, True)
    assert arm.configuration(joints) == (True, True, False)
    robot.move_joints(joints, speed=30)
    robot.move_to(NEAR_BASE_LEFT, speed=30)
    assert robot.status().pose.is_close(NEAR_BASE_LEFT, mm=0.5, deg=0.5)


def test_a_relative_move_out_of_the_configuration_is_refused(
    robots: Callable[..., Robot], memory_simulator_factory: SimFactory
) -> None:
    sim, robot = robot_at(robots, memory_simulator_factory, START)
    offset = NEAR_BASE_LEFT.x - START.x, NEAR_BASE_LEFT.y - START.y, NEAR_BASE_LEFT.z - START.z
    with pytest.raises(UnreachablePoseError) as caught:
        robot.move_by(*offset)
    assert caught.value.reason == "configuration"
    assert command_writes(sim) == []


def test_the_plan_asks_no_configuration_the_check_before_the_write_asked(
    robots: Callable[..., Robot], memory_simulator_factory: SimFactory
) -> None:
    # The configuration is checked before any request and again by the plan, from the
    # joints the robot reports: where those are the seed's, the plan computes nothing new.
    robot = robots(memory_simulator_factory("tmflow"))
    robot.move_to(START, speed=100)
    before = _configuration.cache_info()
    robot.move_to(START.offset(dx=40, dz=30), speed=100)
    after = _configuration.cache_info()
    assert after.misses - before.misses == 1  # the new target's; the seed was known
    assert after.hits - before.hits >= 3  # the seed before the write, both in the plan
