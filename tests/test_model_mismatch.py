"""A Robot made for another arm model than the one it drives is refused at connect.

The master checks every move by its model's kinematics: the reach, the joint limits,
the links against the table and each other, the path, the expected time. Made with
the wrong ``model`` (a ``tm5-900`` cell driven as the default ``tm5-700``, a typo'd
pick & place config), every one of those checks is another arm's: a move the real arm
cannot make passes them until the robot program refuses it, and a link the wrong model
keeps clear of the table may not be. Where the robot publishes its joints (``tmflow``),
their forward kinematics by the master's model must put the TCP where the robot
reports it (within 10 mm and 5 deg, a calibrated arm's few mm pass: see
tests/test_hunt11_calibrated_arm.py); otherwise connect raises a ConfigError naming
``model`` and the built-in model the joints fit, before any command is written.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tmmaster import ConfigError, Pose, Robot
from tmmaster.sim import Cell, RobotSetup, Simulator

#: Reachable by each of the built-in models: a move there would run on any of them.
NEAR = Pose(300, -200, 200, 180, 0, 90)


@pytest.fixture(params=["tm5-700", "tm5-900"])
def arm(request: pytest.FixtureRequest) -> str:
    """The simulated arm's model."""
    return str(request.param)


@pytest.fixture
def sim(arm: str) -> Iterator[Simulator]:
    """A tmflow robot of model ``arm`` (its joints published at 7013-7036)."""
    setup = RobotSetup(model=arm)
    with Simulator(time_scale=40, listen=False, robot=setup, cell=Cell(scene=[])) as made:
        yield made


@pytest.mark.parametrize("model", ["tm5-700", "tm5-900", "tm12", "tm14"])
def test_a_robot_of_another_model_is_refused_at_connect_and_never_commanded(
    sim: Simulator, arm: str, model: str
) -> None:
    robot = Robot(sim.url, model=model, gripper=None)
    if model == arm:
        with robot:
            robot.move_to(NEAR, speed=50)
        assert [record.target for record in sim.motion_log()] == [NEAR]
        assert any(r.values is not None for r in sim.request_log)  # the log sees writes
        return
    with pytest.raises(ConfigError, match=rf"model.*{model}.*fit {arm}"):
        robot.connect()
    writes = [r for r in sim.request_log if r.values is not None]
    assert writes == []  # nothing written, not even a heartbeat
    assert sim.motion_log() == ()
