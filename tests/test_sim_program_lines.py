"""The simulated robot program checks a Line from the arm's joints, as the robot does.

A Line the master accepted (planned from the joints the robot reports) must not be
refused by the simulated program because it checked the path from another posture.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from tmmaster import Pose, Robot, UnreachablePoseError, robot_model
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
MODEL = robot_model("tm5-700")
#: The wrist flipped (J5 < 0): from here a Line straight down near the base keeps clear
#: of J3's limit; from the ready posture's wrist the same Line passes it.
FLIPPED_WRIST = (37.7, -7.3, 108.1, 169.2, -90.0, -142.3)
BELOW = Pose(200, 0, 150, 180, 0, 90)


@pytest.fixture
def robot(memory_simulator_factory: SimFactory) -> Iterator[Robot]:
    sim = memory_simulator_factory("tmflow")
    with Robot(sim.url, profile="tmflow", gripper=None) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.sim = sim  # type: ignore[attr-defined]
        yield robot


def test_a_line_from_a_flipped_wrist_runs_as_the_master_planned_it(robot: Robot) -> None:
    sim: Simulator = robot.sim  # type: ignore[attr-defined]
    robot.move_joints(FLIPPED_WRIST, speed=100)
    with pytest.raises(UnreachablePoseError):  # the same Line from the ready posture
        MODEL.line_joints(MODEL.forward(FLIPPED_WRIST), BELOW)
    robot.move_to(BELOW, speed=50, motion="line")
    assert sim.motion_log()[-1].kind == "line"
    assert sim.motion_log()[-1].done_wall_time is not None
    assert robot.status().pose.is_close(BELOW, mm=1.0)
