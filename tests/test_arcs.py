"""Circular arcs and joint targets in the arm model (RobotModel, the Arc geometry)."""

from __future__ import annotations

import math

import pytest

import tmmaster
from tmmaster import Pose, robot_model
from tmmaster._kinematics import Arc, transform_to_pose
from tmmaster._robot_models import arc_through

START = Pose(300, -200, 200, 180, 0, 90)
VIA = Pose(350, -150, 200, 180, 0, 90)
END = Pose(400, -200, 200, 180, 0, 90)


def test_an_arc_passes_its_three_points_on_one_circle() -> None:
    arc = Arc.through(START, VIA, END)
    assert arc.radius_mm == pytest.approx(50.0)
    assert arc.sweep_rad == pytest.approx(math.pi)
    for k in range(21):
        p = transform_to_pose(arc.at(k / 20))
        assert math.dist((p.x, p.y, p.z), arc.centre) == pytest.approx(50.0)
    assert transform_to_pose(arc.at(arc.via_fraction)).distance_to(VIA) < 1e-6
    assert transform_to_pose(arc.at(0)).is_close(START, mm=1e-6, deg=1e-6)
    assert transform_to_pose(arc.at(1)).is_close(END, mm=1e-6, deg=1e-6)


def test_an_arc_runs_through_its_via_even_the_long_way_round() -> None:
    # The via just past the end, seen from the start: the arc goes round the far side.
    arc = Arc.through(
        Pose(0, 0, 100, 180, 0, 0), Pose(110, 0, 110, 180, 0, 0), Pose(100, 0, 100, 180, 0, 90)
    )
    assert arc.sweep_rad > math.pi
    assert 0.9 < arc.via_fraction < 1.0
    # The orientation turns uniformly from the start's to the end's.
    assert transform_to_pose(arc.at(0.5)).rz == pytest.approx(45.0)


@pytest.mark.parametrize(
    ("via", "end", "message"),
    [
        (Pose(350, -200, 200, 180, 0, 90), END, "one line"),
        (START.offset(dz=0.5), END, "apart"),
        (VIA, START, "apart"),
    ],
)
def test_no_arc_through_points_on_a_line_or_too_close(via: Pose, end: Pose, message: str) -> None:
    with pytest.raises(tmmaster.ConfigError, match=message):
        arc_through(START, via, end)


def test_the_arcs_joint_samples_put_the_tcp_on_the_arc() -> None:
    model = robot_model("tm5-700")
    tool = Pose(0, 0, 100, 0, 0, 0)
    start_joints = model.inverse(START, tool=tool)
    samples = model.arc_joints(START, VIA, END, start_joints_deg=start_joints, tool=tool)
    arc = Arc.through(START, VIA, END)
    for k, joints in enumerate(samples):
        expected = transform_to_pose(arc.at(k / (len(samples) - 1)))
        assert model.forward(joints, tool).is_close(expected, mm=0.01, deg=0.01)
    slow = model.arc_time(START, VIA, END, speed_percent=10, tool=tool, samples=samples)
    fast = model.arc_time(START, VIA, END, speed_percent=100, tool=tool, samples=samples)
    assert slow > fast > arc.length_mm / model.tcp_speed_mm_s


@pytest.mark.parametrize(
    ("joints", "reason"),
    [
        ((300, 0, 90, 0, 90, 0), "joint_limit"),
        ((0, 0, 0, 0, 90, 0), "singularity"),  # arm stretched
        ((0, 0, 90, 0, 2, 0), "singularity"),  # wrist
    ],
)
def test_joints_past_a_range_or_at_a_singularity_are_refused(
    joints: tuple[float, ...], reason: str
) -> None:
    with pytest.raises(tmmaster.UnreachablePoseError) as info:
        robot_model("tm5-700").check_joints(joints)
    assert info.value.reason == reason
    assert info.value.pose is not None
