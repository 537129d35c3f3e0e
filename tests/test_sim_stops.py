"""Stops take time: the simulated arm brakes along its path to rest, in both backends.

A TM5-700 told to stop decelerates over about 0.34-0.68 s and 9-31 deg of joint travel
(Techman's Safety Manual, as quoted in the project's reference notes); the simulator's
model (``tmmaster.sim._stopping``) stops a joint at its top speed in 0.34 s over
30.6 deg. With arm dynamics (MuJoCo) the servo then holds where the braking ended, a
payload included, and no joint turns faster than its top speed.
"""

from __future__ import annotations

import math

import pytest

import tmmaster
from sim_backends import BACKENDS, NEEDS_MUJOCO, STEP_S, until_fault
from tmmaster import Pose
from tmmaster._pose import MotionType
from tmmaster.sim import Fixture, KinematicBackend, TableObject, World
from tmmaster.sim._backend import PhysicsBackend
from tmmaster.sim._stopping import STOP_TIME_AT_TOP_SPEED_S
from tmmaster.sim._world import DEFAULT_TABLE_TOP_Z_MM

MODEL = tmmaster.robot_model("tm5-700")
#: A fine step, to time the stop (s).
FINE_S = 0.002


def make(name: str, **options: object) -> PhysicsBackend:
    if name == "kinematic":
        return KinematicBackend(MODEL, **options)  # type: ignore[arg-type]
    from tmmaster.sim._mujoco import MuJoCoBackend

    return MuJoCoBackend(MODEL, **options)  # type: ignore[arg-type]


def stop_midway(b: PhysicsBackend, speed_percent: float) -> tuple[float, float, float]:
    """Swing J1 by 170 deg, stop halfway: (stop time s, J1's peak and final travel deg)."""
    start = b.joint_positions_deg()
    assert start is not None
    target = [start[0] + 170, *start[1:]]
    duration = b.start_joint_motion(target, speed_percent=speed_percent, accel_time_s=0.2)  # type: ignore[attr-defined]
    elapsed = 0.0
    while elapsed < duration / 2:
        b.step(FINE_S)
        elapsed += FINE_S
    at_stop = b.joint_positions_deg()
    assert at_stop is not None
    b.stop_motion()
    stopping, peak, moving_until = 0.0, 0.0, 0.0
    last = at_stop[0]
    while not b.is_settled():
        assert stopping < 2.0, "not at rest 2 s after the stop"
        b.step(FINE_S)
        stopping += FINE_S
        joints = b.joint_positions_deg()
        assert joints is not None
        peak = max(peak, joints[0] - at_stop[0])
        if abs(joints[0] - last) / FINE_S > 1.0:  # J1 turns faster than 1 deg/s
            moving_until = stopping
        last = joints[0]
    final = b.joint_positions_deg()
    assert final is not None
    return moving_until, peak, final[0] - at_stop[0]


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_stop_at_top_speed_brakes_over_the_tm5s_time_and_distance(backend_name: str) -> None:
    b = make(backend_name)
    moving_s, peak, final = stop_midway(b, 100)
    # J1 at 180 deg/s: 0.34 s and 30.6 deg, within the TM5-700's 0.34-0.68 s / 9-31 deg.
    assert moving_s == pytest.approx(STOP_TIME_AT_TOP_SPEED_S, abs=0.02)
    assert 0.3 <= moving_s <= 0.7
    assert final == pytest.approx(30.6, abs=0.3)
    assert 9 <= final <= 31
    # It comes to rest where it braked to: no spring back.
    assert final == pytest.approx(peak, abs=0.05)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_slower_move_stops_sooner_and_shorter(backend_name: str) -> None:
    moving_s, _, final = stop_midway(make(backend_name), 50)
    # Half the speed: half the time, a quarter of the distance.
    assert moving_s == pytest.approx(STOP_TIME_AT_TOP_SPEED_S / 2, abs=0.02)
    assert final == pytest.approx(30.6 / 4, abs=0.3)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_stopped_line_brakes_on_its_line(backend_name: str) -> None:
    start = Pose(300, -200, 300, 180, 0, 90)
    target = Pose(300, 200, 300, 180, 0, 90)
    b = make(backend_name, home=start)
    duration = b.start_motion(target, motion=MotionType.LINE, speed_percent=100, accel_time_s=0.2)
    for _ in range(round(duration / 2 / STEP_S)):
        b.step(STEP_S)
    at_stop = b.tcp_pose()
    b.stop_motion()
    b.step(STEP_S)
    assert not b.is_settled()  # still moving: the master sees it busy
    until_fault(b, b.is_settled, limit_s=1.0)
    rest = b.tcp_pose()
    assert rest.y - at_stop.y > 20  # braked on, in the motion's direction
    assert rest.y < target.y - 20  # and stopped short of the target
    assert rest.is_close(Pose(300, rest.y, 300, 180, 0, 90), mm=0.5, deg=0.1)


