"""Inverse kinematics refuses only what the arm cannot take, for the true reason, early.

* Every branch is searched before a refusal: a pose made by forward kinematics from
  admissible joints is always found (an independent multi-start check).
* The reason names the true cause: a pose whose in-range solutions are all too close
  to a singularity is a singularity, not a joint limit.
* The datasheet reach applies to the flange whatever the tool.
* The table plane (on by default) and a Line's path are refused before any request.
"""

from __future__ import annotations

import random
from collections.abc import Callable

import pytest

import tmmaster
from sim_speeds import QUICK
from tmmaster import Checks, ConfigError, Pose, Robot, UnreachablePoseError, Workspace
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
TM5 = tmmaster.robot_model("tm5-700")
TM12 = tmmaster.robot_model("tm12")


def admissible_poses(model: tmmaster.RobotModel, count: int, seed: int) -> list[Pose]:
    """Flange poses of random joints inside every range and clear of the singularity margins.

    Joints within 1 deg (20 mm at the shoulder) of a margin are skipped, so that a
    solution the solver finds a hair on the other side of the margin does not count.
    """
    wider = model.model_copy(
        update={
            "wrist_margin_deg": model.wrist_margin_deg + 1,
            "elbow_margin_deg": model.elbow_margin_deg + 1,
            "shoulder_margin_mm": model.shoulder_margin_mm + 20,
        }
    )
    rng = random.Random(seed)
    poses: list[Pose] = []
    while len(poses) < count:
        joints = [rng.uniform(*j.limits_deg) for j in model.joints]
        if wider.singularity(joints) is not None:
            continue
        pose = model.forward(joints)
        if model.distance_from_shoulder(pose) <= model.reach_mm:
            poses.append(pose)
    return poses


@pytest.mark.parametrize(
    ("model", "pose"),
    [
        # The shoulder folded back below the base (J2 -133 deg): none of the canonical
        # postures converges there.
        (TM12, Pose(649, 197, -880, 41.8, -78.2, 73.4)),
        # Every canonical posture converges with a joint past its range; J1 at +142 deg
        # (aimed away from the flange) takes it.
        (TM12, Pose(66.92, 92.58, 335.10, 24.08, -15.18, 30.74)),
    ],
)
def test_a_pose_reachable_only_on_a_far_branch_is_found(
    model: tmmaster.RobotModel, pose: Pose
) -> None:
    joints = model.inverse(pose)
    assert model.forward(joints).is_close(pose, mm=0.01, deg=0.01)


@pytest.mark.parametrize("model", [TM5, TM12], ids=lambda m: m.name)
def test_every_admissible_pose_is_found_from_the_ready_posture(
    model: tmmaster.RobotModel,
) -> None:
    # The independent check: joints first, then the pose; the solver never saw them.
    for pose in admissible_poses(model, 40, seed=11):
        joints = model.inverse(pose)
        assert model.forward(joints).is_close(pose, mm=0.01, deg=0.01), pose


def test_a_pose_whose_in_range_solution_is_singular_says_singularity() -> None:
    # Made from joints with J5 = -0.7 deg: inside every range, inside the wrist margin.
    # Another branch would need J3 = -178.6 deg; the true cause is the singularity.
    pose = Pose(-200.707, 123.976, 24.067, -86.228, 79.708, 65.668)
    with pytest.raises(UnreachablePoseError) as raised:
        TM5.inverse(pose)
    assert raised.value.reason == "singularity"
    assert "wrist" in str(raised.value)


@pytest.mark.parametrize("distance", [705.0, 720.0, 740.0])
def test_the_reach_limit_holds_with_any_tool(distance: float) -> None:
    # Just past the datasheet reach (700 mm), where the chain itself still gets.
    pose = Pose(distance, 0, TM5.shoulder_height_mm, 0, 90, 0)
    for tool in (None, Pose(0, 0, 0, 0, 0, 0)):
        with pytest.raises(UnreachablePoseError) as raised:
            TM5.inverse(pose, tool=tool)
        assert raised.value.reason == "reach"
    # With a real tool the flange is what must be in reach: 100 mm of tool along the
    # flange's z axis (pointing along +x here) lets the TCP go 100 mm further.
    tool = Pose(0, 0, 100, 0, 0, 0)
    TM5.inverse(Pose(distance, 0, TM5.shoulder_height_mm, 0, 90, 0), tool=tool)


# -- checks before any request ----------------------------------------------------------


def test_the_table_plane_is_on_by_default() -> None:
    workspace = Workspace()  # the default cell's table top, 85 mm
    workspace.check(Pose(300, 0, 100, 180, 0, 90))
    with pytest.raises(ConfigError, match="table plane"):
        workspace.check(Pose(300, 0, -150, 180, 0, 90))
    # The flange is a tool point too: a tool pointing up from below the table.
    tool = Pose(0, 0, 150, 0, 0, 0)
    with pytest.raises(ConfigError, match="flange"):
        workspace.check(Pose(300, 0, 200, 0, 0, 0), tool=tool)
    workspace.check(Pose(300, 0, 100, 180, 0, 0), tool=tool)  # tool down: flange at 250
    # Configurable: a table top, or none for a pedestal.
    with pytest.raises(ConfigError, match="floor_z_mm = 85"):
        Workspace(floor_z_mm=85).check(Pose(300, 0, 55, 180, 0, 90))
    Workspace(floor_z_mm=None).check(Pose(300, 0, -150, 180, 0, 90))


def test_a_target_below_the_table_is_refused_before_any_request(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = memory_simulator_factory("tmflow", **QUICK)
    robot = robots(sim, gripper=None)
    before = robot.stats.requests
    with pytest.raises(ConfigError, match="table plane"):
        robot.move_to(Pose(300, -200, -150, 180, 0, 90), speed=10)
    assert robot.stats.requests == before
    assert not [m for m in sim.motion_log() if m.target is not None]


def test_a_line_the_arm_cannot_follow_is_refused_before_any_request(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = memory_simulator_factory("tmflow", **QUICK)
    # The target's posture has the elbow low (link 2 below the default table plane, where
    # the simulated table is not): the arm's links are not what this test is about.
    robot = robots(sim, gripper=None, checks=Checks(workspace=Workspace(arm_radius_mm=None)))
    start = Pose(350, -150, 250, 180, 0, 90)
    robot.move_to(start, speed=100)
    # Straight across the J1 axis: the path passes the shoulder singularity.
    across = Pose(-350, 150, 250, 180, 0, -90)
    robot.validate_move(across, 10)  # the target alone is fine
    before = robot.stats.requests
    with pytest.raises(UnreachablePoseError):
        robot.move_to(across, speed=10, motion="line")
    assert robot.stats.requests == before
    assert [m.target for m in sim.motion_log() if m.target is not None] == [start]
