"""A robot whose controller takes another arm configuration than the master assumed.

The master plans a Cartesian PTP in the arm's own configuration
(RobotModel.inverse); a real controller's rule for ``PTP("CPP", ...)`` is not stated in
the manuals. Here the simulated arm leaves its configuration on every Cartesian PTP: the
master must still see each move end (no false timeout), check arrival on the pose the
robot reports, and plan the next move from the joints the robot reports.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from tmmaster import ConfigError, Pose, Robot, RobotModel, UnreachablePoseError, robot_model
from tmmaster._body import contacts, ptp_samples
from tmmaster.sim import RobotSetup, Simulator

SimFactory = Callable[..., Simulator]
MASTER = robot_model("tm5-700")
#: Tool-down targets whose every configuration the arm's body allows, from one another.
POSES = [
    Pose(350, 200, 400, 180, 0, 90),
    Pose(350, 0, 400, 180, 0, 90),
    Pose(350, 200, 250, 180, 0, -90),
]


class OtherConfiguration(RobotModel):
    """The TM5-700 with a controller that never keeps the arm's configuration on a
    Cartesian PTP: it takes the nearest solution in any other one that its body can
    reach (no part meeting another on the way)."""

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
        seed = tuple(seed_deg) if seed_deg is not None else self.ready_joints_deg
        keep = self.configuration(joints)
        others = []
        for start in self._starts(seed) + self._wide_starts(seed, pose):
            try:
                other = super().inverse(pose, seed_deg=start, tool=tool, same_branch=True)
            except UnreachablePoseError:
                continue
            path = ptp_samples(seed, other)
            if self.configuration(other) != keep and not any(contacts(self, q, tool) for q in path):
                others.append(other)
        return min(others, key=lambda q: self.ptp_seconds(seed, q), default=joints)


def test_the_master_survives_an_arm_that_takes_another_configuration(
    memory_simulator_factory: SimFactory,
) -> None:
    arm = OtherConfiguration(**robot_model("tm5-700").model_dump())
    sim = memory_simulator_factory("tmflow", robot=RobotSetup(model=arm))
    other_branch = refused = 0
    with Robot(sim.url, profile="tmflow", gripper=None) as robot:
        robot.wait_until_ready(timeout_s=5)
        for pose in POSES + POSES[:1]:
            before = robot.status().joints
            assert before is not None
            ran = len(sim.motion_log())
            try:
                planned = MASTER.inverse(pose, seed_deg=before)
                robot.move_to(pose, speed=100)
            except ConfigError:
                # From where the arm went, the master's own plan meets the arm's body:
                # refused before any byte, and the arm stays where it is.
                refused += 1
                assert len(sim.motion_log()) == ran
                continue
            status: Any = robot.status()
            assert status.pose.is_close(pose, mm=1.0)
            if MASTER.configuration(status.joints) != MASTER.configuration(planned):
                other_branch += 1
    # The arm really was off the master's plan (not agreed by construction), and every
    # move the master sent ended, on target, without a false timeout.
    assert other_branch >= 2, (other_branch, refused)
    assert [r.kind for r in sim.motion_log()] == ["ptp"] * (len(POSES) + 1 - refused)
    assert all(r.done_wall_time is not None for r in sim.motion_log())
