"""The simulator's analytic backend moves a TM joint chain (issue 9 item 3).

PTP in joint space (the TCP path curves), Line along the straight segment by inverse
kinematics, refusals with their reason, the tool offset, the joints and flange over
Modbus consistent with forward kinematics, and the encodable range rule.
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from pymodbus.client import ModbusTcpClient

import tmmaster
from sim_speeds import QUICK
from test_sim_controller import (
    DT,
    article,
    move_article,
    run,
    run_until,
    send_article,
    send_tmflow,
    tmflow,
    words,
)
from tmmaster import DEFAULT_HOME, JointSpec, MotionType, Pose, RobotModel, robot_model
from tmmaster import _kinematics as kin
from tmmaster._registers import TARGET_FIELDS
from tmmaster._robot_models import trapezoid_progress
from tmmaster.sim import Cell, KinematicBackend, Simulator
from tmmaster.sim import __main__ as sim_main
from tmmaster.sim._backend import MotionRejectedError
from tmmaster.sim._controller import SimErrorCode

TM5 = robot_model("tm5-700")
ACCEL = TM5.accel_time_s
# The article's cycle (pickplace defaults): approach, pick, lift, place, then home.
APPROACH = Pose(300, -200, 200, 180, 0, 90)
PICK = Pose(300, -200, 100, 180, 0, 90)
LIFT = Pose(300, -200, 250, 180, 0, 90)
PLACE = Pose(300, 200, 200, 180, 0, 90)
CYCLE = (
    (APPROACH, MotionType.PTP),
    (PICK, MotionType.LINE),
    (LIFT, MotionType.LINE),
    (PLACE, MotionType.PTP),
    (DEFAULT_HOME, MotionType.PTP),
)
TOOL = Pose(0, 0, 120, 0, 0, 0)  # 120 mm along the flange's z axis
#: int16 x100: the article map's pose registers end at 327.67 mm.
ARTICLE_MAX = 327.67
#: Poses inside the article map a TM5 cannot take (from DEFAULT_HOME's joints), by reason.
ARTICLE_HOME = Pose(0, 0, 300, 180, 0, 0)  # out of reach: the flange cannot be on J1's axis
#: Every solution needs J3 past its range (-155..155 deg): about -161 deg. (Pose(0, 50,
#: 200, 90, 0, 90) is not one: an in-range branch exists, 19 mm from the shoulder
#: singularity, which is then the reason.)
TM5_JOINT_LIMIT = Pose(0, 60, 150, 90, 0, 90)
TM5_SINGULAR = Pose(0, -50, 100, 90, 0, 90)  # the wrist ~19 mm from the J1 axis plane


def narrow_j1_model() -> RobotModel:
    """A TM5 whose J1 may only turn -10..10 deg."""
    joints = list(TM5.joints)
    joints[0] = JointSpec(
        origin_xyz_mm=(0, 0, 145.2), origin_rpy_deg=(0, 0, 0), limits_deg=(-10, 10), speed_deg_s=180
    )
    return TM5.model_copy(update={"joints": tuple(joints)})


NARROW = narrow_j1_model()
#: The ready posture's pose: inside the narrow J1 range.
READY = TM5.forward(TM5.ready_joints_deg)


def ticks(backend: KinematicBackend, dt: float = 0.02) -> Iterator[None]:
    """Step until the motion is over, yielding after every step."""
    while backend.motion_running:
        backend.step(dt)
        yield


def fk_consistent(backend: KinematicBackend, mm: float = 1e-3) -> None:
    joints = backend.joint_positions_deg()
    assert joints is not None
    assert backend.flange_pose() == TM5.forward(joints)
    tcp = TM5.forward(joints, backend.tool)
    assert tcp.distance_to(backend.tcp_pose()) <= mm
    a, b = kin.pose_to_transform(tcp), kin.pose_to_transform(backend.tcp_pose())
    assert math.degrees(math.hypot(*kin.rotation_error(a, b))) <= mm


# -- the backend ---------------------------------------------------------------------------


@pytest.mark.parametrize("tool", [None, TOOL])
def test_the_joints_map_onto_the_flange_by_forward_kinematics_all_cycle_long(
    tool: Pose | None,
) -> None:
    backend = KinematicBackend(TM5, tool=tool)
    fk_consistent(backend)
    for target, motion in CYCLE:
        backend.start_motion(target, motion=motion, speed_percent=100, accel_time_s=ACCEL)
        for _ in ticks(backend):
            fk_consistent(backend)
        assert backend.tcp_pose() == target  # the commanded pose, exactly, at rest
        fk_consistent(backend)


def test_ptp_interpolates_the_joints_and_the_tcp_path_curves() -> None:
    backend = KinematicBackend(TM5, home=LIFT)
    start = backend.joint_positions_deg()
    assert start is not None
    end = TM5.inverse(PLACE, seed_deg=start)
    duration = backend.start_motion(
        PLACE, motion=MotionType.PTP, speed_percent=50, accel_time_s=ACCEL
    )
    # The numbers the master derives its timeouts from.
    assert duration == TM5.ptp_time(start, end, speed_percent=50, accel_time_s=ACCEL)
    assert duration == TM5.motion_time(
        LIFT, PLACE, speed_percent=50, motion=MotionType.PTP, start_joints_deg=start
    )
    backend.step(duration / 2)
    progress = trapezoid_progress(duration / 2, duration, ACCEL)
    assert progress == pytest.approx(0.5)
    expected = [a + (b - a) * progress for a, b in zip(start, end, strict=True)]
    assert list(backend.joint_positions_deg() or ()) == pytest.approx(expected, abs=1e-9)
    middle = backend.tcp_pose()
    assert middle == TM5.forward(expected)
    # Off the straight segment, and beyond what the article map can hold.
    assert middle.distance_to(Pose(300, 0, 225, 180, 0, 90)) > 20
    assert middle.x > ARTICLE_MAX
    backend.step(duration)
    assert backend.tcp_pose() == PLACE
    assert backend.joint_positions_deg() == end


def test_line_keeps_the_tcp_on_the_straight_segment_while_turning() -> None:
    start, target = Pose(300, -200, 200, 180, 0, 90), Pose(350, 0, 150, 180, 0, 45)
    backend = KinematicBackend(TM5, home=start, tool=TOOL)
    duration = backend.start_motion(
        target, motion=MotionType.LINE, speed_percent=30, accel_time_s=ACCEL
    )
    assert duration == TM5.line_time(
        start,
        target,
        speed_percent=30,
        accel_time_s=ACCEL,
        start_joints_deg=TM5.inverse(start, tool=TOOL),
        tool=TOOL,
    )
    a, b = kin.pose_to_transform(start), kin.pose_to_transform(target)
    length = start.distance_to(target)
    seen = 0
    for _ in ticks(backend, 0.01):
        pose = backend.tcp_pose()
        done = start.distance_to(pose) / length
        # On the segment: the point at that fraction, orientation turned as far.
        expected = kin.transform_to_pose(kin.interpolate(a, b, done))
        assert pose.distance_to(expected) < 1e-6
        assert pose.is_close(expected, mm=1e-6, deg=1e-6)
        fk_consistent(backend)
        seen += 1
    assert seen > 10
    assert backend.tcp_pose() == target


@pytest.mark.parametrize(
    ("model", "home", "target", "motion", "reason"),
    [
        (TM5, DEFAULT_HOME, Pose(900, 0, 300, 180, 0, 90), MotionType.PTP, "reach"),
        (TM5, DEFAULT_HOME, TM5_JOINT_LIMIT, MotionType.PTP, "joint_limit"),
        (TM5, DEFAULT_HOME, TM5_SINGULAR, MotionType.PTP, "singularity"),
        (NARROW, READY, Pose(0, 400, 200, 180, 0, 90), MotionType.PTP, "joint_limit"),
        # J3 = 0: the arm stretched straight.
        (TM5, DEFAULT_HOME, TM5.forward([0, 30, 0, 60, 90, 0]), MotionType.PTP, "singularity"),
        # The straight path passes the J1 axis, where no tool-down pose exists.
        (TM5, APPROACH, Pose(-300, 200, 200, 180, 0, 90), MotionType.LINE, "reach"),
    ],
)
def test_a_target_the_arm_cannot_take_is_refused_with_its_reason(
    model: RobotModel, home: Pose, target: Pose, motion: MotionType, reason: str
) -> None:
    backend = KinematicBackend(model, home=home)
    before = backend.joint_positions_deg()
    with pytest.raises(MotionRejectedError) as caught:
        backend.start_motion(target, motion=motion, speed_percent=100, accel_time_s=ACCEL)
    assert caught.value.reason == reason
    # Nothing moves.
    assert not backend.motion_running
    backend.step(1.0)
    assert (backend.joint_positions_deg(), backend.tcp_pose()) == (before, home)


def test_a_refusal_leaves_a_running_motion_alone() -> None:
    backend = KinematicBackend(TM5)
    backend.start_motion(PLACE, motion=MotionType.PTP, speed_percent=10, accel_time_s=ACCEL)
    backend.step(0.5)
    with pytest.raises(MotionRejectedError):
        backend.start_motion(
            Pose(900, 0, 300, 180, 0, 90), motion=MotionType.PTP, speed_percent=100, accel_time_s=0
        )
    assert backend.motion_running
    for _ in ticks(backend):
        pass
    assert backend.tcp_pose() == PLACE


def test_ptp_goes_where_a_line_cannot() -> None:
    backend = KinematicBackend(TM5, home=APPROACH)
    # rz -90: J6 ends near 20 deg (at rz 90 it passes -160 deg, where the end module's
    # camera meets wrist 1, a self-collision).
    target = Pose(-300, 200, 200, 180, 0, -90)
    backend.start_motion(target, motion=MotionType.PTP, speed_percent=100, accel_time_s=ACCEL)
    for _ in ticks(backend):
        fk_consistent(backend)
    assert backend.tcp_pose() == target


def test_an_unreachable_home_is_refused_naming_home() -> None:
    with pytest.raises(ValueError, match="home"):
        KinematicBackend(TM5, home=Pose(0, 0, 300, 180, 0, 0))  # the article's HOME


def test_the_tool_offset_is_the_tcp_in_the_flange_frame() -> None:
    backend = KinematicBackend(TM5, tool=TOOL)
    assert backend.tcp_pose() == DEFAULT_HOME
    flange = backend.flange_pose()
    assert flange is not None
    # Tool pointing down: the flange is 120 mm above the TCP.
    assert flange.is_close(DEFAULT_HOME.offset(dz=120), mm=1e-3, deg=1e-3)
    with pytest.raises(tmmaster.ConfigError, match="tool"):
        KinematicBackend(TM5, tool=(0, 0, 120, 0, 0, 0))  # type: ignore[arg-type]


# -- the controller ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("target", "code"),
    [
        (ARTICLE_HOME, SimErrorCode.UNREACHABLE),
        (TM5_JOINT_LIMIT, SimErrorCode.JOINT_LIMIT),
        (TM5_SINGULAR, SimErrorCode.SINGULARITY),
    ],
)
def test_article_reports_each_refusal_with_its_own_error_code(
    target: Pose, code: SimErrorCode
) -> None:
    ctl, bank, backend, log = article()
    send_article(bank, target)
    ctl.tick(DT)
    assert bank.get("error_code") == code
    assert bank.get("robot_mode") == 7
    assert (bank.get("command"), bank.get("motion_status")) == (0, 0)
    assert ctl.moves_started == 0
    assert backend.tcp_pose() == DEFAULT_HOME
    assert "sim.motion_started" not in log.names()


def test_tmflow_stops_in_error_on_a_line_through_the_base() -> None:
    # The target is reachable (inversekin), the straight path is not. On a robot Line()
    # returns false for a malformed command only (TMscript 2.24 p. 337): the robot stops
    # in error, "Inverse Kinematics Failure, Interpolation Points Issue" (0x12, TMflow
    # 2.24 appendix J, p. 349), and errorstop reports the command failed.
    ctl, bank, backend, _ = tmflow()
    send_tmflow(bank, 1, target=APPROACH)
    run_until(ctl, lambda: bank.get("done_seq") == 1)
    send_tmflow(bank, 2, command=2, target=Pose(-300, 200, 200, 180, 0, 90))
    run_until(ctl, lambda: bank.get("project_running") is False, limit_s=2.0)
    assert (bank.get("error"), bank.get("last_error_code")) == (True, 0x12)
    run_until(ctl, lambda: bank.get("result_code") != 0, limit_s=4 * DT)
    assert (bank.get("ack_seq"), bank.get("done_seq")) == (2, 1)
    assert (bank.get("result_code"), bank.get("robot_state")) == (3, 2)
    assert ctl.moves_started == 1
    assert backend.tcp_pose() == APPROACH


def test_the_article_cycle_passes_beyond_the_encodable_range_without_an_error() -> None:
    ctl, bank, backend, log = article()
    published, true = [], []
    for target, motion in CYCLE:
        send_article(bank, target, command=1 if motion is MotionType.PTP else 2)
        ctl.tick(DT)
        while bank.get("motion_status") == 1:
            ctl.tick(DT)
            published.append(bank.get("tcp_x"))
            true.append(backend.tcp_pose().x)
        assert bank.get("error_code") == 0, log.events[-3:]
        assert backend.tcp_pose() == target
    # The curved lift -> place passes x > 327.67: published saturated, kept true inside.
    assert max(true) > ARTICLE_MAX + 10
    assert max(published) == pytest.approx(ARTICLE_MAX)
    names = log.names()
    assert names.count("sim.pose_saturated") == 1
    assert names.count("sim.pose_in_range") == 1
    assert "sim.robot_error" not in names
    event = next(e for _, name, e in log.events if name == "sim.pose_saturated")
    assert event["fields"] == ["tcp_x"]


def test_an_arm_stopped_beyond_the_encodable_range_is_an_error_once() -> None:
    ctl, bank, backend, log = article()
    move_article(ctl, bank, LIFT)
    send_article(bank, PLACE)
    run_until(ctl, lambda: backend.tcp_pose().x > ARTICLE_MAX + 5)
    send_article(bank, PLACE, command=3)  # stop, where the registers cannot say
    ctl.tick(DT)
    # The arm brakes (a stop takes time): an error once it is at rest out of range.
    assert bank.get("error_code") == 0
    run_until(ctl, backend.is_settled)
    assert backend.tcp_pose().x > ARTICLE_MAX
    assert bank.get("error_code") == SimErrorCode.POSE_OUT_OF_RANGE
    assert bank.get("tcp_x") == pytest.approx(ARTICLE_MAX)
    assert "sim.pose_out_of_range" in log.names()
    # The operator's reset: no new error while the arm stays there, and it can move back.
    ctl.clear_error()
    run(ctl, 0.2)
    assert bank.get("error_code") == 0
    send_article(bank, DEFAULT_HOME)
    run_until(ctl, lambda: bank.get("command") == 0 and bank.get("motion_status") == 0)
    assert bank.get("error_code") == 0
    assert backend.tcp_pose() == DEFAULT_HOME
    assert bank.get("tcp_x") == pytest.approx(DEFAULT_HOME.x)


def test_an_estop_beyond_the_encodable_range_keeps_its_own_code() -> None:
    ctl, bank, backend, _ = article()
    move_article(ctl, bank, LIFT)
    send_article(bank, PLACE)
    run_until(ctl, lambda: backend.tcp_pose().x > ARTICLE_MAX + 5)
    ctl.press_estop()
    run(ctl, 0.5)  # the arm brakes to rest (a stop takes time), out of range
    assert backend.is_settled()
    assert backend.tcp_pose().x > ARTICLE_MAX
    assert bank.get("error_code") == SimErrorCode.EMERGENCY_STOP
    ctl.clear_error()
    run(ctl, 0.2)
    assert bank.get("error_code") == 0


# -- over Modbus ---------------------------------------------------------------------------


def floats(client: ModbusTcpClient, address: int, n: int) -> list[float]:
    reply = client.read_input_registers(address, count=2 * n, device_id=1)
    assert not reply.isError(), reply
    regs = reply.registers
    return [
        struct.unpack(">f", struct.pack(">HH", regs[i], regs[i + 1]))[0] for i in range(0, 2 * n, 2)
    ]


def test_joints_and_flange_read_over_modbus_agree_by_forward_kinematics(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    # 4x at the suite's 100 Hz: 0.04 simulated s a tick, the PTP below about 0.9 s
    # (~23 ticks in ~0.23 s of wall time), each tick read a few times (see the loop).
    sim = tm_simulator_factory("tmflow", cell=Cell(tool=TOOL), time_scale=4)
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    assert sim.tool == TOOL
    client = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=2)
    assert client.connect()
    try:
        # A PTP that swings the arm, commanded over Modbus like a master would.
        values: dict[str, Any] = dict(zip(TARGET_FIELDS, PLACE.as_list(), strict=True))
        values |= {"speed": 20, "accel_time": 0, "command": 1, "seq": 1}
        reply = client.write_registers(9000, words(sim.profile, values), device_id=1)
        assert not reply.isError(), reply
        sim.wait_for(lambda: sim.field("ack_seq") == 1, 2.0)
        # Read mid-motion, one request per sample: flange, joints and TCP (7001-7036)
        # come from the same tick.
        samples = 0
        while sim.field("done_seq") != 1:
            got = floats(client, 7001, 18)
            flange, joints, tcp = Pose(*got[:6]), got[6:12], Pose(*got[12:])
            model_flange = TM5.forward(joints)
            assert model_flange.distance_to(flange) <= 0.01
            assert model_flange.rotation_to(flange) <= 0.01
            assert TM5.forward(joints, TOOL).distance_to(tcp) <= 0.01
            samples += 1
            # A few reads per 10 ms tick are enough to see every tick; without a pause
            # the loop spent a core on about a thousand reads.
            time.sleep(0.002)
        assert samples >= 3
        assert sim.tcp_pose() == PLACE
    finally:
        client.close()


def test_the_cli_takes_a_tool_and_refuses_a_bad_one(capsys: pytest.CaptureFixture[str]) -> None:
    assert sim_main.main(["--tool", "0,0,120"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sim: --tool X,Y,Z,RX,RY,RZ")
    assert err.endswith("[exit 2]")
    assert "\n" not in err
    assert sim_main.main(["--tool", "0,0,x,0,0,0"]) == 2
    assert "--tool" in capsys.readouterr().err
    args = sim_main.build_parser().parse_args(["--tool", "0,0,120,0,0,0"])
    assert sim_main._tool(args.tool) == TOOL


def test_the_tool_is_the_cells_and_a_backend_of_ones_own_keeps_its_own() -> None:
    sim = Simulator(cell=Cell(tool=TOOL), listen=False)
    assert sim.tool == TOOL
    assert sim.call(sim.backend.tcp_pose) == sim.tcp_pose()
    own = Simulator(cell=KinematicBackend(TM5, tool=TOOL), listen=False)
    assert own.tool is None  # the simulator gives your backend nothing: it has its own
    with pytest.raises(tmmaster.ConfigError, match="cell must be a Cell or a PhysicsBackend"):
        Simulator(cell="kinematic", listen=False)  # type: ignore[arg-type]
    with pytest.raises(tmmaster.ConfigError, match="tool must be a Pose"):
        Cell(tool=(0, 0, 120, 0, 0, 0))  # type: ignore[arg-type]


class JointlessBackend(KinematicBackend):
    """A backend without a joint model that takes any target (the controller must check)."""

    def __init__(self) -> None:
        super().__init__(TM5)
        self.started: list[Pose] = []

    def joint_positions_deg(self) -> tuple[float, ...] | None:
        return None

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        self.started.append(target)
        return 1.0


@pytest.mark.parametrize(
    ("target", "code"),
    [
        (ARTICLE_HOME, SimErrorCode.UNREACHABLE),
        (TM5_JOINT_LIMIT, SimErrorCode.JOINT_LIMIT),
        (TM5_SINGULAR, SimErrorCode.SINGULARITY),
    ],
)
def test_a_backend_without_joints_gets_the_models_check(target: Pose, code: SimErrorCode) -> None:
    backend = JointlessBackend()
    ctl, bank, _, _ = article(backend=backend)
    send_article(bank, target)
    ctl.tick(DT)
    assert bank.get("error_code") == code
    assert backend.started == []


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_master_with_the_same_tool_drives_the_simulator_through_the_cycle(
    memory_simulator_factory: Callable[..., Simulator], profile: str
) -> None:
    # 100x with a 250 Hz tick (0.4 simulated s a tick, as the suite's 40x at 100 Hz): the
    # subject is where the tool puts the TCP, and each move now ends by the first poll.
    sim = memory_simulator_factory(profile, cell=Cell(tool=TOOL), **QUICK)
    # The article profile cannot read the robot's tool back: the test set both, so the
    # master is told it is checked (the tmflow master reads and checks it).
    checks = (
        tmmaster.Checks(frame=tmmaster.FrameCheck.off("the simulator is given the same tool"))
        if profile == "article"
        else None
    )
    with tmmaster.connect(sim.url, profile=profile, tool=TOOL, checks=checks) as robot:
        robot.wait_until_ready()
        for target, motion in CYCLE:
            robot.move_to(target, speed=100, motion=motion)
            assert sim.tcp_pose() == target
    assert sim.field("error_code" if profile == "article" else "last_error_code") == 0
    if profile == "tmflow":
        # Back home, tool down: the flange (7001-7012) is 120 mm above the TCP.
        flange = Pose(*(sim.field(f"flange_{a}") for a in ("x", "y", "z", "rx", "ry", "rz")))
        assert flange.is_close(DEFAULT_HOME.offset(dz=120), mm=1e-3, deg=1e-3)


#: From the home posture (shoulder, elbow, wrist: True, True, True), reachable only with
#: the wrist flipped (J5 -90): inversekin answers "by the current pose configuration"
#: (TMscript 2.24, p. 207), so the robot program finds it unreachable.
TM5_OTHER_CONFIGURATION = Pose(0, 200, 100, 180, 0, 90)


@pytest.mark.parametrize(
    ("target", "reason"),
    [
        (TM5_JOINT_LIMIT, "joint_limit"),
        (TM5_SINGULAR, "singularity"),
        (TM5_OTHER_CONFIGURATION, "configuration"),
    ],
)
def test_tmflow_reports_unreachable_and_logs_the_reason(target: Pose, reason: str) -> None:
    ctl, bank, _, log = tmflow()
    send_tmflow(bank, 1, target=target)
    # Within a tick or two (the program's time budget per tick may end after inversekin,
    # or between the result and the state it writes next).
    run_until(ctl, lambda: bank.get("robot_state") == 2, limit_s=4 * DT)
    assert (bank.get("ack_seq"), bank.get("done_seq")) == (1, 0)
    # The profile's result_code has no joint_limit / singularity label: unreachable.
    assert (bank.get("result_code"), bank.get("robot_state")) == (1, 2)
    assert any(
        name == "sim.command_rejected" and fields.get("reason") == reason
        for _, name, fields in log.events
    )


@pytest.mark.parametrize(
    ("start", "target", "speed"),
    [
        # The worst of 84 Lines between seven poses (at 30 %, sampled every 1 ms: 1.0003x).
        (Pose(200, 250, 150, 180, 0, 45), Pose(150, -300, 200, 180, 0, 90), 100),
        (Pose(300, -200, 200, 180, 0, 90), Pose(300, 200, 200, 180, 0, 90), 100),
        (Pose(450, 0, 250, 180, 0, 0), Pose(150, -300, 200, 180, 0, 90), 100),
    ],
)
def test_a_line_never_drives_a_joint_past_its_speed(start: Pose, target: Pose, speed: int) -> None:
    # Sampled densely (every 5 ms, the ramps last 200 ms): the joints' rates between two
    # samples stay within their limits scaled by the speed, where the TCP speeds up or the
    # path passes near the base.
    backend = KinematicBackend(TM5, home=start)
    backend.start_motion(target, motion=MotionType.LINE, speed_percent=speed, accel_time_s=ACCEL)
    limits = [s * speed / 100 for s in TM5.joint_speed_deg_s]
    dt = 0.005
    before = backend.joint_positions_deg()
    assert before is not None
    worst = 0.0
    while backend.motion_running:
        backend.step(dt)
        joints = backend.joint_positions_deg()
        assert joints is not None
        rates = [
            abs(b - a) / dt / limit for a, b, limit in zip(before, joints, limits, strict=True)
        ]
        worst = max(worst, *rates)
        before = joints
    assert backend.tcp_pose() == target
    assert 0.9 < worst <= 1.005  # one joint runs at its limit, none beyond
