"""The kinematic backend's flange pose is the forward kinematics of its joints, at every tick.

Techman's table publishes the flange beside the TCP at every tick of a tmflow robot: the
pose read must be ``RobotModel.forward(joints)`` to the last bit, with a tool or without,
during a PTP, a joint move and a line, and at rest.
"""

from __future__ import annotations

import pytest

import tmmaster
from tmmaster._pose import MotionType, Pose
from tmmaster.sim._kinematic import KinematicBackend

TM5 = tmmaster.robot_model("tm5-700")
TOOL = Pose(0, 0, 120, 0, 0, 30)
LEFT = Pose(300, -200, 200, 180, 0, 90)
RIGHT = Pose(300, 200, 250, 180, 0, 60)


@pytest.mark.parametrize("tool", [None, TOOL], ids=["no-tool", "tool"])
def test_the_flange_is_the_forward_kinematics_of_the_joints_at_every_tick(
    tool: Pose | None,
) -> None:
    backend = KinematicBackend(TM5, tool=tool)
    moves = [
        lambda: backend.start_motion(
            LEFT, motion=MotionType.PTP, speed_percent=60, accel_time_s=0.2
        ),
        lambda: backend.start_motion(
            RIGHT, motion=MotionType.LINE, speed_percent=60, accel_time_s=0.2
        ),
        lambda: backend.start_joint_motion(
            (10, 5, 80, 0, 90, 0), speed_percent=60, accel_time_s=0.2
        ),
        lambda: backend.start_motion(
            LEFT, motion=MotionType.PTP, speed_percent=60, accel_time_s=0.2
        ),
    ]
    ticks = 0
    for start in moves:
        start()
        for _ in range(400):
            backend.step(0.02)
            joints = backend.joint_positions_deg()
            assert joints is not None
            assert backend.flange_pose() == TM5.forward(joints), (ticks, joints)
            ticks += 1
            if backend.is_settled():
                break
        else:
            raise AssertionError("the move never settled")
    assert ticks > 40
    backend.step(0.02)  # at rest
    assert backend.flange_pose() == TM5.forward(backend.joint_positions_deg() or ())
