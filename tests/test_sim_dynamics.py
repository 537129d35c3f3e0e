"""The MuJoCo backend's arm dynamics (its default for the TM5-700 and TM5-900).

Techman's link masses and inertias, joint servos limited to the joints' efforts with the
planned acceleration fed forward: the arm alone follows the planned trajectory within a
fraction of a millimetre, a part it carries (which the servo does not know of) makes it
lag and overshoot, and a move is done only once the joints have settled at its target.
Every check compares simulated quantities, never wall time.
"""

from __future__ import annotations

import importlib.util
import math
from collections.abc import Callable

import pytest

import tmmaster
from tmmaster import ConfigError, PollPolicy, Pose
from tmmaster._pose import MotionType
from tmmaster.sim import Cell, KinematicBackend, RobotSetup, Simulator, TableObject, World
from tmmaster.sim._mujoco import MuJoCoBackend, build_mjcf
from tmmaster.sim._simulator import simulator_summary
from tmmaster.sim._world import DEFAULT_TABLE_TOP_Z_MM

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("mujoco") is None,
    reason="the MuJoCo backend needs the mujoco extra",
)

MODEL = tmmaster.robot_model("tm5-700")
HOME = tmmaster.DEFAULT_HOME
DT = 0.02
PICK = Pose(300, -200, 100, 180, 0, 90)
ABOVE_PICK = PICK.offset(dz=100)
PLACE = Pose(300, 200, 200, 180, 0, 90)
#: The master's default tolerance on the pose reported at done (RobotConfig).
MASTER_MM, MASTER_DEG = 1.0, 1.0


def run_until(b: MuJoCoBackend, done: Callable[[], bool], *, limit_s: float = 20.0) -> float:
    for n in range(1, round(limit_s / DT) + 1):
        b.step(DT)
        if done():
            return n * DT
    raise AssertionError(f"not done after {limit_s} simulated seconds")


def dynamic(mass_kg: float) -> MuJoCoBackend:
    world = World([TableObject(name="part", pose=PICK, mass_kg=mass_kg)])
    return MuJoCoBackend(MODEL, world=world, home=HOME, grasp="weld", dynamics=True)


def test_the_scene_has_techmans_link_masses_and_joint_torques() -> None:
    import mujoco

    m = mujoco.MjModel.from_xml_string(build_mjcf(MODEL, [], table_top_z_mm=85, dynamics=True))
    # tm_description/urdf/tm5-700-nominal.urdf: link_1 .. link_6 masses, joint efforts.
    masses = [float(m.body(f"link{i}").mass[0]) for i in range(1, 7)]
    assert masses == pytest.approx([4.032, 8.567, 2.273, 1.576, 1.576, 0.65])
    assert float(m.body("link2").inertia[1]) == pytest.approx(0.19825197)
    limits = [tuple(m.actuator(f"a{i}").ctrlrange) for i in range(1, 7)]
    assert limits == [(-157, 157)] * 3 + [(-43, 43)] * 3
    assert m.body_gravcomp[m.body("link2").id] == 0  # the links feel gravity
    # Without dynamics the links stay weightless, set by the backend (no arm motors).
    ideal = mujoco.MjModel.from_xml_string(build_mjcf(MODEL, [], table_top_z_mm=85))
    assert ideal.nu == 2
    assert ideal.body_gravcomp[ideal.body("link2").id] == 1
    with pytest.raises(ValueError, match="link masses"):
        build_mjcf(tmmaster.robot_model("tm12"), [], table_top_z_mm=85, dynamics=True)


def holding(mass_kg: float) -> MuJoCoBackend:
    """An arm that picked a part of ``mass_kg`` and lifted it to ABOVE_PICK."""
    b = dynamic(mass_kg)
    for target, motion, speed in (
        (ABOVE_PICK, MotionType.PTP, 50),
        (PICK, MotionType.LINE, 10),
    ):
        b.start_motion(target, motion=motion, speed_percent=speed, accel_time_s=0.2)
        run_until(b, b.is_settled)
    b.drive_gripper(0, speed_mm_s=100, force_n=40)
    run_until(b, lambda: not b.gripper_state().moving)
    b.start_motion(ABOVE_PICK, motion=MotionType.LINE, speed_percent=10, accel_time_s=0.2)
    run_until(b, b.is_settled)
    assert b.objects()[0].held
    return b


