"""The arm model: Techman's joint chain, forward and inverse kinematics, limits, timing."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tmmaster
from tmmaster import JointSpec, MotionType, Pose, UnreachablePoseError, robot_model
from tmmaster import _kinematics as kin
from tmmaster._robot_models import joint_chain
from tmmaster.pickplace import ARTICLE_HOME

TM5 = robot_model("tm5-700")


def close(a: Pose, b: Pose, mm: float = 1e-3, deg: float = 1e-3) -> bool:
    """Both poses name the same transform (Euler angles may differ at gimbal lock)."""
    ta, tb = kin.pose_to_transform(a), kin.pose_to_transform(b)
    rotation = math.degrees(math.hypot(*kin.rotation_error(ta, tb)))
    return a.distance_to(b) <= mm and rotation <= deg


def test_zero_joints_put_the_flange_where_techmans_description_does() -> None:
    # tm5-700-nominal.urdf at tmr_ros2 684faab: z = 145.2 + 329 + 311.5 + 106,
    # y = -(122.3 + 113.15); the flange's z axis points along -y (rx = 90).
    assert close(TM5.forward([0] * 6), Pose(0, -235.45, 891.7, 90, 0, 0))


def test_the_pre_2022_nominal_numbers_give_the_issues_figure() -> None:
    # The same file before tmr_ros2 commit 33de3ba ("modify TM5-900, TM5-700 series
    # nominal DH parameters") had 145.1, 122.2 and 114.4 mm: (0, -236.6, 891.6).
    joints = list(TM5.joints)
    joints[0] = joints[0].model_copy(update={"origin_xyz_mm": (0, 0, 145.1)})
    joints[3] = joints[3].model_copy(update={"origin_xyz_mm": (311.5, 0, -122.2)})
    joints[5] = joints[5].model_copy(update={"origin_xyz_mm": (0, -114.4, 0)})
    old = TM5.model_copy(update={"joints": tuple(joints)})
    assert close(old.forward([0] * 6), Pose(0, -236.6, 891.6, 90, 0, 0))


def test_every_builtin_model_is_loaded_from_data() -> None:
    assert sorted(tmmaster.ROBOT_MODELS) == ["tm12", "tm14", "tm5-700", "tm5-900"]
    assert robot_model("tm5-900").joints[2].origin_xyz_mm == (429, 0, 0)
    assert robot_model("tm12").joint_speed_deg_s[:2] == (120, 120)
    assert robot_model("tm5-700").joints[2].limits_deg == (-155, 155)


def test_tm_euler_angles_are_fixed_axis_x_then_y_then_z() -> None:
    # R = Rz(rz) Ry(ry) Rx(rx): rx = 90 alone turns the y axis onto z.
    t = kin.pose_to_transform(Pose(0, 0, 0, 90, 0, 0))
    assert [round(t[i][1], 9) for i in range(3)] == [0, 0, 1]
    # rx then rz (fixed axes): x axis stays x under Rx, then Rz(90) turns it to y.
    t = kin.pose_to_transform(Pose(0, 0, 0, 90, 0, 90))
    assert [round(t[i][0], 9) for i in range(3)] == [0, 1, 0]
    assert [round(t[i][1], 9) for i in range(3)] == [0, 0, 1]


angles = st.floats(-179, 179, allow_nan=False)


@given(
    st.floats(-500, 500),
    st.floats(-500, 500),
    st.floats(-500, 500),
    angles,
    st.floats(-89, 89),
    angles,
)
def test_pose_transform_round_trip(
    x: float, y: float, z: float, rx: float, ry: float, rz: float
) -> None:
    pose = Pose(x, y, z, rx, ry, rz)
    assert close(kin.transform_to_pose(kin.pose_to_transform(pose)), pose, 1e-6, 1e-6)


def joints_strategy() -> st.SearchStrategy[tuple[float, ...]]:
    # Inside the ranges and away from the singularities the model refuses.
    return st.tuples(
        st.floats(-170, 170),
        st.floats(-80, 80),
        st.floats(20, 150) | st.floats(-150, -20),
        st.floats(-170, 170),
        st.floats(20, 160) | st.floats(-160, -20),
        st.floats(-170, 170),
    )


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(joints_strategy(), st.lists(st.floats(-3, 3), min_size=6, max_size=6))
def test_inverse_kinematics_round_trips_from_a_nearby_seed(
    joints: tuple[float, ...], nudge: list[float]
) -> None:
    pose = TM5.forward(joints)
    if TM5.singularity(joints) is not None or TM5.distance_from_shoulder(pose) > TM5.reach_mm:
        return
    seed = [q + d for q, d in zip(joints, nudge, strict=True)]
    if TM5.configuration(seed) != TM5.configuration(joints):
        return  # the nudge crossed into another configuration: the seed's is preferred
    solution = TM5.inverse(pose, seed_deg=seed)
    # The nearest solution is the one the seed came from (to IK's 1 um / 1 urad tolerance).
    assert max(abs(a - b) for a, b in zip(solution, joints, strict=True)) < 1e-2
    assert close(TM5.forward(solution), pose)


@settings(max_examples=25, deadline=None)
@given(joints_strategy())
def test_inverse_kinematics_finds_a_pose_from_the_ready_posture(joints: tuple[float, ...]) -> None:
    pose = TM5.forward(joints)
    if TM5.singularity(joints) is not None or TM5.distance_from_shoulder(pose) > TM5.reach_mm:
        return  # outside what the model promises (the datasheet reach is conservative)
    refused: UnreachablePoseError | None = None
    try:
        solution = TM5.inverse(pose)
    except UnreachablePoseError as exc:
        refused = exc
    if refused is not None:
        # The pose has a regular solution (``joints``); from the ready posture a branch
        # past a limit may be found first, but the pose is never "out of reach".
        assert refused.reason != "reach"
    else:
        assert close(TM5.forward(solution), pose)


def test_the_articles_home_is_out_of_reach() -> None:
    home = Pose.from_sequence(ARTICLE_HOME)
    with pytest.raises(UnreachablePoseError) as caught:
        TM5.inverse(home)
    assert caught.value.reason == "reach"
    assert "reach" in str(caught.value)
    assert isinstance(caught.value, tmmaster.ConfigError)
    assert not TM5.can_reach(home)


def test_default_home_and_article_poses_are_reachable() -> None:
    for values in ((300, -200, 100, 180, 0, 90), (300, 200, 200, 180, 0, 90)):
        assert TM5.can_reach(Pose(*values))
    assert TM5.can_reach(tmmaster.DEFAULT_HOME)


def test_a_joint_limit_is_named() -> None:
    joints = list(TM5.joints)
    joints[0] = JointSpec(
        origin_xyz_mm=(0, 0, 145.2), origin_rpy_deg=(0, 0, 0), limits_deg=(-10, 10), speed_deg_s=180
    )
    narrow = TM5.model_copy(update={"joints": tuple(joints)})
    with pytest.raises(UnreachablePoseError) as caught:
        narrow.inverse(Pose(0, 400, 200, 180, 0, 90))
    assert caught.value.reason == "joint_limit"
    assert "J1" in str(caught.value)


def test_a_line_that_takes_j6_past_its_range_says_joint_limit() -> None:
    # Tool down from rz 0 (J6 114 deg) to rz -170: the shorter turn drives J6 up past
    # +270 deg, where the only solution in range is a whole turn away.
    start = Pose(300, 0, 250, 180, 0, 0)
    with pytest.raises(UnreachablePoseError) as caught:
        TM5.line_joints(start, Pose(300, 0, 200, 180, 0, -170), start_joints_deg=TM5.inverse(start))
    assert caught.value.reason == "joint_limit"
    assert "past its range" in str(caught.value)


def test_a_stretched_arm_is_refused_as_an_elbow_singularity() -> None:
    # J3 = 0: the arm is straight (on every branch of these poses).
    for joints in ([0, 0, 0, 90, 90, 0], [0, 30, 0, 60, 90, 0]):
        pose = TM5.forward(joints)
        with pytest.raises(UnreachablePoseError) as caught:
            TM5.inverse(pose, seed_deg=joints)
        assert caught.value.reason == "singularity"
        assert "elbow" in str(caught.value)


def test_a_wrist_singular_branch_is_left_for_a_regular_one() -> None:
    singular = [0.0, 0.0, 90.0, 0.0, 0.0, 0.0]  # J5 = 0: J4 and J6 aligned
    assert "wrist" in (TM5.singularity(singular) or "")
    pose = TM5.forward(singular)
    solution = TM5.inverse(pose, seed_deg=singular)
    assert TM5.singularity(solution) is None
    assert close(TM5.forward(solution), pose)


@settings(max_examples=30, deadline=None)
@given(joints_strategy())
def test_the_shoulder_distance_is_the_jacobian_factor(joints: tuple[float, ...]) -> None:
    # det(J) / (a2 a3 sin J3 sin J5) is the wrist centre's distance from the plane of the
    # J1 axis and the J2 axis: with the 122.3 mm shoulder offset, Pythagoras with the
    # wrist centre's horizontal distance from the J1 axis.
    wrist = TM5.joint_frames(joints)[4]
    radius = math.hypot(wrist[0][3], wrist[1][3])
    distance = TM5.shoulder_distance_mm(joints)
    assert math.hypot(distance, 122.3) == pytest.approx(radius, abs=1e-6)


def test_a_tool_offset_moves_the_tcp_in_the_flange_frame() -> None:
    tool = Pose(0, 0, 150, 0, 0, 0)  # 150 mm along the flange's z axis
    joints = (0.0, 0.0, 90.0, 0.0, 90.0, 0.0)
    flange = TM5.forward(joints)
    tcp = TM5.forward(joints, tool=tool)
    # Tool pointing down: the TCP is 150 mm below the flange.
    assert tcp.z == pytest.approx(flange.z - 150)
    solution = TM5.inverse(tcp, seed_deg=joints, tool=tool)
    assert max(abs(a - b) for a, b in zip(solution, joints, strict=True)) < 1e-3


def test_ptp_moves_in_joint_space_and_its_tcp_path_curves() -> None:
    lift, place = Pose(300, -200, 250, 180, 0, 90), Pose(300, 200, 200, 180, 0, 90)
    start = TM5.inverse(lift)
    end = TM5.inverse(place, seed_deg=start)
    middle = TM5.forward([(a + b) / 2 for a, b in zip(start, end, strict=True)])
    straight = Pose(300, 0, 225, 180, 0, 90)
    assert middle.distance_to(straight) > 20  # the TCP swings out, away from the line
    assert middle.x > 327.67  # beyond what the article map's int16 x100 can hold
    expected = TM5.ptp_time(start, end, speed_percent=30)
    assert TM5.motion_time(lift, place, speed_percent=30, motion=MotionType.PTP) == expected
    # Synchronised trapezoid: the slowest joint sets the time.
    slowest = max(
        tmmaster._robot_models.trapezoid_time(abs(b - a), spec.speed_deg_s * 0.3, TM5.accel_time_s)
        for a, b, spec in zip(start, end, TM5.joints, strict=True)
    )
    assert expected == slowest


def test_line_time_is_never_shorter_than_the_cartesian_trapezoid() -> None:
    a, b = Pose(300, -200, 200, 180, 0, 90), Pose(300, -200, 100, 180, 0, 90)
    line = TM5.motion_time(a, b, speed_percent=10, motion=MotionType.LINE)
    cartesian = tmmaster._robot_models.trapezoid_time(100, TM5.tcp_speed_mm_s * 0.1, 0.2)
    assert line >= cartesian
    samples = TM5.line_joints(a, b)
    for joints in samples:
        pose = TM5.forward(joints)
        assert abs(pose.x - 300) < 1e-3  # a straight line
        assert abs(pose.y + 200) < 1e-3


def test_a_line_through_an_unreachable_region_is_refused() -> None:
    a, b = Pose(300, -200, 200, 180, 0, 90), Pose(-300, 200, 200, 180, 0, 90)
    with pytest.raises(UnreachablePoseError):
        TM5.line_joints(a, b)  # passes the J1 axis, where no tool-down pose exists


@pytest.mark.parametrize("name", ["tm5-700", "tm5-900", "tm12", "tm14"])
def test_joint_origins_are_the_frames_positions(name: str) -> None:
    # The simulator's link check uses the matrix-free path; it must place every joint
    # where the frames the master plans with do.
    chain = joint_chain(robot_model(name))
    rng = random.Random(7)
    for _ in range(200):
        q = [rng.uniform(-math.pi, math.pi) for _ in range(6)]
        frames = chain.frames(q)
        origins = chain.joint_origins(q)
        assert len(origins) == len(frames)
        for frame, point in zip(frames, origins, strict=True):
            assert point == pytest.approx([frame[i][3] for i in range(3)], abs=1e-9)
