"""Techman's Joint Speed (7949-7960) and TCP Speed (7859-7872) in the simulated table.

A master that needs to know the arm is at rest on ``tmflow`` cannot take it from the
robot program's state (``status().moving`` leaves busy as soon as the project stops,
while the arm still brakes): the arm's own speeds can tell it. The simulator publishes
them from what its arm did, for every backend with a joint model: how far the joints and
the TCP moved since the last tick, per simulated second. So they are non-zero while the
arm moves and while it brakes after a stop, and 0 only once it held still a whole tick.

Found by hunt 18's follow-up (fails without it): both sections read 0 during a move.
The judge is the simulated arm (its joints and TCP tick by tick), not the registers.
"""

from __future__ import annotations

import math

import pytest

from sim_backends import BACKENDS
from tmmaster import Pose
from tmmaster._profiles import robot_profile
from tmmaster._robot_models import robot_model
from tmmaster.sim import _simulator
from tmmaster.sim._backend import PathBackend, PhysicsBackend
from tmmaster.sim._bank import RegisterBank
from tmmaster.sim._controller import RobotController, motion_speeds
from tmmaster.sim._kinematic import KinematicBackend
from tmmaster.sim._world import World

MODEL = robot_model("tm5-700")
TICK_S = 0.02
JOINT_SPEEDS = tuple(f"joint_speed_{j}" for j in range(1, 7))
TCP_SPEEDS = tuple(f"tcp_speed_{a}" for a in ("x", "y", "z", "rx", "ry", "rz", "s3d"))


def _backend(name: str) -> PhysicsBackend:
    if name == "kinematic":
        return KinematicBackend(MODEL, world=World(()))
    from tmmaster.sim._mujoco import MuJoCoBackend

    return MuJoCoBackend(MODEL, world=World(()))


def _robot(backend: PhysicsBackend) -> tuple[RobotController, RegisterBank]:
    """A tmflow robot running the generated program, as the Simulator builds it."""
    profile = robot_profile("tmflow")
    cls, options = _simulator._script_project(profile, "generated", None)
    bank = cls.bank_for(profile)
    return cls(profile, bank, backend, MODEL, **options), bank


def _arm(backend: PhysicsBackend) -> tuple[tuple[float, ...], Pose]:
    joints = backend.joint_positions_deg()
    assert joints is not None
    return tuple(joints), backend.tcp_pose()


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_the_speeds_follow_the_arm_through_a_move_its_brake_and_its_rest(
    backend_name: str,
) -> None:
    backend = _backend(backend_name)
    controller, bank = _robot(backend)
    swing = list(_arm(backend)[0])
    swing[0] += 90.0  # J1 reaches its top speed, 180 deg/s, after 0.2 s
    seen = {"moving": 0, "braking": 0, "still": 0}
    for tick in range(110):
        if tick == 15:
            assert isinstance(backend, PathBackend)
            backend.start_joint_motion(swing, speed_percent=100, accel_time_s=0.2)
        if tick == 27:
            backend.stop_motion()  # near top speed: a Stop's brake takes ~0.34 s
        before = _arm(backend)
        controller.tick(TICK_S)
        after = _arm(backend)
        joints = [bank.get(n) for n in JOINT_SPEEDS]
        tcp = [bank.get(n) for n in TCP_SPEEDS]
        if before == after:  # the arm held still over this tick
            assert joints + tcp == [0.0] * 13, f"tick {tick}: the arm held still"
            seen["still"] += 1
            continue
        # The arm moved over this tick: the registers say how fast (as float32).
        expected = motion_speeds(before[1], after[1], before[0], after[0], TICK_S)
        assert joints + tcp == pytest.approx(expected, rel=1e-4, abs=1e-6), f"tick {tick}"
        if 15 <= tick < 27:
            seen["moving"] += 1
            assert joints[0] > 0.0
        elif tick >= 27 and abs(after[0][0] - before[0][0]) > 1e-3:
            seen["braking"] += 1
            assert joints[0] != 0.0, f"tick {tick}: J1 still turns"
    assert seen["moving"] == 12
    assert seen["braking"] >= 15, seen  # the arm brakes over ~0.34 s: 17 ticks
    # At rest at the end: the kinematic arm exactly, MuJoCo's within its settling noise.
    assert max(abs(bank.get(n)) for n in (*JOINT_SPEEDS, *TCP_SPEEDS)) < 1e-6
    if backend_name == "kinematic":
        assert seen["still"] > 50


def test_the_tcp_speed_turns_an_angle_the_short_way_round() -> None:
    a = Pose(0, 0, 0, 179.0, 0, -179.0)
    b = Pose(3, 4, 0, -179.0, 0, 179.0)
    speeds = motion_speeds(a, b, (0.0,) * 6, (1.0, -2.0, 0, 0, 0, 0), 0.5)
    assert speeds[:6] == pytest.approx((2.0, -4.0, 0, 0, 0, 0))
    assert speeds[6:] == pytest.approx((6.0, 8.0, 0.0, 4.0, 0.0, -4.0, 10.0))
    assert math.isclose(speeds[-1], math.hypot(6.0, 8.0))
