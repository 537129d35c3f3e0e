"""A Cartesian PTP goes to the posture the master planned, whatever the controller's own
rule for a PTP without a posture would be.

The master plans a Cartesian PTP's joints with its own inverse kinematics: the solution
in the arm's configuration, nearest the joints the robot reports (docs/kinematics.md).
Which solution a TM controller takes for ``PTP("CPP", target, ...)`` without a pose
configuration the manuals do not say (TMscript 2.24 §13.8 Syntax 1, p. 331: "robot
posture attention required"). The robot program solves the target "by the current pose
configuration" (``inversekin``, §6.35, p. 207) and gives that solution to the PTP as
its reference joints, so that the robot moves to "the closest assigned joint target"
(Syntax 3, pp. 334-335): the solution the master planned.

The simulated controller here honours the reference as the manual says (a reference
that solves the target is where the arm goes) and, without one, takes another
configuration, as a controller whose unstated rule differs from the master's might. The
judge is the arm: its joints after each move (the simulator's backend, not what the
master believes) against the master's plan from the joints the robot reported.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

from test_other_branch import POSES, OtherConfiguration
from tmmaster import ConfigError, Pose, Robot, RobotModel, robot_model
from tmmaster._profiles import robot_profile
from tmmaster._robot_program import robot_program
from tmmaster.sim import RobotSetup, Simulator
from tmmaster.sim._script_project import simulated_tool

SimFactory = Callable[..., Simulator]
MASTER = robot_model("tm5-700")
NEW_PTP = 'ok = PTP("CPP", target, speed, accel, 0, false, joints)'
OLD_PTP = 'ok = PTP("CPP", target, speed, accel, 0, false)'


class ClosestToReference(OtherConfiguration):
    """A TM5-700 controller that goes to "the closest assigned joint target" of a PTP's
    reference joints (a reference that solves the target is where the arm goes), and
    otherwise takes the nearest solution in another configuration its body reaches
    (test_other_branch's controller)."""

    def inverse(
        self,
        pose: Pose,
        *,
        seed_deg: Sequence[float] | None = None,
        tool: Pose | None = None,
        same_branch: bool = False,
    ) -> tuple[float, ...]:
        seed = tuple(seed_deg) if seed_deg is not None else self.ready_joints_deg
        if not same_branch and self.forward(seed, tool).is_close(pose, mm=0.01, deg=0.01):
            # The reference solves the target: it is the closest.
            return RobotModel.inverse(self, pose, seed_deg=seed_deg, tool=tool)
        return super().inverse(pose, seed_deg=seed_deg, tool=tool, same_branch=same_branch)


def _program(tmp_path: Path, ptp: str) -> Path:
    """The generated program, its Cartesian PTP written as ``ptp``."""
    text = robot_program(robot_profile("tmflow"), tool=simulated_tool(None))
    assert text.count(NEW_PTP) == 1
    path = tmp_path / "program.tms"
    path.write_text(text.replace(NEW_PTP, ptp), encoding="utf-8")
    return path


def _arm_joints(sim: Simulator) -> tuple[float, ...]:
    joints = sim.call(sim.backend.joint_positions_deg)
    assert joints is not None
    return joints


def _run(sim: Simulator) -> tuple[int, int]:
    """Each pose by a 100 % PTP; returns (moves off the master's plan, moves refused)."""
    off_plan = refused = 0
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
                refused += 1  # the master's own plan from there is refused, unsent
                assert len(sim.motion_log()) == ran
                continue
            arm = _arm_joints(sim)
            assert MASTER.forward(arm).is_close(pose, mm=1.0)
            if max(abs(a - p) for a, p in zip(arm, planned, strict=True)) > 0.5:
                off_plan += 1
    return off_plan, refused


def test_a_cartesian_ptp_ends_on_the_joints_the_master_planned(
    memory_simulator_factory: SimFactory,
) -> None:
    arm = ClosestToReference(**robot_model("tm5-700").model_dump())
    sim = memory_simulator_factory("tmflow", robot=RobotSetup(model=arm))
    assert _run(sim) == (0, 0)
    assert [r.kind for r in sim.motion_log()] == ["ptp"] * (len(POSES) + 1)
    assert all(r.done_wall_time is not None for r in sim.motion_log())


def test_without_reference_joints_the_same_controller_leaves_the_plan(
    memory_simulator_factory: SimFactory, tmp_path: Path
) -> None:
    # The program before: PTP("CPP", target, ...) without a posture. The same controller
    # takes its own choice, and the arm ends off the master's plan (or the master, from
    # where the arm went, refuses its next plan): the difference is real.
    arm = ClosestToReference(**robot_model("tm5-700").model_dump())
    program = _program(tmp_path, OLD_PTP)
    sim = memory_simulator_factory("tmflow", robot=RobotSetup(model=arm, program=program))
    off_plan, refused = _run(sim)
    assert off_plan >= 2, (off_plan, refused)


@pytest.mark.parametrize("ptp", [NEW_PTP, OLD_PTP], ids=["reference", "no_reference"])
@pytest.mark.parametrize("flip", ["wrist", "none"])
def test_from_another_configuration_the_ptp_stays_in_it(
    memory_simulator_factory: SimFactory, tmp_path: Path, flip: str, ptp: str
) -> None:
    # The arm in another configuration than the ready one (a joint move, exactly those
    # joints: "JPP"): the master plans in the configuration the robot reports; with the
    # reference joints the robot's PTP keeps to it, without them this controller leaves it.
    arm = ClosestToReference(**robot_model("tm5-700").model_dump())
    setup = RobotSetup(model=arm, program=_program(tmp_path, ptp))
    sim = memory_simulator_factory("tmflow", robot=setup)
    j1, j2, j3, j4, j5, j6 = MASTER.inverse(POSES[1])
    start = (j1, j2, j3, j4 + 180, -j5, j6 - 180) if flip == "wrist" else (j1, j2, j3, j4, j5, j6)
    start = MASTER.inverse(POSES[1], seed_deg=start)
    with Robot(sim.url, profile="tmflow", gripper=None) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_joints(start, speed=50)
        here = robot.status().joints
        assert here is not None
        planned = MASTER.inverse(POSES[0], seed_deg=here)
        assert MASTER.configuration(planned) == MASTER.configuration(start)
        robot.move_to(POSES[0], speed=100)
    done = _arm_joints(sim)
    assert MASTER.forward(done).is_close(POSES[0], mm=1.0)
    on_plan = max(abs(a - p) for a, p in zip(done, planned, strict=True)) < 0.5
    assert on_plan is (ptp == NEW_PTP)
    assert (MASTER.configuration(done) == MASTER.configuration(start)) is (ptp == NEW_PTP)
    assert [r.kind for r in sim.motion_log()] == ["ptp_joints", "ptp"]
