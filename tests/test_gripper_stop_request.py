"""A stop request refuses a gripper command unsent, as Robot.interrupt() promises.

``Robot.interrupt()``: "until clear_stop_request(), no new command is written either: a
move or gripper command started meanwhile raises StopRequestedError unsent". An awaited
gripper call cancelled (tmmaster.aio) makes the same stop request. The check is on what
the simulated gripper did: its action in the motion log (the article's register
gripper), its fingers' width (a stand-alone OnRobot 2FG7).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

import tmmaster
from tmmaster import GripperDevice, PollPolicy, Robot
from tmmaster.sim import RobotSetup, Simulator


def test_a_stop_request_refuses_the_article_gripper_unsent(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    sim = tm_simulator_factory("article")
    with Robot(
        "127.0.0.1", sim.port, profile="article", polling=PollPolicy(interval_s=0.01)
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.interrupt()
        with pytest.raises(tmmaster.StopRequestedError):
            robot.gripper.close()
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 5, timeout=5)
    assert [m.kind for m in sim.motion_log()] == []  # the fingers never closed


def test_a_stop_request_refuses_a_stand_alone_gripper_unsent(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(gripper="onrobot-2fg7"))
    gripper = GripperDevice("onrobot-2fg7", port=sim.gripper_port)
    with Robot(
        "127.0.0.1", sim.port, gripper=gripper, polling=PollPolicy(interval_s=0.01)
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        width = robot.gripper.status().width_mm
        robot.interrupt()
        with pytest.raises(tmmaster.StopRequestedError):
            robot.gripper.close()
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 5, timeout=5)
        robot.clear_stop_request()
        assert robot.gripper.status().width_mm == width  # the fingers never moved