def carry_fast(mass_kg: float) -> tuple[MuJoCoBackend, float, float]:
    """Pick a part of ``mass_kg``, PTP it to PLACE at 100 %: (backend, lag mm, done at s).

    The lag is the largest distance between the TCP and the TCP of the servo's reference
    joints, read every tick of the move.
    """
    b = holding(mass_kg)
    b.start_motion(PLACE, motion=MotionType.PTP, speed_percent=100, accel_time_s=0.2)
    lag = 0.0
    elapsed = 0.0
    while not b.is_settled():
        b.step(DT)
        elapsed += DT
        reference = MODEL.forward(b.reference_joints_deg(), tool=b.tool)
        lag = max(lag, b.tcp_pose().distance_to(reference))
        assert elapsed < 5, "the move never settled"
    return b, lag, elapsed


def test_a_heavy_part_makes_the_tcp_lag_the_reference_and_done_waits_for_it() -> None:
    light, light_lag, light_done = carry_fast(0.1)
    heavy, heavy_lag, heavy_done = carry_fast(4.9)  # with the 1.1 kg gripper: the 6 kg
    # The servo does not know the part: a 4.9 kg part at full speed lags by millimetres
    # (4 mm), the arm with a light one, its acceleration fed forward, by hundredths (a
    # PD servo alone lagged 4 mm with it).
    assert heavy_lag > 3.0
    assert light_lag < 0.5
    assert heavy_lag > 2 * light_lag
    assert max(heavy.max_tracking_error_deg) > max(light.max_tracking_error_deg)
    # Both moves have the same planned duration; the heavy one settles later.
    assert heavy_done > light_done
    for b in (light, heavy):
        # Done: the joints reached the target and stopped; the TCP reported is theirs.
        assert not b.motion_running
        assert b.tcp_pose().is_close(PLACE, mm=MASTER_MM, deg=MASTER_DEG)
        assert b.tcp_pose().is_close(PLACE, mm=0.3, deg=0.05)
        [part] = b.objects()
        assert part.held


def test_the_move_is_not_done_while_the_joints_still_move() -> None:
    b = holding(4.9)  # a part the servo does not know of: the joints lag
    duration = b.start_motion(PLACE, motion=MotionType.PTP, speed_percent=100, accel_time_s=0.2)
    # Step to the end of the planned trajectory: the reference is at the target ...
    b.step(math.ceil(duration / 0.002) * 0.002)
    assert not b.motion_running
    target = MODEL.inverse(PLACE, seed_deg=b.reference_joints_deg())
    assert b.reference_joints_deg() == pytest.approx(target, abs=1e-4)
    # ... the joints are not yet: the move is not done, and the reported joints are the
    # joints', not the reference's.
    assert not b.is_settled()
    joints = b.joint_positions_deg()
    assert max(abs(a - c) for a, c in zip(joints, target, strict=True)) > 0.01
    run_until(b, b.is_settled, limit_s=2)
    joints = b.joint_positions_deg()
    assert max(abs(a - c) for a, c in zip(joints, target, strict=True)) <= 0.01


def test_a_fast_line_down_stops_where_planned_without_overshooting() -> None:
    # 100 % down to 10 mm above the table (the pads 12 mm under the TCP), 0.1 s ramps:
    # with the acceleration fed forward the arm alone follows the reference and stops
    # at the target. A PD servo alone lagged 8 mm and overshot it by 6 mm, into what a
    # real arm stops short of.
    above = Pose(300, -200, 200, 180, 0, 90)
    b = MuJoCoBackend(MODEL, world=World(), home=above, dynamics=True)
    target = above.offset(dz=DEFAULT_TABLE_TOP_Z_MM + 12 + 10 - above.z)
    planned = b.start_motion(target, motion=MotionType.LINE, speed_percent=100, accel_time_s=0.1)
    lowest, lag, elapsed = math.inf, 0.0, 0.0
    while not b.is_settled():
        b.step(0.002)  # every physics step: the overshoot lasts a few
        elapsed += 0.002
        assert b.take_fault() is None
        lowest = min(lowest, b.tcp_pose().z)
        reference = MODEL.forward(b.reference_joints_deg(), tool=b.tool)
        lag = max(lag, b.tcp_pose().distance_to(reference))
        assert elapsed < 1, "the move never settled"
    # Below the settle tolerance's 0.01 deg per joint (about 0.1 mm at the TCP) times a
    # few: measured 0.00 mm overshoot, 0.07 mm lag.
    assert target.z - lowest < 0.5
    assert lag < 0.5
    assert elapsed < planned + 0.05  # settled at once, not after ringing out
    assert b.tcp_pose().is_close(target, mm=0.2, deg=0.05)


