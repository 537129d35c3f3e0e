"""Collisions and payload: the physics stops the arm, the controller raises TM's error code.

Both backends stop a motion in the physics step where the fingers or any arm link hit the
table, and when the arm carries a part over its rated payload; the
controller turns the fault into a robot error with Techman's code (0x22 "Force or Torque
Over Range", 0x0F "Over Payload Limit"). The library's default workspace floor (0 mm)
knows nothing of the simulator's table at 85 mm: the simulator catches what it lets by
(pick & place's default floor is the table top: tests/test_cell_floor.py).
"""

from __future__ import annotations

import pytest

import tmmaster
from sim_backends import BACKENDS, until_fault
from test_sim_controller import article, run, run_until, send_article, send_tmflow, tmflow
from tmmaster import Checks, PollPolicy, Pose
from tmmaster._pose import MotionType
from tmmaster.sim import KinematicBackend, Simulator, TableObject, Timing, World
from tmmaster.sim._backend import PhysicsBackend
from tmmaster.sim._controller import SimErrorCode
from tmmaster.sim._world import DEFAULT_TABLE_TOP_Z_MM

MODEL = tmmaster.robot_model("tm5-700")
ABOVE = Pose(300, -200, 200, 180, 0, 90)
#: Above the master's floor (0 mm), below the simulator's table top (85 mm) + the pads.
INTO_TABLE = Pose(300, -200, 60, 180, 0, 90)
#: The pads reach 12 mm below the TCP: they touch the table with the TCP here.
TOUCH_Z = DEFAULT_TABLE_TOP_Z_MM + 12
ELSEWHERE = Pose(500, 300, 100, 180, 0, 90)


def make(
    name: str, world: World | None = None, home: Pose = ABOVE, **options: object
) -> PhysicsBackend:
    world = World([TableObject(name="part", pose=ELSEWHERE)]) if world is None else world
    if name == "kinematic":
        return KinematicBackend(MODEL, world=world, home=home, **options)  # type: ignore[arg-type]
    from tmmaster.sim._mujoco import MuJoCoBackend

    return MuJoCoBackend(MODEL, world=world, home=home, **options)  # type: ignore[arg-type]


