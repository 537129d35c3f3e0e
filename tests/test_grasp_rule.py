"""One grasp rule, two backends: the same scenarios grip, miss, jam, slip or collide alike.

Each scenario puts one part on the table, brings the open fingers down onto it along a
Line, closes them with a grip force, lifts 60 mm and says what happened. The kinematic
backend decides by the rule (``tmmaster.sim._world.grasp_fit``, the friction rule of
``GripperGeometry``); the MuJoCo backend by contacts and friction in a scene built from
the same pads, stroke and friction. The MuJoCo runs are skipped without the extra.

The part lies with its y axis along the closing direction: at the TCP's rz = 90 that is
the base x axis, so ``across`` offsets move the part along base x, ``depth`` along base y.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import pytest

import tmmaster
from sim_backends import BACKENDS, until_fault
from tmmaster import Pose
from tmmaster._pose import MotionType
from tmmaster.sim import KinematicBackend, TableObject, World
from tmmaster.sim._backend import PhysicsBackend
from tmmaster.sim._world import DEFAULT_GRIPPER, DEFAULT_TABLE_TOP_Z_MM, GripperGeometry

MODEL = tmmaster.robot_model("tm5-700")


@dataclass(frozen=True)
class Scenario:
    """A part, where the TCP closes on it, the grip force, and what must happen."""

    expected: str
    size_mm: tuple[float, float, float] = (30.0, 30.0, 30.0)
    mass_kg: float = 0.1
    #: The part's offset from the TCP along the closing direction, its depth and height, mm.
    across: float = 0.0
    depth: float = 0.0
    high: float = 0.0
    #: The part turned about the vertical, deg.
    turned: float = 0.0
    force_n: float = 40.0
    #: The speed of the Line down onto the part, %.
    speed: float = 20.0
    #: The width the fingers stop at, for the scenarios that grip, mm.
    width_mm: float | None = None
    extra: dict[str, object] = field(default_factory=dict)


SCENARIOS = {
    "centred": Scenario("held", width_mm=30),
    "4 mm across, pushed to the centre": Scenario("held", across=4, width_mm=30),
    "12 mm across: a pad lands on it": Scenario("collision", across=12),
    # A pad's inner face 19.5 mm off the TCP, the part's edge at 19.6 mm: it lands on it.
    "4.6 mm across: a pad lands on its edge": Scenario("collision", across=4.6),
    "4.6 mm across at 100 %: a pad lands on its edge": Scenario("collision", across=4.6, speed=100),
    "4.4 mm across at 100 %: pushed to the centre": Scenario(
        "held", across=4.4, speed=100, width_mm=30
    ),
    "20 mm deep: the pads overlap 5 mm": Scenario("held", depth=20, width_mm=30),
    "30 mm deep: the pads pass beside": Scenario("missed", depth=30),
    "TCP 20 mm high": Scenario("held", high=20, width_mm=30),
    "TCP 30 mm high: the pads pass above": Scenario("missed", high=30),
    "turned 10 deg: squeezed square": Scenario("held", turned=10, width_mm=30),
    "24 mm cube turned 45 deg: jams on its edges": Scenario(
        "jammed", size_mm=(24, 24, 30), turned=45, width_mm=24 * 2**0.5
    ),
    "30 mm cube turned 45 deg: wider than the opening": Scenario("collision", turned=45),
    "38 mm wide: within the stroke": Scenario("held", size_mm=(30, 38, 30), width_mm=38),
    "45 mm wide: beyond the stroke": Scenario("collision", size_mm=(30, 45, 30)),
    "1 kg at 40 N: friction carries it": Scenario("held", mass_kg=1.0, width_mm=30),
    "5 kg at 40 N: it slips out": Scenario("slipped", mass_kg=5.0),
    # 2 x 0.5 x 40 N = 40 N of friction would carry 4 kg; the safety factor of 2 leaves 2 kg.
    "3 kg at 40 N: beyond the safety factor, it slips out": Scenario("slipped", mass_kg=3.0),
    # Within the margin by more than the lift's own acceleration (MuJoCo feels it).
    "1.6 kg at 40 N: within the safety factor, carried": Scenario("held", mass_kg=1.6, width_mm=30),
    "6.5 kg at 140 N: carried, over the payload": Scenario("payload", mass_kg=6.5, force_n=140),
    # 5.5 kg is within the TM5-700's 6 kg, but not with the 2FG7's own 1.1 kg.
    "5.5 kg at 140 N: with the gripper, over the payload": Scenario(
        "payload", mass_kg=5.5, force_n=140
    ),
}


def make_backend(name: str, world: World, home: Pose) -> PhysicsBackend:
    if name == "kinematic":
        return KinematicBackend(MODEL, world=world, home=home)
    from tmmaster.sim._mujoco import MuJoCoBackend

    return MuJoCoBackend(MODEL, world=world, home=home)


def run(backend: PhysicsBackend, done: Callable[[], bool], limit_s: float = 5.0) -> str | None:
    """Step until ``done()``; the kind of a fault that stopped the arm, or None."""
    fault = until_fault(backend, done, limit_s)
    return None if fault is None else fault.kind


def attempt(backend_name: str, s: Scenario) -> tuple[str, float]:
    """Run a scenario: its outcome and the width the fingers stopped at."""
    part = Pose(300, -200, DEFAULT_TABLE_TOP_Z_MM + s.size_mm[2] / 2, 180, 0, 90 + s.turned)
    grasp = Pose(part.x - s.across, part.y - s.depth, part.z + s.high, 180, 0, 90)
    above = grasp.offset(dz=60)
    world = World([TableObject(name="part", pose=part, size_mm=s.size_mm, mass_kg=s.mass_kg)])
    b = make_backend(backend_name, world, above)
    b.start_motion(grasp, motion=MotionType.LINE, speed_percent=s.speed, accel_time_s=0.1)
    fault = run(b, b.is_settled)
    if fault is not None:
        return fault, 0.0
    b.drive_gripper(0, speed_mm_s=100, force_n=s.force_n)
    run(b, lambda: not b.gripper_state().moving)
    run(b, lambda: True)
    closed = b.gripper_state()
    b.start_motion(above, motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1)
    fault = run(b, b.is_settled)
    if fault is not None:
        return fault, closed.width_mm
    [obj] = b.objects()
    lifted = obj.pose.z - part.z
    if obj.held and lifted > 55:
        face = s.size_mm[1]
        return ("jammed" if closed.width_mm > face + 2 else "held"), closed.width_mm
    if closed.contact:
        # Squeezed, then left behind: on the table where it was, the fingers shut.
        assert abs(lifted) < 1.0
        assert obj.resting_on == "table"
        assert not b.gripper_state().contact
        return "slipped", closed.width_mm
    assert abs(lifted) < 1.0
    return "missed", closed.width_mm


@pytest.mark.parametrize("backend_name", BACKENDS)
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_both_backends_agree_on_the_grasp(backend_name: str, name: str) -> None:
    scenario = SCENARIOS[name]
    outcome, width = attempt(backend_name, scenario)
    assert outcome == scenario.expected
    if scenario.width_mm is not None:
        # MuJoCo's pads sink a fraction of a millimetre into the part (soft contacts).
        assert width == pytest.approx(scenario.width_mm, abs=0.7)


def test_the_friction_rule_reproduces_the_2fg7_payload() -> None:
    # 2 x 0.5 x 140 N / (2 x 9.81) = 7.1 kg at the 2FG7's strongest grip (its rated
    # payload: 7 kg); at the simulator's default 40 N, 2.0 kg.
    assert DEFAULT_GRIPPER.max_mass_kg(140) == pytest.approx(7.14, abs=0.01)
    assert DEFAULT_GRIPPER.max_mass_kg(40) == pytest.approx(2.04, abs=0.01)
    assert DEFAULT_GRIPPER.holds(2.0, 40)
    assert not DEFAULT_GRIPPER.holds(2.1, 40)
    stricter = GripperGeometry(safety_factor=4)
    assert stricter.max_mass_kg(140) == pytest.approx(3.57, abs=0.01)
