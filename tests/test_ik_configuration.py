"""Which joint solution a Cartesian target gets: the arm's own configuration first.

The rule (RobotModel.inverse): the solution in the seed's pose configuration
(shoulder, elbow, wrist: Techman's Config1-3, TMscript 2.24 pp. 332-334) when there is
one, as TMscript's ``inversekin`` answers "by the current pose configuration" (p. 207);
otherwise the one with the shortest PTP from the seed.
"""

from __future__ import annotations

import random
from collections.abc import Sequence

import pytest

from tmmaster import Pose, UnreachablePoseError, robot_model

MODEL = robot_model("tm5-700")


def shoulder_elbow_wrist(joints: Sequence[float]) -> tuple[bool, bool, bool]:
    """The configuration, from the joint frames (written apart from the model's own)."""
    frames = MODEL.joint_frames(joints)
    axis_x, axis_y = frames[1][0][2], frames[1][1][2]  # J2's axis
    wrist_x, wrist_y = frames[4][0][3], frames[4][1][3]  # J5's origin
    front = wrist_x * axis_y - wrist_y * axis_x
    return (front >= 0, joints[2] >= 0, joints[4] >= 0)


#: Current joints and a target (random postures, fixed) from which the solver used to
#: leave the arm's configuration although a solution in it exists.
KEEPS_CONFIGURATION = [
    (
        (28.6, 137.4, 56.4, 145.8, 121.2, 166.9),
        (-145.749, -308.593, 191.736, -106.419, 4.547, 96.54),
    ),
    (
        (-64.7, -143.8, 30.9, -159.3, -102.9, -31.3),
        (109.811, -133.966, -211.003, 142.365, 35.355, 128.432),
    ),
    (
        (135.3, 98.9, -73.7, -12.2, -128.1, 106.5),
        (88.362, -123.286, -176.616, 5.024, -13.146, 165.455),
    ),
]


@pytest.mark.parametrize(("seed", "target"), KEEPS_CONFIGURATION)
def test_a_target_keeps_the_arms_configuration_when_it_can(
    seed: tuple[float, ...], target: tuple[float, ...]
) -> None:
    joints = MODEL.inverse(Pose(*target), seed_deg=seed)
    assert MODEL.forward(joints).is_close(Pose(*target), mm=1e-3)
    assert shoulder_elbow_wrist(joints) == shoulder_elbow_wrist(seed)


def solutions(pose: Pose, seed: Sequence[float]) -> list[tuple[float, ...]]:
    """Every solution found from the model's start postures, each taken alone."""
    found = []
    for start in MODEL._starts(tuple(seed)) + MODEL._wide_starts(tuple(seed), pose):
        try:
            found.append(MODEL.inverse(pose, seed_deg=start, same_branch=True))
        except UnreachablePoseError:
            continue
    return found


def test_the_eight_configurations_of_one_pose_are_told_apart() -> None:
    pose = Pose(250, 0, 200, 180, 0, 90)
    found = solutions(pose, MODEL.ready_joints_deg)
    assert {MODEL.configuration(j) for j in found} == {
        (a, b, c) for a in (False, True) for b in (False, True) for c in (False, True)
    }
    assert all(MODEL.configuration(j) == shoulder_elbow_wrist(j) for j in found)


def test_without_the_arms_configuration_the_shortest_ptp_is_taken() -> None:
    # Straight below this posture, J3 would pass its 155 deg limit in its configuration.
    seed = (29.3, -33.3, 143.4, -20.1, 90.0, 29.3)
    pose = Pose(250, 0, 100, 180, 0, 90)
    joints = MODEL.inverse(pose, seed_deg=seed)
    assert shoulder_elbow_wrist(joints) != shoulder_elbow_wrist(seed)
    found = solutions(pose, seed)
    assert found
    assert MODEL.ptp_seconds(seed, joints) <= min(MODEL.ptp_seconds(seed, j) for j in found) + 1e-9


def test_the_models_configuration_is_the_joint_frames_one_on_random_postures() -> None:
    rnd = random.Random(7)
    for _ in range(3000):
        joints = tuple(rnd.uniform(-270.0, 270.0) for _ in range(6))
        assert MODEL.configuration(joints) == shoulder_elbow_wrist(joints), joints
