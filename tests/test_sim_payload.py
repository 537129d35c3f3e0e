"""What the arm carries: the gripper's own mass, and a held part pressed into the table.

The simulated 2FG7 weighs what OnRobot's datasheet says (1.1 kg) in MuJoCo's scene, and
both backends count that mass with the part against the arm's rated payload
(``tests/test_grasp_rule.py`` has the scenarios). A held part pressed into the table is
a collision in both backends and both grasp modes: the weld grasp held it whatever the
force, and the arm pressed on with hundreds of newtons and never finished its move.
"""

from __future__ import annotations

import pytest

import tmmaster
from sim_backends import BACKENDS, NEEDS_MUJOCO, until_fault
from tmmaster import Pose
from tmmaster._pose import MotionType
from tmmaster.sim import KinematicBackend, TableObject, World
from tmmaster.sim._backend import PhysicsBackend
from tmmaster.sim._payload import carried_kg
from tmmaster.sim._world import DEFAULT_GRIPPER, DEFAULT_TABLE_TOP_Z_MM

MODEL = tmmaster.robot_model("tm5-700")
PART = Pose(300, -200, DEFAULT_TABLE_TOP_Z_MM + 15, 180, 0, 90)


def make(name: str, world: World, grasp: str) -> PhysicsBackend:
    if name == "kinematic":
        return KinematicBackend(MODEL, world=world, home=PART, grasp=grasp)  # type: ignore[arg-type]
    from tmmaster.sim._mujoco import MuJoCoBackend

    return MuJoCoBackend(MODEL, world=world, home=PART, grasp=grasp)  # type: ignore[arg-type]


def test_the_2fg7_weighs_what_onrobot_says_and_counts_with_the_part() -> None:
    assert DEFAULT_GRIPPER.mass_kg == pytest.approx(1.1)
    part = TableObject(name="p", pose=PART, mass_kg=4.9)
    assert carried_kg(part, DEFAULT_GRIPPER) == pytest.approx(6.0)
    assert carried_kg(None, DEFAULT_GRIPPER) == pytest.approx(1.1)


@NEEDS_MUJOCO
def test_the_simulated_2fg7_has_the_real_ones_mass() -> None:
    from tmmaster.sim._mujoco import MuJoCoBackend

    b = MuJoCoBackend(MODEL, world=World(), dynamics=True)
    model = b.mj_model
    # The palm and the fingers under the TCP body: the gripper (it weighed 0.25 kg).
    assert model.body_subtreemass[model.body("tcp").id] == pytest.approx(1.1, abs=1e-6)


@pytest.mark.parametrize("grasp", ["friction", "weld"])
@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_held_part_pressed_into_the_table_is_a_collision(backend_name: str, grasp: str) -> None:
    b = make(backend_name, World([TableObject(name="p", pose=PART, mass_kg=0.5)]), grasp)
    b.drive_gripper(0, speed_mm_s=100, force_n=40)
    assert until_fault(b, lambda: not b.gripper_state().moving) is None
    b.start_motion(PART.offset(dz=30), motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1)
    assert until_fault(b, b.is_settled) is None
    assert b.objects()[0].held
    # Down 30 mm past where the part rests on the table.
    b.start_motion(PART.offset(dz=-30), motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1)
    fault = until_fault(b, b.is_settled, limit_s=3.0)
    assert fault is not None
    assert fault.kind == "collision"
    # Stopped at the table, within the few millimetres a friction grip slips first.
    assert b.tcp_pose().z == pytest.approx(PART.z, abs=4.0)
