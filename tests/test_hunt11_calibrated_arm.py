"""A TM5 whose kinematics differ from the nominal chain by a millimetre or two.

A real TM5 is calibrated: the TCP it reports is its own kinematics' of its joints,
which can differ from the URDF chain the master models by a few mm. What the master
plans must still come from the joints the robot REPORTS (their branch), and what it
checks at the end must be what the robot reports, not the model's prediction.

Found by this hunt (each fails without its fix):

- joints whose nominal forward kinematics missed the reported TCP by more than the
  arrival tolerance (1 mm) were ignored as "not the arm's", so the first move of a
  Robot planned (and ``validate_move`` checked) from the model's ready posture: an arm
  left wrist-flipped ran a PTP through its own body (the simulated arm stopped, 0x0022)
  that the same master refuses, unsent, on a nominal arm;
- a joint move ended in ``RobotError`` ("finished but the TCP is at ... 1.50 mm from
  the target") with every joint exactly on its target: the target TCP was the nominal
  forward kinematics.
"""

from __future__ import annotations

import pytest

from tmmaster import Checks, ConfigError, Pose, Robot, RobotModel, robot_model
from tmmaster.sim import Cell, RobotSetup, Simulator

NOMINAL = robot_model("tm5-700")
HOME = Pose(250, 0, 300, 180, 0, 90)
#: From HOME wrist-flipped, the PTP to it passes the camera through wrist 1 (the model's
#: self-collision): refused unsent on a nominal arm.
THROUGH_ITSELF = Pose(300, -200, 200, 180, 0, 90)
#: From HOME wrist-flipped, reachable in that configuration.
REACHABLE = Pose(300, 150, 250, 180, 0, 60)


def calibrated(extra_mm: float) -> RobotModel:
    """The TM5-700 with its upper arm (J2 to J3) ``extra_mm`` longer than nominal."""
    joints = list(NOMINAL.joints)
    joints[2] = joints[2].model_copy(update={"origin_xyz_mm": (329.0 + extra_mm, 0.0, 0.0)})
    return NOMINAL.model_copy(update={"joints": tuple(joints)})


def wrist_flipped(arm: RobotModel) -> list[float]:
    """HOME's joints on ``arm`` with the wrist flipped (J5 < 0), rounded as a user types."""
    j1, j2, j3, j4, j5, j6 = arm.inverse(HOME)
    joints = arm.inverse(HOME, seed_deg=(j1, j2, j3, j4 + 180, -j5, j6 - 180))
    assert arm.configuration(joints)[2] is False
    return [round(q, 2) for q in joints]


def left_flipped(sim: Simulator, arm: RobotModel) -> list[float]:
    """An earlier program leaves the arm wrist-flipped; returns its joints."""
    joints = wrist_flipped(arm)
    # Arrival on the joints: the TCP check is the model's (a tolerance wide enough for
    # the calibrated arm keeps this set-up independent of the fix for it).
    with Robot(sim.url, gripper=None, checks=Checks(position_tolerance_mm=5)) as robot:
        robot.move_joints(joints, speed=100)
    return joints


@pytest.mark.parametrize("extra_mm", [0.0, 1.5], ids=["nominal", "calibrated"])
def test_the_first_move_is_planned_on_the_branch_the_robot_reports(extra_mm: float) -> None:
    arm = calibrated(extra_mm)
    robot_setup = RobotSetup(model=arm)
    with Simulator(time_scale=10, listen=False, robot=robot_setup, cell=Cell(scene=[])) as sim:
        left_flipped(sim, arm)
        before = len(sim.motion_log())
        with Robot(sim.url, gripper=None) as robot:  # a new run: it knows nothing yet
            # Checked as from the arm's joints, as the move itself will be.
            assert arm.configuration(robot.validate_move(REACHABLE, speed=60))[2] is False
            with pytest.raises(ConfigError, match="self-collision"):
                robot.validate_move(THROUGH_ITSELF, speed=60)
            with pytest.raises(ConfigError, match="self-collision"):
                robot.move_to(THROUGH_ITSELF, speed=60)
            assert len(sim.motion_log()) == before  # nothing ran
            assert sim.field("last_error_code") == 0
            robot.move_to(REACHABLE, speed=60)
        joints = sim.call(sim.backend.joint_positions_deg)
        assert joints is not None
        assert arm.configuration(joints)[2] is False  # it stayed wrist-flipped
        assert sim.tcp_pose().is_close(REACHABLE, mm=0.01, deg=0.01)


def test_a_joint_move_on_a_calibrated_arm_ends_done_on_its_joints() -> None:
    arm = calibrated(1.5)
    joints = wrist_flipped(arm)
    robot_setup = RobotSetup(model=arm)
    with Simulator(time_scale=10, listen=False, robot=robot_setup, cell=Cell(scene=[])) as sim:
        with Robot(sim.url, gripper=None) as robot:
            robot.move_joints(joints, speed=100)
            reported = robot.status().joints
        assert reported is not None
        assert max(abs(a - b) for a, b in zip(reported, joints, strict=True)) < 0.01
        # The nominal model puts that TCP 1.5 mm from where the arm reports it.
        assert NOMINAL.forward(joints).distance_to(sim.tcp_pose()) > 1.0
