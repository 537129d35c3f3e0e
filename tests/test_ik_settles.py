"""Inverse kinematics answers the same joints from nearby seeds, so a cycle's plans repeat.

A repeating cycle seeds each move's solve with the previous move's joints; an answer
that still depended on the seed at the solver's tolerance would give each cycle new
seeds, and the planner's caches would miss move after move.
"""

from __future__ import annotations

import pytest

from tmmaster import Pose, robot_model

ABOVE = Pose(300, -200, 200, 180, 0, 90)
BELOW = Pose(300, -200, 120, 180, 0, 90)


@pytest.mark.parametrize("target", [ABOVE, BELOW])
def test_nearby_seeds_give_the_same_joints(target: Pose) -> None:
    arm = robot_model("tm5-700")
    other = BELOW if target is ABOVE else ABOVE
    seed = arm.inverse(other)
    answers = [
        arm.inverse(target, seed_deg=[q + shift for q in seed]) for shift in (0.0, 0.01, -0.02)
    ]
    # The same at the resolution the caches key seeds by (1e-3 deg), a hundred times over;
    # what is left is the rounding of the pose error near zero (about 1e-8 rad).
    for answer in answers[1:]:
        assert max(abs(a - b) for a, b in zip(answer, answers[0], strict=True)) < 1e-5
