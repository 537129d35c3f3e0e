"""A sequence whose own ``prepare`` moves the arm is planned from where it left it.

Runner.run checks the whole plan before its first command (12e3472), from the pose and
joints the robot reports once it is ready. A ``prepare`` is user code and may move the
arm (the runner waits for a move it leaves running, e8caabf): one that brings a
wrist-flipped arm back to its home posture before the first step was refused in IDLE,
the first step's PTP checked from where the arm stood before the prepare (a
self-collision from there, none from home), where the same run ended DONE before
12e3472. A prepare of the library's (the gripper open, the held-part check) moves no
arm: the plan is still checked before it, so a refusal opens nothing
(tests/test_hunt21_runner_validates.py).

The judge is the simulator: the arm ran the prepare's move and the step's, no error.
"""

from __future__ import annotations

import pytest

from test_hunt11_calibrated_arm import HOME, NOMINAL, THROUGH_ITSELF, wrist_flipped
from tmmaster import ConfigError, Robot
from tmmaster.pickplace import PlannedMove, Runner, StepContext, TaskSequence
from tmmaster.sim import Cell, Simulator

HOME_JOINTS = [round(q, 2) for q in NOMINAL.inverse(HOME)]


def _home_first(ctx: StepContext) -> None:
    ctx.robot.move_joints(HOME_JOINTS, speed=60)  # the wrist back from wherever it was


def test_a_prepare_that_moves_the_arm_has_the_plan_checked_from_where_it_left_it() -> None:
    sequence = TaskSequence("home-first", prepare=_home_first)
    sequence.add("TO_TARGET", move=PlannedMove("TO_TARGET", THROUGH_ITSELF, 60, "ptp"))
    with Simulator(time_scale=10, listen=False, cell=Cell(scene=[])) as sim:
        with Robot(sim.url, gripper=None) as robot:
            robot.move_joints(wrist_flipped(NOMINAL), speed=100)  # an earlier program's end
            # From there, the step's PTP meets the arm's own body: refused, unsent.
            with pytest.raises(ConfigError, match="self-collision"):
                robot.check_move(THROUGH_ITSELF, 60)
            before = len(sim.motion_log())
            result = Runner(robot).run(sequence)
        assert result.ok, result.failure
        assert len(sim.motion_log()) == before + 2  # the prepare's move, then the step's
        assert sim.tcp_pose().is_close(THROUGH_ITSELF, mm=0.5, deg=0.5)
        assert sim.field("last_error_code") == 0
