"""The simulator's physics layer: kinematic arm timing, gripper, grasp rule, held objects."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

import pytest

from sim_backends import BackendNotReadyError, SlowSettlingBackend
from tmmaster._exceptions import TMMasterError
from tmmaster._pose import MotionType, Pose
from tmmaster._robot_models import robot_model
from tmmaster.sim._backend import GripperState, MotionRejectedError, PhysicsBackend
from tmmaster.sim._kinematic import DEFAULT_HOME, KinematicBackend
from tmmaster.sim._world import (
    DEFAULT_PART_POSE,
    DEFAULT_TABLE_TOP_Z_MM,
    TABLE,
    TableObject,
    World,
)

DT = 0.01
MODEL = robot_model("tm5-700")
ACCEL = MODEL.accel_time_s
PICK = DEFAULT_PART_POSE
ABOVE_PICK = PICK.offset(dz=100)
PLACE = Pose(300, 200, 100, 180, 0, 90)


def run_until(backend: KinematicBackend, done: Callable[[], bool], *, limit_s: float = 10.0) -> int:
    """Step until ``done()``; return the number of ticks it took."""
    for tick in range(1, round(limit_s / DT) + 1):
        backend.step(DT)
        if done():
            return tick
    raise AssertionError(f"not done after {limit_s} simulated seconds")


def move(backend: KinematicBackend, target: Pose, motion: MotionType = MotionType.LINE) -> int:
    """Run a full motion at 100 % speed; return its tick count."""
    backend.start_motion(target, motion=motion, speed_percent=100, accel_time_s=ACCEL)
    return run_until(backend, lambda: not backend.motion_running)


def backend_at(
    pose: Pose, *, world: World | None = None, settle_time_s: float = 0.0
) -> KinematicBackend:
    return KinematicBackend(MODEL, home=pose, world=world, settle_time_s=settle_time_s)


def close_gripper(backend: KinematicBackend, width_mm: float = 10.0) -> None:
    backend.drive_gripper(width_mm, speed_mm_s=50, force_n=20)
    run_until(backend, lambda: not backend.gripper_state().moving)


def test_backends_implement_the_protocol() -> None:
    assert isinstance(KinematicBackend(MODEL), PhysicsBackend)
    assert isinstance(SlowSettlingBackend(MODEL), PhysicsBackend)


def test_initial_state() -> None:
    backend = KinematicBackend(MODEL)
    assert backend.tcp_pose() == DEFAULT_HOME == Pose(250, 0, 300, 180, 0, 90)
    joints = backend.joint_positions_deg()
    assert joints is not None
    assert backend.flange_pose() == MODEL.forward(joints)
    assert MODEL.forward(joints).is_close(DEFAULT_HOME, mm=1e-3, deg=1e-3)
    assert backend.is_settled()
    assert backend.is_ready()
    assert backend.gripper_state().width_mm == 39.0
    assert not backend.gripper_state().moving
    [part] = backend.objects()
    assert (part.name, part.pose, part.held) == ("part", Pose(300, -200, 100, 180, 0, 90), False)


def test_line_of_100_mm_at_10_percent_takes_the_model_time() -> None:
    backend = backend_at(ABOVE_PICK)
    duration = backend.start_motion(
        PICK, motion=MotionType.LINE, speed_percent=10, accel_time_s=ACCEL
    )
    assert duration == MODEL.motion_time(
        ABOVE_PICK,
        PICK,
        speed_percent=10,
        motion=MotionType.LINE,
        accel_time_s=ACCEL,
        start_joints_deg=backend_at(ABOVE_PICK).joint_positions_deg(),
    )
    # Never faster than 110 mm/s at 10 %, plus one ramp time (the joints may be slower).
    assert duration >= 100 / 110 + 0.2
    assert not backend.is_settled()
    ticks = run_until(backend, backend.is_settled)
    assert abs(ticks * DT - duration) <= DT
    assert backend.tcp_pose() == PICK


def test_ptp_and_line_take_different_times_over_the_same_distance() -> None:
    start, target = Pose(300, -50, 100, 180, 0, 90), Pose(300, 50, 100, 180, 0, 90)
    elapsed = {}
    for motion in MotionType:
        backend = backend_at(start)
        duration = backend.start_motion(target, motion=motion, speed_percent=10, accel_time_s=ACCEL)
        ticks = 0
        while backend.motion_running:
            backend.step(DT)
            ticks += 1
        assert abs(ticks * DT - duration) <= DT
        assert backend.tcp_pose() == target
        elapsed[motion] = duration
    # PTP is limited by the base joint swinging ~18.9 deg at 18 deg/s; the Line by the
    # same joints, whose rate peaks mid-path (the joint-space model, issue 9).
    assert elapsed[MotionType.PTP] == pytest.approx(1.2514, abs=1e-3)
    assert elapsed[MotionType.LINE] == pytest.approx(1.3071, abs=1e-3)


def test_pose_moves_along_the_line_during_a_motion_and_ends_exactly_on_target() -> None:
    backend = backend_at(ABOVE_PICK)
    duration = backend.start_motion(
        PICK, motion=MotionType.LINE, speed_percent=10, accel_time_s=ACCEL
    )
    heights = []
    while backend.motion_running:
        backend.step(DT)
        pose = backend.tcp_pose()
        assert (pose.x, pose.y, pose.rx, pose.ry, pose.rz) == (300, -200, 180, 0, 90)
        heights.append(pose.z)
    assert heights == sorted(heights, reverse=True)
    assert len(set(heights)) == len(heights)  # never stalls mid-way
    # The trapezoid is symmetric: half the time covers half the path.
    backend = backend_at(ABOVE_PICK)
    backend.start_motion(PICK, motion=MotionType.LINE, speed_percent=10, accel_time_s=ACCEL)
    backend.step(duration / 2)
    assert backend.tcp_pose().z == pytest.approx(150.0)
    backend.step(duration / 2)
    assert backend.tcp_pose() == PICK


def test_settle_time_delays_settled_after_the_motion_ends() -> None:
    backend = backend_at(ABOVE_PICK, settle_time_s=0.3)
    move(backend, PICK)
    assert not backend.is_settled()
    ticks = run_until(backend, backend.is_settled)
    assert abs(ticks * DT - 0.3) <= DT


def test_a_replaced_motion_starts_from_the_current_pose() -> None:
    backend = backend_at(ABOVE_PICK)
    first = backend.start_motion(PICK, motion=MotionType.LINE, speed_percent=10, accel_time_s=0)
    backend.step(first / 2)
    midway = backend.tcp_pose()
    assert midway.z == pytest.approx(150.0)
    target = midway.offset(dx=50)
    joints = backend.joint_positions_deg()
    duration = backend.start_motion(
        target, motion=MotionType.LINE, speed_percent=10, accel_time_s=0
    )
    assert duration == MODEL.motion_time(
        midway,
        target,
        speed_percent=10,
        motion=MotionType.LINE,
        accel_time_s=0,
        start_joints_deg=joints,
    )
    assert duration >= 50 / 110
    backend.step(duration / 2)
    assert backend.tcp_pose().is_close(midway.offset(dx=25), mm=1e-6)
    backend.step(duration)
    assert backend.tcp_pose() == target


def test_stop_motion_holds_the_current_pose() -> None:
    backend = backend_at(ABOVE_PICK)
    duration = backend.start_motion(
        PICK, motion=MotionType.LINE, speed_percent=10, accel_time_s=ACCEL
    )
    backend.step(duration / 2)
    stopped = backend.tcp_pose()
    backend.stop_motion()
    assert backend.motion_running  # it brakes to rest: a stop takes time
    backend.step(duration)
    assert not backend.motion_running
    assert backend.is_settled()
    rest = backend.tcp_pose()
    assert stopped.z == pytest.approx(150.0)
    assert PICK.z < rest.z < stopped.z  # braked on along the line, short of the target
    assert rest.is_close(Pose(PICK.x, PICK.y, rest.z, *PICK.as_list()[3:]), mm=0.01, deg=0.01)
    backend.step(duration)
    assert backend.tcp_pose() == rest


def test_orientation_wraps_the_short_way() -> None:
    start = Pose(300, 0, 300, 180, 0, 179)
    target = Pose(300, 0, 300, 180, 0, -179)
    backend = backend_at(start)
    duration = backend.start_motion(
        target, motion=MotionType.LINE, speed_percent=100, accel_time_s=ACCEL
    )
    # J6 turns 2 degrees at 225 deg/s; 358 degrees would take ~1.8 s.
    assert duration == MODEL.motion_time(
        start,
        target,
        speed_percent=100,
        motion=MotionType.LINE,
        accel_time_s=ACCEL,
        start_joints_deg=backend_at(start).joint_positions_deg(),
    )
    assert duration < 0.3
    while backend.motion_running:
        backend.step(duration / 10)
        rz = backend.tcp_pose().rz
        assert abs(rz) >= 179 - 1e-9, rz
        assert backend.tcp_pose().rx == 180  # not reported as -180
    assert backend.tcp_pose() == target


def test_gripper_moves_at_the_commanded_speed() -> None:
    backend = KinematicBackend(MODEL)
    backend.drive_gripper(10, speed_mm_s=29, force_n=20)
    backend.step(0.5)
    state = backend.gripper_state()
    assert state.moving
    assert state.width_mm == pytest.approx(24.5)
    backend.step(0.5)
    assert backend.gripper_state() == GripperState(width_mm=10, moving=False, contact=False)


def test_gripper_target_is_clamped_to_the_stroke() -> None:
    backend = KinematicBackend(MODEL)
    close_gripper(backend, width_mm=-5)
    assert backend.gripper_state().width_mm == 1.0


def test_closing_away_from_the_object_grips_nothing() -> None:
    backend = KinematicBackend(MODEL)
    close_gripper(backend)
    state = backend.gripper_state()
    assert (state.width_mm, state.contact, state.moving) == (10.0, False, False)
    assert [o.held for o in backend.objects()] == [False]
    assert backend.world.held is None


@pytest.mark.parametrize(
    ("offset", "grips"),
    [
        # Along the pads' depth (base y here): they overlap the 30 mm part up to 25 mm off.
        ({"dy": 24.9}, True),
        ({"dy": 25.1}, False),
        # Along their height (base z): 12 mm of pad above and below the TCP, 15 mm of part.
        ({"dz": 26.9}, True),
        ({"dz": 27.1}, False),
        # Across the fingers (base x): the part must lie between the open fingers.
        ({"dx": 4.4}, True),
    ],
)
def test_grasp_tolerance_comes_from_the_pads_and_the_part(
    offset: dict[str, float], grips: bool
) -> None:
    # The TCP may be off the part's centre by as much as the pads still overlap it: the
    # tolerance is derived from the same pad geometry the MuJoCo scene is built from.
    backend = backend_at(PICK.offset(**offset))
    close_gripper(backend)
    assert backend.gripper_state().contact is grips
    assert backend.gripper_state().width_mm == (30.0 if grips else 10.0)


def test_a_gripped_part_keeps_its_offset_in_the_fingers() -> None:
    # Gripped 20 mm off its centre along the pads' depth and pushed to the middle across:
    # it is carried where it sits between the pads, not snapped onto the TCP.
    backend = backend_at(PICK.offset(dx=-3, dy=-20))
    close_gripper(backend)
    [part] = backend.objects()
    assert part.held
    assert part.pose.is_close(PICK.offset(dx=-3), mm=1e-6, deg=1e-6)
    move(backend, PICK.offset(dx=-3, dy=-20, dz=100))
    [part] = backend.objects()
    assert part.pose.is_close(PICK.offset(dx=-3, dz=100), mm=1e-6, deg=1e-6)


def test_closing_on_the_object_stops_at_its_width_with_contact() -> None:
    backend = backend_at(ABOVE_PICK)
    move(backend, PICK)
    backend.drive_gripper(10, speed_mm_s=9, force_n=20)
    ticks = run_until(backend, lambda: not backend.gripper_state().moving)
    assert abs(ticks * DT - 1.0) <= DT  # 39 -> 30 mm at 9 mm/s
    state = backend.gripper_state()
    assert (state.width_mm, state.contact, state.moving) == (30.0, True, False)
    [part] = backend.objects()
    assert part.held


def test_object_wider_than_the_opening_or_narrower_than_the_target_is_not_gripped() -> None:
    world = World([TableObject(name="box", pose=PICK, width_mm=45)])
    backend = backend_at(PICK, world=world)
    close_gripper(backend)
    assert backend.gripper_state().contact is False
    assert backend.gripper_state().width_mm == 10.0

    backend = backend_at(PICK)
    close_gripper(backend, width_mm=35)  # stops before touching the 30 mm part
    assert backend.gripper_state().contact is False
    assert backend.world.held is None


def test_held_object_follows_the_tcp_and_stays_where_released() -> None:
    backend = backend_at(ABOVE_PICK)
    move(backend, PICK)
    close_gripper(backend)
    backend.start_motion(PLACE, motion=MotionType.PTP, speed_percent=50, accel_time_s=ACCEL)
    backend.step(0.3)
    [part] = backend.objects()
    assert part.held
    assert part.pose == backend.tcp_pose()
    assert part.pose.distance_to(PICK) > 10
    run_until(backend, lambda: not backend.motion_running)
    assert backend.objects()[0].pose == PLACE

    backend.drive_gripper(39, speed_mm_s=50, force_n=0)
    backend.step(DT)
    assert backend.gripper_state().contact is False
    assert backend.gripper_state().moving
    assert backend.world.held is None
    move(backend, DEFAULT_HOME, MotionType.PTP)
    [part] = backend.objects()
    assert (part.pose, part.held) == (PLACE, False)


def test_squeezing_a_held_object_keeps_contact() -> None:
    backend = backend_at(PICK)
    close_gripper(backend)
    backend.drive_gripper(5, speed_mm_s=50, force_n=40)
    backend.step(DT)
    state = backend.gripper_state()
    assert (state.width_mm, state.contact, state.moving) == (30.0, True, False)


def test_invalid_arguments_are_rejected() -> None:
    backend = KinematicBackend(MODEL)
    with pytest.raises(ValueError, match="dt"):
        backend.step(-0.1)
    with pytest.raises(ValueError, match="speed_percent"):
        backend.start_motion(PICK, motion=MotionType.LINE, speed_percent=0, accel_time_s=0.2)
    with pytest.raises(ValueError, match="speed_mm_s"):
        backend.drive_gripper(10, speed_mm_s=0, force_n=10)
    with pytest.raises(ValueError, match="duplicate"):
        World([TableObject(name="a", pose=PICK), TableObject(name="a", pose=PLACE)])


def test_slow_settling_backend_loses_its_view_and_recovers() -> None:
    backend = SlowSettlingBackend(MODEL, home=ABOVE_PICK, invalidate_after_motions=1)
    move(backend, PICK)
    assert backend.motions_completed == 1
    assert not backend.is_ready()
    with pytest.raises(BackendNotReadyError):
        backend.start_motion(ABOVE_PICK, motion=MotionType.LINE, speed_percent=100, accel_time_s=0)
    with pytest.raises(BackendNotReadyError):
        backend.drive_gripper(10, speed_mm_s=50, force_n=10)
    assert backend.rejected_commands == 2
    backend.step(5.0)  # a paused physics view does not settle either
    assert not backend.is_settled()

    backend.reinitialize()
    assert backend.is_ready()
    assert backend.reinitialize_count == 1
    assert backend.tcp_pose() == PICK
    ticks = run_until(backend, backend.is_settled)
    assert abs(ticks * DT - 1.5) <= DT
    # The view stays valid until the next motion completes.
    assert backend.is_ready()
    move(backend, ABOVE_PICK)
    assert backend.tcp_pose() == ABOVE_PICK
    assert not backend.is_ready()


def test_world_grasp_rule() -> None:
    world = World()
    part = world.get("part")
    assert world.grasp_candidate(PICK, current_width_mm=39, target_width_mm=10) == part
    assert world.grasp_candidate(PICK, current_width_mm=39, target_width_mm=30) is None
    assert world.grasp_candidate(PICK, current_width_mm=29, target_width_mm=10) is None
    assert world.grasp_candidate(PICK, current_width_mm=10, target_width_mm=39) is None
    # The pads (24 mm high) pass 3 mm above the 30 mm part.
    above = PICK.offset(dz=30)
    assert world.grasp_candidate(above, current_width_mm=39, target_width_mm=10) is None
    assert world.grasp_candidate(PICK.offset(dz=6), current_width_mm=39, target_width_mm=10) == part
    world.grasp("part", PICK)
    assert world.held == part
    assert world.release(PLACE) == part.model_copy(update={"pose": PLACE})
    assert world.held is None
    assert world.release(PLACE) is None


# -- size, mass and the falling rule (issue 9) ---------------------------------------------


def test_objects_have_size_and_mass_and_width_is_the_y_size() -> None:
    box = TableObject(name="box", pose=PICK, size_mm=(40, 20, 10), mass_kg=0.5)
    assert (box.width_mm, box.mass_kg) == (20, 0.5)
    assert TableObject(name="w", pose=PICK, width_mm=45).size_mm == (30, 45, 30)
    with pytest.raises(ValueError, match="width_mm or size_mm"):
        TableObject(name="x", pose=PICK, width_mm=45, size_mm=(30, 30, 30))
    with pytest.raises(ValueError, match="greater than 0"):
        TableObject(name="x", pose=PICK, size_mm=(30, 0, 30))
    [state] = World([box]).states()
    assert (state.size_mm, state.mass_kg) == ((40, 20, 10), 0.5)


def test_the_default_part_rests_on_the_table_where_it_starts() -> None:
    world = World()
    assert world.table_top_z_mm == DEFAULT_TABLE_TOP_Z_MM == 85.0
    [state] = world.states()
    assert (state.pose, state.resting_on) == (DEFAULT_PART_POSE, "table")


def test_an_object_placed_in_the_air_starts_on_its_support() -> None:
    world = World([TableObject(name="high", pose=PLACE.offset(dz=80))])
    assert world.get("high").pose == PLACE
    assert world.resting_on("high") == TABLE


def test_released_object_falls_onto_the_table_keeping_x_y_and_orientation() -> None:
    world = World()
    world.grasp("part", PICK)
    air = Pose(250, 150, 260, 180, 0, 45)
    world.follow(air)
    assert world.resting_on("part") is None
    released = world.release(air)
    assert released is not None
    assert released.pose == Pose(250, 150, 100, 180, 0, 45)
    assert world.resting_on("part") == TABLE


def test_released_object_falls_onto_the_object_below_it() -> None:
    world = World(
        [
            TableObject(name="bottom", pose=PLACE),
            TableObject(name="top", pose=PICK, size_mm=(30, 30, 20)),
        ]
    )
    world.grasp("top", PICK)
    # 10 mm off to the side: the footprints still overlap, so it lands on "bottom".
    world.release(PLACE.offset(dx=10, dz=100))
    assert world.get("top").pose == PLACE.offset(dx=10, dz=15 + 10)
    assert world.resting_on("top") == "bottom"
    # 31 mm off: no overlap with the 30 mm box, it falls past it onto the table.
    world.grasp("top", world.get("top").pose)
    world.release(PLACE.offset(dx=31, dz=100))
    assert world.get("top").pose.z == DEFAULT_TABLE_TOP_Z_MM + 10
    assert world.resting_on("top") == TABLE


def test_a_support_above_the_object_does_not_carry_it() -> None:
    # Parts waiting at the pick spot (a feeder) overlap; none stands on another.
    world = World([TableObject(name=f"p{i}", pose=PICK) for i in range(3)])
    assert [s.resting_on for s in world.states()] == [TABLE] * 3
    assert all(s.pose == PICK for s in world.states())


def test_rotated_box_rests_on_its_rotated_height() -> None:
    # A 60 x 30 x 20 box turned on its side (rx = 90): 30 mm high in the base frame.
    box = TableObject(name="b", pose=Pose(300, 0, 300, 90, 0, 0), size_mm=(60, 30, 20))
    world = World([box])
    assert world.get("b").pose.z == pytest.approx(DEFAULT_TABLE_TOP_Z_MM + 15)


def test_kinematic_backend_drops_the_released_part() -> None:
    backend = backend_at(ABOVE_PICK)
    move(backend, PICK)
    close_gripper(backend)
    move(backend, PLACE.offset(dz=100), MotionType.PTP)
    assert backend.objects()[0].resting_on is None
    backend.drive_gripper(39, speed_mm_s=50, force_n=0)
    backend.step(DT)
    [part] = backend.objects()
    assert (part.pose, part.held, part.resting_on) == (PLACE, False, TABLE)


def test_kinematic_backend_reinitialize_keeps_the_motion() -> None:
    backend = backend_at(ABOVE_PICK)
    backend.start_motion(PICK, motion=MotionType.LINE, speed_percent=10, accel_time_s=ACCEL)
    backend.step(0.3)
    assert backend.reinitialize() is True
    assert backend.motion_running
    run_until(backend, lambda: not backend.motion_running)
    assert backend.tcp_pose() == PICK


def test_motion_rejected_error_names_a_known_reason() -> None:
    error = MotionRejectedError("joint_limit", "J3 beyond 155 deg")
    assert (error.reason, str(error)) == ("joint_limit", "J3 beyond 155 deg")
    assert isinstance(error, TMMasterError)
    with pytest.raises(ValueError, match="reason"):
        MotionRejectedError("bad")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("module", "argv"),
    [
        ("tmmaster.sim", ["--physics", "mujoco", "--port", "0"]),
        ("tmmaster.pickplace", ["--sim", "--sim-physics", "mujoco"]),
    ],
)
def test_without_mujoco_the_clis_exit_1_naming_the_extra(
    module: str,
    argv: list[str],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # sys.modules["mujoco"] = None makes "import mujoco" fail as if it were not installed
    # (tmmaster imports it only when the backend is asked for, so in-process is enough).
    monkeypatch.setitem(sys.modules, "mujoco", None)
    command_main = importlib.import_module(f"{module}.__main__").main
    assert command_main(argv) == 1
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "tmmaster[mujoco]" in lines[0]
    assert lines[0].endswith("[exit 1]")


def _reference_support(world: World, obj: TableObject) -> tuple[str, float]:
    """The support rule read straight off every object (what the world's index must find)."""
    hx, hy, hz = obj.half_extents_mm()
    best = (TABLE, world.table_top_z_mm)
    for other in world.objects:
        if other.name == obj.name or (world.held is not None and other.name == world.held.name):
            continue
        ox, oy, oz = other.half_extents_mm()
        overlaps = (
            abs(other.pose.x - obj.pose.x) < ox + hx and abs(other.pose.y - obj.pose.y) < oy + hy
        )
        top = other.pose.z + oz
        if overlaps and top <= obj.pose.z - hz + 0.5 and top > best[1]:
            best = (other.name, top)
    return best


def test_the_support_index_finds_what_reading_every_object_finds() -> None:
    # Random heaps of boxes (some turned, one wider than the index's grid), dropped one at
    # a time: each lands where the plain rule over every object says it should.
    import random

    rng = random.Random(7)
    objects = [
        TableObject(
            name=f"o{i}",
            pose=Pose(
                rng.uniform(250, 350),
                rng.uniform(-50, 50),
                rng.uniform(100, 400),
                rng.choice([180, 90, 0]),
                0,
                rng.choice([0, 30, 90]),
            ),
            size_mm=(rng.uniform(5, 80), rng.uniform(5, 40), rng.uniform(5, 40)),
        )
        for i in range(40)
    ]
    objects.append(
        TableObject(name="plate", pose=Pose(300, 0, 90, 180, 0, 0), size_mm=(3000, 3000, 2))
    )
    world = World(objects)
    for state in world.states():
        assert state.resting_on is not None
        if state.resting_on != TABLE:  # it rests on something that is under it
            below = world.get(state.resting_on)
            assert below.pose.z < state.pose.z
    for i in range(40):
        name = f"o{rng.randrange(40)}"
        obj = world.get(name)
        world.grasp(name, obj.pose)
        tcp = Pose(rng.uniform(250, 350), rng.uniform(-50, 50), 500, obj.pose.rx, 0, obj.pose.rz)
        world.follow(tcp)
        falling = world.get(name)
        expected = _reference_support(world, falling)
        assert world.support_below(falling) == expected, i
        world.release(tcp)
        assert world.resting_on(name) == expected[0]


def test_parts_waiting_at_one_spot_settle_in_linear_time(monkeypatch: pytest.MonkeyPatch) -> None:
    # Structural, not timed: settling N parts stacked in a feeder must not look at every
    # other part for each one (N * N box computations: a 100,000-cycle --sim run never
    # started). Count the bounding-box computations: a few per part.
    calls = 0
    original = TableObject.half_extents_mm

    def counting(self: TableObject, pose: Pose | None = None) -> tuple[float, float, float]:
        nonlocal calls
        calls += 1
        return original(self, pose)

    monkeypatch.setattr(TableObject, "half_extents_mm", counting)
    parts = [TableObject(name=f"part-{i}", pose=PICK) for i in range(1000)]
    world = World(parts)
    assert calls <= 10 * len(parts)
    assert {s.resting_on for s in world.states()} == {TABLE}
    # Putting one back on the heap: a few box computations again, and of the parts equally
    # high under it, the first in the world's order carries it (as a scan would say).
    world.grasp("part-0", PICK)
    world.follow(PICK.offset(dz=50))
    expected = _reference_support(world, world.get("part-0"))
    calls = 0
    world.release(PICK.offset(dz=50))
    assert calls <= 10
    assert world.resting_on("part-0") == expected[0] == "part-1"
