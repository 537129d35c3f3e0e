"""An ``article`` robot left in another arm configuration than the master assumes.

The article's map publishes the TCP pose, never the joints, so the master plans an
``article`` robot's first move from the model's ready posture (docs/kinematics.md,
"Where it is used"). A TCP pose does not tell the branch: an arm jogged wrist-flipped
on the pendant shows the same pose. The master's checks of the move (self-collision,
joint ranges) then hold the path from the wrong branch, and the robot runs its own.
"""

from __future__ import annotations

import pytest

from safety_invariant import at_rest
from tmmaster import ConfigError, Pose, Robot, RobotFaultError, robot_model
from tmmaster.sim import Cell, Simulator

ARM = robot_model("tm5-700")
HOME = Pose(250, 0, 300, 180, 0, 90)
#: From HOME wrist-flipped, the PTP here passes the camera through wrist 1.
THROUGH_ITSELF = Pose(300, -200, 200, 180, 0, 90)


@pytest.mark.xfail(
    strict=True,
    raises=RobotFaultError,
    reason="article publishes no joints: the master checks the PTP from the ready"
    " posture's branch, the arm runs it from its own (wrist-flipped) and meets itself;"
    " use tmflow, which plans from the joints the robot reports",
)
def test_a_ptp_through_the_arms_body_from_where_it_is_is_refused_unsent() -> None:
    j1, j2, j3, j4, j5, j6 = ARM.inverse(HOME)
    flipped = ARM.inverse(HOME, seed_deg=(j1, j2, j3, j4 + 180, -j5, j6 - 180))
    with Simulator("article", time_scale=10, listen=False, cell=Cell(scene=[])) as sim:
        backend = sim.backend
        # The operator jogs the arm wrist-flipped on the pendant: same TCP pose.
        sim.call(lambda: backend.start_joint_motion(flipped, speed_percent=100, accel_time_s=0.2))  # type: ignore[attr-defined]
        sim.wait_for(at_rest(sim), timeout=5.0, interval=0.05)
        assert sim.tcp_pose().is_close(HOME, mm=0.01, deg=0.01)
        before = len(sim.motion_log())
        robot = Robot(sim.url, profile="article", gripper=None)
        with robot, pytest.raises(ConfigError, match="self-collision"):
            robot.move_to(THROUGH_ITSELF, speed=60)
        assert len(sim.motion_log()) == before
