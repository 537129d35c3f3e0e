"""A relative Line (``move_by(..., motion="line")``) is checked as ``move_to``'s Line is.

``move_by`` resolves its offset against the pose the robot reports into one absolute
target, "validated and sent like move_to's". It validated that target as a PTP's only
(``validate_move``: the arm's body along the joint-space path): a Line's straight path,
which ``move_to(target, motion="line")`` checks from where the arm is and refuses
unsent when it passes the arm through its own body, was never checked. From HOME, the
Line below swings the camera into the wrist; its PTP is clear. ``move_to`` refused it,
``move_by`` sent it and the simulated arm stopped in its collision (0x0022), on both
profiles (found by the review of this session's move checks, tests/test_hunt18_moved_arm.py).

The judge is the simulator: nothing runs, no error.
"""

from __future__ import annotations

import pytest

from test_hunt11_calibrated_arm import HOME
from tmmaster import ConfigError, Pose, Robot
from tmmaster._planning import moved
from tmmaster.sim import Cell, Simulator

#: From HOME, a Line by this offset (robot base frame) passes the camera through the
#: wrist; the PTP to the same target is clear.
OFFSET = Pose(-249.66, -215.44, -11.09, 50.58, -54.24, 65.89)


def _by(robot: Robot, motion: str) -> None:
    o = OFFSET
    robot.move_by(o.x, o.y, o.z, o.rx, o.ry, o.rz, speed=30, motion=motion)  # type: ignore[arg-type]


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_relative_line_through_the_arms_body_is_refused_unsent(profile: str) -> None:
    sim = Simulator(profile, time_scale=10, listen=False, cell=Cell(scene=[]))
    with sim, Robot(sim.url, profile=profile, gripper=None) as robot:
        robot.move_to(HOME, speed=60)
        target = moved(robot.pose(), OFFSET, "base")
        before = len(sim.motion_log())
        # What move_to answers for the same Line: refused, unsent.
        with pytest.raises(ConfigError, match="self-collision"):
            robot.move_to(target, speed=30, motion="line")
        with pytest.raises(ConfigError, match="self-collision"):
            _by(robot, "line")
        assert len(sim.motion_log()) == before  # nothing ran
        assert robot.status().error_code == 0
        _by(robot, "ptp")  # its PTP is clear, and runs
        assert sim.tcp_pose().is_close(target, mm=0.5, deg=0.5)
        assert robot.status().error_code == 0