@pytest.mark.parametrize("backend_name", BACKENDS)
@pytest.mark.parametrize("speed", [20, 100])
def test_fingers_hitting_the_table_stop_the_arm_where_they_touch(
    backend_name: str, speed: float
) -> None:
    b = make(backend_name)
    b.start_motion(INTO_TABLE, motion=MotionType.LINE, speed_percent=speed, accel_time_s=0.1)
    fault = until_fault(b, b.is_settled)
    assert fault is not None
    assert fault.kind == "collision"
    assert "table" in fault.message
    assert not b.motion_running  # stopped, not still heading for the target
    dynamics = getattr(b, "dynamics", False)
    if dynamics:
        # The joints were moving: the servo brakes them, and the arm comes to rest
        # against the table at once (not pressing ever harder into it, never at rest).
        assert until_fault(b, b.is_settled, limit_s=0.5) is None
    assert b.is_settled()
    # Stopped at the touch, not a tick (up to 22 mm at full speed) later: the kinematic
    # backend finds the moment in the tick, MuJoCo stops in the 2 ms physics step (2.2 mm
    # at 100 %). With dynamics the arm hits at its planned speed (0.8 m/s at 100 %) and
    # holds the joints of the step that saw the contact, the wrist already bent by the
    # impact: it rests tilted (under 1 deg) on the pads' edge, the TCP up to 0.4 mm above
    # the touch.
    assert TOUCH_Z - speed * 0.025 <= b.tcp_pose().z <= TOUCH_Z + (0.5 if dynamics else 0.3)
    assert b.take_fault() is None  # handed over once
    # Backing out of a contact the arm already has is no new collision.
    b.start_motion(ABOVE, motion=MotionType.LINE, speed_percent=speed, accel_time_s=0.1)
    assert until_fault(b, b.is_settled) is None
    # With dynamics, settled within 0.01 deg on each joint: a tenth of a millimetre.
    assert b.tcp_pose().is_close(ABOVE, mm=0.2 if dynamics else 0.01)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_moving_just_above_the_table_is_no_collision(backend_name: str) -> None:
    b = make(backend_name)
    # 2 mm above the table, reached and crossed at 20 %: an arm lags at speed (with
    # dynamics, carrying a 5 kg part the servo does not know of, the TCP overshoots the
    # end of a 100 % Line down with a 0.1 s ramp by ~8 mm), so a program comes close to a
    # surface slowly.
    low = INTO_TABLE.offset(dz=TOUCH_Z + 2 - INTO_TABLE.z)
    for target, speed in ((low, 20), (low.offset(dx=100), 20), (ABOVE, 100)):
        b.start_motion(target, motion=MotionType.LINE, speed_percent=speed, accel_time_s=0.1)
        assert until_fault(b, b.is_settled) is None
    assert b.tcp_pose().is_close(ABOVE, mm=0.2)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_tool_pointing_up_hangs_the_wrist_into_the_table(backend_name: str) -> None:
    # With a 120 mm tool pointing up, the wrist hangs under the flange: its links (45 mm
    # capsules, the same in both backends) meet the table 113 + 45 mm under the flange,
    # long before the flange does. MuJoCo: its ideal servo, which the kinematic arm is.
    tool = Pose(0, 0, 120, 0, 0, 0)
    ideal = {"dynamics": False} if backend_name == "mujoco" else {}
    # rz 180: the end module's camera turned away from the forearm (at rz 0 the capsules
    # of the two meet first, a self-collision).
    b = make(backend_name, home=Pose(400, 0, 600, 0, 0, 180), tool=tool, **ideal)
    b.start_motion(
        Pose(400, 0, 200, 0, 0, 180), motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1
    )
    fault = until_fault(b, b.is_settled)
    assert fault is not None
    assert fault.kind == "collision"
    flange = b.flange_pose()
    assert flange is not None
    assert flange.z == pytest.approx(DEFAULT_TABLE_TOP_Z_MM + 113.15 + 45, abs=0.5)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_fingers_opening_against_a_neighbour_then_rising_is_no_collision(
    backend_name: str,
) -> None:
    # A pallet at a 40 mm pitch: the open fingers (39 mm + 8 mm pads) reach 2.5 mm into
    # the part in the next slot. Opening pushes it (MuJoCo) or overlaps it from the side
    # (kinematic); rising out of it is no collision.
    slot = Pose(300, -200, DEFAULT_TABLE_TOP_Z_MM + 15, 180, 0, 90)
    world = World(
        [
            TableObject(name="placed", pose=slot),
            TableObject(name="neighbour", pose=slot.offset(dx=40)),  # across the fingers
        ]
    )
    b = make(backend_name, world, home=slot)
    b.drive_gripper(0, speed_mm_s=100, force_n=40)
    until_fault(b, lambda: not b.gripper_state().moving)
    b.drive_gripper(39, speed_mm_s=100, force_n=40)
    until_fault(b, lambda: not b.gripper_state().moving)
    b.start_motion(slot.offset(dz=60), motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1)
    assert until_fault(b, b.is_settled) is None


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_an_arm_link_that_hits_the_table_stops_the_arm(backend_name: str) -> None:
    # The tool horizontal, 110 mm up: its pads stay clear but the wrist (45 mm radius)
    # comes down to 65 mm.
    b = make(backend_name, home=Pose(400, 0, 250, 90, 0, 0))
    b.start_motion(
        Pose(400, 0, 110, 90, 0, 0), motion=MotionType.LINE, speed_percent=50, accel_time_s=0.1
    )
    fault = until_fault(b, b.is_settled)
    assert fault is not None
    assert fault.kind == "collision"
    assert b.tcp_pose().z > 125  # stopped when the wrist touched


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_carried_part_over_the_rated_payload_stops_the_lift(backend_name: str) -> None:
    assert MODEL.payload_kg == 6.0
    pick = Pose(300, -200, DEFAULT_TABLE_TOP_Z_MM + 15, 180, 0, 90)
    # The gripper's 1.1 kg counts with the part: 4.9 kg is the most the arm may pick.
    for mass, fault_kind in ((4.9, None), (5.0, "payload"), (6.5, "payload")):
        world = World([TableObject(name="part", pose=pick, mass_kg=mass)])
        b = make(backend_name, world, home=pick)
        b.drive_gripper(0, speed_mm_s=100, force_n=140)  # the 2FG7's strongest grip
        until_fault(b, lambda b=b: not b.gripper_state().moving)  # type: ignore[misc]
        b.start_motion(
            pick.offset(dz=60), motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1
        )
        fault = until_fault(b, b.is_settled)
        assert (fault and fault.kind) == fault_kind
        if fault is not None:
            assert f"{mass:g} kg" in fault.message
            assert "1.1 kg gripper" in fault.message
            assert b.tcp_pose().z < pick.z + 5  # stopped as it lifted


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_the_payload_checked_is_the_arm_models_own(backend_name: str) -> None:
    # The same 2 kg part: over a 1.5 kg model's payload, unchecked for a model without one.
    pick = Pose(300, -200, DEFAULT_TABLE_TOP_Z_MM + 15, 180, 0, 90)
    for payload, fault_kind in ((1.5, "payload"), (None, None)):
        model = MODEL.model_copy(update={"payload_kg": payload})
        world = World([TableObject(name="part", pose=pick, mass_kg=2.0)])
        if backend_name == "kinematic":
            b: PhysicsBackend = KinematicBackend(model, world=world, home=pick)
        else:
            from tmmaster.sim._mujoco import MuJoCoBackend

            b = MuJoCoBackend(model, world=world, home=pick)
        b.drive_gripper(0, speed_mm_s=100, force_n=140)
        until_fault(b, lambda b=b: not b.gripper_state().moving)  # type: ignore[misc]
        b.start_motion(
            pick.offset(dz=60), motion=MotionType.LINE, speed_percent=20, accel_time_s=0.1
        )
        fault = until_fault(b, b.is_settled)
        assert (fault and fault.kind) == fault_kind