def grasp_and_lift(mass_kg: float) -> PhysicsBackend:
    """A MuJoCo arm (dynamics) holding a part of ``mass_kg`` (weld grasp), lifted 100 mm."""
    part = Pose(300, -200, DEFAULT_TABLE_TOP_Z_MM + 15, 180, 0, 90)
    above = part.offset(dz=60)
    world = World([TableObject(name="part", pose=part, mass_kg=mass_kg)])
    b = make("mujoco", world=world, home=above, grasp="weld")
    b.start_motion(part, motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1)
    assert until_fault(b, b.is_settled) is None
    b.drive_gripper(0, speed_mm_s=100, force_n=140)
    assert until_fault(b, lambda: not b.gripper_state().moving) is None
    return b


@NEEDS_MUJOCO
def test_a_stop_with_a_payload_does_not_sag() -> None:
    # 4.5 kg with the 1.1 kg gripper: within the TM5-700's 6 kg. A stop (the Stop
    # command, an e-stop, a robot error) during a fast Line at a constant height.
    b = grasp_and_lift(4.5)
    lifted = Pose(300, -200, 250, 180, 0, 90)
    b.start_motion(lifted, motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1)
    assert until_fault(b, b.is_settled) is None
    duration = b.start_motion(
        lifted.offset(dy=400), motion=MotionType.LINE, speed_percent=100, accel_time_s=0.2
    )
    for _ in range(round(duration / 2 / STEP_S)):
        b.step(STEP_S)
    b.stop_motion()
    lowest = b.tcp_pose().z
    for _ in range(round(1.0 / FINE_S)):
        b.step(FINE_S)
        lowest = min(lowest, b.tcp_pose().z)
    assert b.is_settled()
    assert b.objects()[0].held
    # The servo keeps the payload's torque through the stop: under 1 mm below the path
    # (it sagged 2.5 mm when the stop reset the servo's reference to the lagging joints).
    assert lifted.z - lowest < 1.0
    assert b.tcp_pose().z == pytest.approx(lifted.z, abs=0.1)


@NEEDS_MUJOCO
def test_joints_never_turn_faster_than_their_top_speed_with_a_payload() -> None:
    b = grasp_and_lift(4.5)
    b.start_motion(
        Pose(300, -200, 250, 180, 0, 90), motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1
    )
    assert until_fault(b, b.is_settled) is None
    start = b.joint_positions_deg()
    target = [start[0] + 150, start[1] + 20, *start[2:5], start[5] + 150]
    b.start_joint_motion(target, speed_percent=100, accel_time_s=0.2)  # type: ignore[attr-defined]
    top = MODEL.joint_speed_deg_s
    worst = 0.0
    while not b.is_settled():
        b.step(FINE_S)
        data = b.mj_data  # type: ignore[attr-defined]
        speeds = [abs(math.degrees(data.joint(f"j{i}").qvel[0])) for i in range(1, 7)]
        worst = max(worst, *(w / t for w, t in zip(speeds, top, strict=True)))
    assert b.objects()[0].held
    assert 0.95 < worst <= 1.0 + 1e-9


@NEEDS_MUJOCO
def test_the_arm_holds_a_payload_after_a_collision_without_sagging() -> None:
    # A 4.5 kg part carried at 400 mm; the forearm meets a post on the way.
    part = Pose(300, -200, DEFAULT_TABLE_TOP_Z_MM + 15, 180, 0, 90)
    post = Fixture(name="post", pose=Pose(300, 0, 400, 0, 0, 0), size_mm=(40, 40, 200))
    world = World([TableObject(name="part", pose=part, mass_kg=4.5)], fixtures=[post])
    b = make("mujoco", world=world, home=part, grasp="weld")
    b.drive_gripper(0, speed_mm_s=100, force_n=140)
    assert until_fault(b, lambda: not b.gripper_state().moving) is None
    lifted = Pose(300, -200, 400, 180, 0, 90)
    b.start_motion(lifted, motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1)
    assert until_fault(b, b.is_settled) is None
    b.start_motion(
        lifted.offset(dy=400), motion=MotionType.LINE, speed_percent=50, accel_time_s=0.1
    )
    fault = until_fault(b, lambda: False)
    assert fault is not None
    assert fault.kind == "collision"
    at_fault = b.tcp_pose().z
    lowest = at_fault
    for _ in range(round(1.0 / STEP_S)):
        b.step(STEP_S)
        lowest = min(lowest, b.tcp_pose().z)
    assert b.objects()[0].held
    # The servo keeps the payload's torque (it sagged 5.3 mm when a fault reset it).
    assert at_fault - lowest < 0.5
