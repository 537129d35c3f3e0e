"""``robot.model = ...`` on a connected robot: the arm is checked against the new model.

``connect()`` refuses a Robot whose ``model`` the arm's reported joints do not fit
(``tests/test_model_mismatch.py``): every check of a move would be another arm's (the
reach, the joint limits, the links against the table and each other, the expected
time). ``Robot.model`` has a setter, documented among the options "meant to change
while it runs", and it checked only the type and the tool's mass against the new
model's payload: set to a ``tm5-900`` on a connected TM5-700, it was taken, and the next
moves were planned and checked by the TM5-900's kinematics, the robot's joints ignored
as "not the arm's" (their forward kinematics miss the reported TCP: a warning, once).

Found by hunt 18; fixed: set on a connected robot, the setter makes connect's check
(one read of the flange and the joints) and refuses a model they do not fit, the model
not taken.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import ConfigError, Pose, Robot, robot_model
from tmmaster.sim import Cell, Simulator

NEAR = Pose(300, -200, 200, 180, 0, 90)


def test_a_model_the_connected_arm_does_not_fit_is_refused_before_any_move(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    sim = tm_simulator_factory(cell=Cell(scene=[]))  # a TM5-700
    with Robot(sim.url, gripper=None) as robot:
        robot.move_to(NEAR, speed=50)
        with pytest.raises(ConfigError, match=r"model.*tm5-900.*fit tm5-700"):
            robot.model = robot_model("tm5-900")  # refused as connect() refuses it
        assert robot.model.name == "tm5-700"
        robot.move_to(NEAR.offset(dz=50), speed=50)  # planned by the arm's own model
        assert sim.motion_log()[-1].target == NEAR.offset(dz=50)


def test_a_model_given_by_name_is_checked_against_the_arm_as_a_model_object_is(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    sim = tm_simulator_factory(cell=Cell(scene=[]))  # a TM5-700
    with Robot(sim.url, gripper=None, model="tm5-700") as robot:
        with pytest.raises(ConfigError, match=r"model 'tm5-900'.*fit tm5-700"):
            robot.model = "tm5-900"
        assert robot.model is robot_model("tm5-700")