# -- the controller: TM's error codes ------------------------------------------------------


def test_article_reports_a_collision_with_tms_code() -> None:
    backend = KinematicBackend(
        MODEL, home=ABOVE, world=World([TableObject(name="p", pose=ELSEWHERE)])
    )
    ctl, bank, _, log = article(backend=backend)
    send_article(bank, INTO_TABLE, speed=50, command=2)
    run_until(ctl, lambda: bank.get("error_code") != 0)
    assert bank.get("error_code") == SimErrorCode.COLLISION == 0x22
    assert bank.get("robot_mode") == 7  # error
    assert backend.tcp_pose().z == pytest.approx(TOUCH_Z, abs=1.0)
    assert "sim.backend_fault" in log.names()
    # The operator's reset, then the arm backs out: no new error.
    ctl.clear_error()
    send_article(bank, ABOVE, speed=50, command=2)
    run_until(ctl, lambda: bank.get("command") == 0 and bank.get("motion_status") == 0)
    run(ctl, 0.2)
    assert bank.get("error_code") == 0
    assert backend.tcp_pose().is_close(ABOVE, mm=0.01)


def test_tmflow_reports_an_overload_with_tms_code() -> None:
    pick = Pose(300, -200, DEFAULT_TABLE_TOP_Z_MM + 15, 180, 0, 90)
    heavy = World([TableObject(name="p", pose=pick, mass_kg=7.0)])
    # A weld grasp carries whatever the friction of the controller's 40 N grip would drop.
    backend = KinematicBackend(MODEL, home=pick, world=heavy, grasp="weld")
    ctl, bank, _, log = tmflow(backend=backend)
    send_tmflow(bank, 1, command=4)  # gripper_close
    run_until(ctl, lambda: bank.get("done_seq") == 1)
    assert bank.get("grasp_status") == 1
    send_tmflow(bank, 2, command=2, target=pick.offset(dz=50), speed=20)
    run_until(ctl, lambda: bank.get("last_error_code") != 0)
    assert bank.get("last_error_code") == SimErrorCode.OVER_PAYLOAD == 0x0F
    assert bank.get("error") is True
    assert bank.get("done_seq") == 1  # the lift never finished
    assert backend.tcp_pose().z < pick.z + 5
    assert any(
        e.get("fault") == "payload" for _, name, e in log.events if name == "sim.backend_fault"
    )


def test_the_master_lets_a_move_below_the_table_by_and_the_simulator_stops_it() -> None:
    # A master told of no table (its floor the robot's mounting plane, 0 mm): a TCP at
    # 60 mm passes its checks; the simulated cell's table top is at 85 mm.
    with (
        Simulator("tmflow", time_scale=20, timing=Timing(tick_hz=100), listen=False) as sim,
        tmmaster.connect(
            sim.url,
            profile="tmflow",
            polling=PollPolicy(interval_s=0.01),
            checks=Checks(workspace=tmmaster.Workspace(floor_z_mm=0)),
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(ABOVE, speed=50)
        with pytest.raises(tmmaster.RobotError) as caught:
            robot.move_to(INTO_TABLE, speed=50, motion="line")
        assert caught.value.error_code == 0x22
        assert sim.tcp_pose().z == pytest.approx(TOUCH_Z, abs=1.0)
