"""A robot whose controller takes another arm configuration than the master assumed.

The master plans a Cartesian PTP in the arm's own configuration
(RobotModel.inverse); a real controller's rule for ``PTP("CPP", ...)`` is not stated in
the manuals. Here the simulated arm takes the other wrist for every Cartesian PTP: the
master must still see each move end (no false timeout), check arrival on the pose the
robot reports, and plan the next move from the joints the robot reports.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from tmmaster import Pose, Robot, RobotModel, UnreachablePoseError, robot_model
from tmmaster.sim import RobotSetup, Simulator

SimFactory = Callable[..., Simulator]
MASTER = robot_model("tm5-700")
POSES = [
    Pose(300, -200, 200, 180, 0, 90),
    Pose(350, 150, 250, 180, 0, 45),
    Pose(250, 0, 300, 180, 0, 90),
]


class OtherWrist(RobotModel):
    """The TM5-700 with a controller that flips the wrist on every Cartesian PTP."""

    def inverse(
        self,
        pose: Pose,
        *,
        seed_deg: Sequence[float] | None = None,
        tool: Pose | None = None,
        same_branch: bool = False,
    ) -> tuple[float, ...]:
        joints = super().inverse(pose, seed_deg=seed_deg, tool=tool, same_branch=same_branch)
        if same_branch:
            return joints  # a Line's path keeps its configuration, as on any arm
        q = joints
        guess = (q[0], q[1], q[2], q[3] + 180.0, -q[4], q[5] + 180.0)
        try:
            other = super().inverse(pose, seed_deg=guess, tool=tool, same_branch=True)
        except UnreachablePoseError:
            return joints
        return other if self.configuration(other) != self.configuration(joints) else joints


def test_the_master_survives_an_arm_that_takes_the_other_wrist(
    memory_simulator_factory: SimFactory,
) -> None:
    arm = OtherWrist(**robot_model("tm5-700").model_dump())
    sim = memory_simulator_factory("tmflow", robot=RobotSetup(model=arm))
    other_branch = 0
    with Robot(sim.url, profile="tmflow", gripper=None) as robot:
        robot.wait_until_ready(timeout_s=5)
        for pose in POSES + POSES[:1]:
            before = robot.status().joints
            assert before is not None
            planned = MASTER.inverse(pose, seed_deg=before)
            robot.move_to(pose, speed=100)
            status: Any = robot.status()
            assert status.pose.is_close(pose, mm=1.0)
            if MASTER.configuration(status.joints) != MASTER.configuration(planned):
                other_branch += 1
    # The arm really was off the master's plan (not agreed by construction).
    assert other_branch >= 3, other_branch
    assert [r.kind for r in sim.motion_log()] == ["ptp"] * (len(POSES) + 1)
    assert all(r.done_wall_time is not None for r in sim.motion_log())
