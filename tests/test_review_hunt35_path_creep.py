"""Review of hunt 35: a seed past a range's end no longer stretches the range.

Hunt 35 (tests/test_hunt35_joint_edges.py) let ``_admissible`` stretch a joint's range to
any seed past its end and the seed's rounding (0.001 deg), so that a calibrated arm's
start, solved on the nominal chain a hair past the end, is planned where the arm is.
Two effects reached beyond that start:

- a path seeds each sample with the one before, so each sample could go 0.001 deg
  further past the end than the last: a Line turning J1 0.02 deg on past the end over
  50 samples passed the master's check, from a start inside the range (nominal arm) or
  past it (calibrated); the master sent it and the simulated arm, whose model stretched
  the same way, ran it past its range (a real TM5 refuses it, 0x0012);
- ``RobotModel.inverse`` (public) answered a seed past the end with joints past the end.

Now only the start (``start_joints``) and the path after it are solved on ranges
stretched to that start, once per path; ``inverse`` keeps every range as it is.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from test_hunt35_joint_edges import NOMINAL, placed, sim_joints, turned_about_z, zero_offset
from tmmaster import Pose, Robot, UnreachablePoseError
from tmmaster.sim import Simulator

#: J1 0.0005 deg inside its end (+270 deg).
INSIDE_J1_END = (269.9995, 0.0, 90.0, 0.0, 90.0, 0.0)
#: J1 inside its end on an arm whose J1 zero is 0.08 deg off: 270.06 deg on this chain.
CALIBRATED_AT_J1_END = (269.98, 0.0, 90.0, 0.0, 90.0, 0.0)


def down_and_turned(pose: Pose, deg: float) -> Pose:
    """250 mm straight down (J1 stays), turned ``deg`` about the base's z (J1 turns)."""
    turned = turned_about_z(pose, deg)
    return Pose(turned.x, turned.y, turned.z - 250.0, turned.rx, turned.ry, turned.rz)


@pytest.mark.parametrize(
    ("arm_offset_deg", "reported"),
    [(0.0, INSIDE_J1_END), (0.08, CALIBRATED_AT_J1_END)],
    ids=["from-inside", "calibrated-from-past"],
)
def test_a_line_turning_j1_slowly_on_past_its_end_is_refused(
    arm_offset_deg: float, reported: tuple[float, ...]
) -> None:
    """(An arc takes the same path check, ``RobotModel._path``: one that turns J1 this
    slowly out of the arm's plane was not found in the time, so it is not tested.)"""
    start = zero_offset(arm_offset_deg).forward(reported)  # the TCP the arm reports
    target = down_and_turned(start, 0.02)  # J1 0.02 deg further, over 50 samples
    with pytest.raises(UnreachablePoseError) as refused:
        NOMINAL.line_joints(start, target, start_joints_deg=reported)
    assert refused.value.reason == "joint_limit"


@pytest.mark.parametrize(
    ("arm_offset_deg", "reported"),
    [(0.0, INSIDE_J1_END), (0.08, CALIBRATED_AT_J1_END)],
    ids=["from-inside", "calibrated-from-past"],
)
def test_a_path_whose_j1_stays_or_turns_back_still_passes(
    arm_offset_deg: float, reported: tuple[float, ...]
) -> None:
    """The fix holds the seeds, not the samples: J1 unchanged, or back into the range."""
    start = zero_offset(arm_offset_deg).forward(reported)
    first = NOMINAL.start_joints(start, reported)
    for deg in (0.0, -0.5):
        samples = NOMINAL.line_joints(start, down_and_turned(start, deg), start_joints_deg=reported)
        assert max(q[0] for q in samples) <= max(270.0, first[0]) + 1e-3
        assert samples[-1][0] == pytest.approx(first[0] + deg, abs=0.01)


@pytest.mark.parametrize(
    ("arm_offset_deg", "reported"),
    [(0.0, INSIDE_J1_END), (0.08, CALIBRATED_AT_J1_END)],
    ids=["from-inside", "calibrated-from-past"],
)
def test_the_arm_never_runs_such_a_line_past_its_range(
    tm_simulator_factory: Callable[..., Simulator],
    arm_offset_deg: float,
    reported: tuple[float, ...],
) -> None:
    """Judged on the simulated arm (whose model stretched its range the same way and ran
    the Line, J1 ending 0.02 deg past its end): refused unsent, the arm where it was."""
    sim = placed(tm_simulator_factory, zero_offset(arm_offset_deg), reported)
    with Robot(sim.url, gripper=None) as robot:
        before = len(sim.motion_log())
        with pytest.raises(UnreachablePoseError):
            robot.move_to(down_and_turned(sim.tcp_pose(), 0.02), speed=50, motion="line")
        assert len(sim.motion_log()) == before  # nothing was sent
    assert sim.field("last_error_code") == 0
    assert sim_joints(sim) == pytest.approx(reported, abs=1e-3)


def test_inverse_from_a_seed_past_a_range_end_answers_inside_the_range() -> None:
    """``RobotModel.inverse`` (public; ``Robot.validate_move``'s ``seed_deg``, the
    simulated TMscript's ``inversekin`` reference joints) promises joints inside every
    range or a refusal "past a joint limit". Hunt 35 let any seed past an end stretch the
    range to it: a seed at J1 = 300 deg (outside +-270) was answered J1 = 299 deg, past
    the end, where the arm takes the pose at -61 deg."""
    pose = NOMINAL.forward((299.0, 0.0, 90.0, 0.0, 90.0, 0.0))
    joints = NOMINAL.inverse(pose, seed_deg=(300.0, 0.0, 90.0, 0.0, 90.0, 0.0))
    assert joints[0] == pytest.approx(-61.0, abs=1e-3)