def test_the_pick_and_place_cycle_through_the_master_with_a_heavy_part() -> None:
    b = dynamic(4.9)  # with the 1.1 kg gripper: the TM5-700's 6 kg
    with (
        # 10x, not 20x: at 20x (0.4 simulated s of 2 ms physics steps a 50 Hz tick) the
        # physics fell behind on a busy machine and starved the master (test_sim_mujoco).
        Simulator("tmflow", time_scale=10, cell=b, listen=False) as sim,
        tmmaster.connect(sim.url, profile="tmflow", polling=PollPolicy(interval_s=0.01)) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(ABOVE_PICK, speed=50)
        robot.move_to(PICK, speed=10, motion="line")
        assert robot.gripper.close().holding
        robot.move_to(ABOVE_PICK, speed=10, motion="line")
        # A fast PTP with the part: the master checks the pose it reads at done against
        # its tolerance (a move reported done short of its target raises).
        motion = robot.move_to(PLACE, speed=100)
        assert motion.last_pose is not None
        assert motion.last_pose.is_close(PLACE, mm=MASTER_MM, deg=MASTER_DEG)
        robot.gripper.open()
        robot.move_to(HOME, speed=100)
        sim.wait_for(lambda: sim.call(lambda: b.objects()[0].resting_on) == "table", timeout=10)
        part = sim.call(lambda: b.objects()[0])
    assert part.pose.x == pytest.approx(PLACE.x, abs=5)
    assert part.pose.y == pytest.approx(PLACE.y, abs=5)


def test_a_joint_held_at_its_effort_shows_as_saturation_and_lag(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from tmmaster.sim import _mujoco

    full, full_lag, full_done = carry_fast(4.9)
    assert full.saturated_steps == [0] * 6  # the TM5's efforts carry 4.9 kg at full speed
    # The same arm with a J1 motor of 20 N m instead of 157: the servo is held at the
    # limit, J1 falls behind its reference and the move settles later.
    weak_efforts = (20.0, *_mujoco._URDF_EFFORT_NM["tm5-700"][1:])
    monkeypatch.setitem(_mujoco._URDF_EFFORT_NM, "tm5-700", weak_efforts)
    weak, weak_lag, weak_done = carry_fast(4.9)
    assert weak.saturated_steps[0] > 100
    assert weak.saturated_steps[1:] == [0] * 5
    assert weak_lag > 5 * full_lag
    assert weak_done > full_done
    assert weak.tcp_pose().is_close(PLACE, mm=MASTER_MM, deg=MASTER_DEG)  # it gets there


def test_the_simulator_and_its_command_line_choose_the_dynamics() -> None:
    with Simulator(cell=Cell(physics="mujoco", dynamics=True), listen=False) as sim:
        backend = sim.backend
        assert isinstance(backend, MuJoCoBackend)
        assert backend.dynamics
    from tmmaster.sim.__main__ import build_parser

    parse = build_parser().parse_args
    assert parse(["--physics", "mujoco", "--dynamics"]).dynamics is True
    assert parse(["--physics", "mujoco", "--no-dynamics"]).dynamics is False
    assert parse(["--physics", "mujoco"]).dynamics is None  # the simulator decides


@pytest.mark.parametrize(
    ("cell", "model", "expected"),
    [
        pytest.param(Cell(physics="mujoco"), "tm5-700", True, id="mujoco-tm5-700"),
        pytest.param(Cell(physics="mujoco"), "tm5-900", True, id="mujoco-tm5-900"),
        pytest.param(Cell(physics="mujoco"), "tm12", False, id="mujoco-tm12-no-data"),
        pytest.param(
            Cell(physics="mujoco", dynamics=False), "tm5-700", False, id="mujoco-ideal-servo"
        ),
        pytest.param(Cell(), "tm5-700", False, id="kinematic"),
        pytest.param(Cell(dynamics=False), "tm5-700", False, id="kinematic-told-off"),
    ],
)
def test_dynamics_is_the_mujoco_default_where_the_link_masses_are_known(
    cell: Cell, model: str, expected: bool
) -> None:
    sim = Simulator(listen=False, cell=cell, robot=RobotSetup(model=model))
    try:
        assert sim.dynamics is expected
        assert getattr(sim.backend, "dynamics", False) is expected
        [line] = [line for line in simulator_summary(sim) if line.startswith("physics")]
        assert f"arm dynamics {'on' if expected else 'off'}" in line
    finally:
        sim.close()


def test_dynamics_the_simulator_cannot_give_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="tm12"):
        Simulator(
            cell=Cell(physics="mujoco", dynamics=True), robot=RobotSetup(model="tm12"), listen=False
        )
    with pytest.raises(ConfigError, match="only the mujoco physics backend"):
        Cell(dynamics=True)
    # Your own backend models what it models: it takes no Cell options at all.
    with Simulator(cell=KinematicBackend(MODEL), listen=False) as sim:
        assert not sim.dynamics
        assert sim.physics is None
