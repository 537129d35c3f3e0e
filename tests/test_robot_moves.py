"""Joint moves, relative moves, arcs and TCP speeds, against the robot program itself.

Each new command is checked end to end (the simulator runs the generated robot program),
refused before any byte when it may not run, and given up safely when its wait ends
early (withdrawn before the robot took it, stopped once it runs).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest

import tmmaster
from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from sim_speeds import QUICK
from tmmaster import Checks, PollPolicy, Pose, Robot, TimeoutPolicy, robot_model
from tmmaster._codec import Value
from tmmaster._kinematics import Arc
from tmmaster.sim import Cell, KinematicBackend, Simulator, Timing

SimFactory = Callable[..., Simulator]

START = Pose(300, -200, 200, 180, 0, 90)
VIA = Pose(350, -150, 200, 180, 0, 90)
END = Pose(400, -200, 200, 180, 0, 90)
READY = (0.0, 0.0, 90.0, 0.0, 90.0, 0.0)


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: SimFactory) -> SimFactory:
    """The robot API is the subject here, not TCP: simulators in memory."""
    return memory_simulator_factory


def command_writes(sim: Simulator) -> list[tuple[int, ...]]:
    """Values of every FC16 write that reached the tmflow command block (9000)."""
    return [
        tuple(r.values or ())
        for r in sim.request_log
        if r.function_code == 16 and r.address == 9000 and not r.refused
    ]


def new_command(robot: Robot, kind: str, **options: Any) -> None:
    """Send one of the new commands: a joint move, an arc, or a Line in mm/s."""
    if kind == "joints":
        robot.move_joints(READY, speed=50, **options)
    elif kind == "arc":
        robot.move_arc(VIA, END, speed=50, **options)
    else:
        robot.move_to(END, motion="line", speed_mm_s=300, **options)


def writes(sim: Simulator) -> list[Any]:
    """Every write request the simulator saw."""
    return [r for r in sim.request_log if r.function_code in (5, 6, 15, 16)]


# -- the simulated arm ----------------------------------------------------------------


def test_the_kinematic_backend_follows_the_arc() -> None:
    model = robot_model("tm5-700")
    backend = KinematicBackend(model, home=START)
    duration = backend.start_arc_motion(VIA, END, speed_percent=20, accel_time_s=0.2)
    arc = Arc.through(START, VIA, END)
    closest = math.inf
    elapsed = 0.0
    while backend.motion_running:
        backend.step(0.01)
        elapsed += 0.01
        p = backend.tcp_pose()
        assert math.dist((p.x, p.y, p.z), arc.centre) == pytest.approx(arc.radius_mm, abs=0.05)
        closest = min(closest, p.distance_to(VIA))
    assert elapsed == pytest.approx(duration, abs=0.011)
    assert closest < 1.0  # it passed the via point
    assert backend.tcp_pose() == END
    with pytest.raises(tmmaster.sim.MotionRejectedError):
        backend.start_joint_motion((0, 0, 90, 0, 0, 0), speed_percent=20, accel_time_s=0.2)


# -- status().joints ----------------------------------------------------------------


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_status_reports_the_joints_where_the_profile_publishes_them(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile, **QUICK)
    robot = robots(sim)
    status = robot.status()
    if profile == "article":
        assert status.joints is None
        return
    assert status.joints is not None
    assert robot.model.forward(status.joints).is_close(status.pose, mm=0.01, deg=0.01)


# -- move_joints ----------------------------------------------------------------------


def test_move_joints_runs_a_joint_ptp_to_exactly_those_joints(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory(**QUICK)
    robot = robots(sim)
    sim.clear_request_log()
    motion = robot.move_joints([10, -5, 100, -5, 90, 10], speed=40)
    status = robot.status()
    assert status.joints == pytest.approx((10, -5, 100, -5, 90, 10), abs=1e-4)
    assert motion.target is not None
    assert status.pose.is_close(robot.model.forward((10, -5, 100, -5, 90, 10)), mm=0.01)
    (write,) = command_writes(sim)
    # The whole block, one request: the extension no one's (ext_seq 0), then the session
    # and the program's start (boot_id) the master read.
    assert len(write) == 32
    assert write[14] == robot.profile.field("command").code_of("ptp_joints")
    assert write[16:30] == (0,) * 14
    assert write[30] == robot._heartbeat.session
    (record,) = sim.motion_log()
    assert record.kind == "ptp_joints"
    # Timed from the joints the robot reported: the model's joint-space time.
    start = robot.model.inverse(sim_home(sim))
    assert motion.expected_s == pytest.approx(
        robot.model.ptp_time(start, (10, -5, 100, -5, 90, 10), speed_percent=40), rel=0.01
    )


def sim_home(sim: Simulator) -> Pose:
    """The simulator's first pose (where its motion log's first move started)."""
    return tmmaster.sim.DEFAULT_HOME


def test_move_joints_arrival_is_checked_on_the_joints(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], monkeypatch: pytest.MonkeyPatch
) -> None:
    sim = tm_simulator_factory(**QUICK)
    robot = robots(sim)
    channel = robot._channel
    real = channel._note_plan_read  # the read of the pose and joints after a done

    def other_branch(values: dict[str, Value]) -> tuple[Pose, tuple[float, ...] | None]:
        pose, joints = real(values)
        assert joints is not None
        return pose, (joints[0] + 5.0, *joints[1:])  # the TCP agrees, a joint does not

    robot.move_joints(READY, speed=50)
    monkeypatch.setattr(channel, "_note_plan_read", other_branch)
    with pytest.raises(tmmaster.RobotError, match="joints"):
        robot.move_joints([5, 0, 95, 0, 90, 0], speed=50)


# -- move_by -------------------------------------------------------------------------


def test_move_by_resolves_against_the_reported_pose_in_the_base_and_the_tool_frame(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    tool = Pose(0, 0, 100, 0, 0, 0)
    sim = tm_simulator_factory(cell=Cell(tool=tool), **QUICK)
    robot = robots(sim, tool=tool)
    robot.move_to(START, speed=50)
    moved = robot.move_by(dx=20, dz=-30, motion="line", speed_mm_s=200)
    assert moved.start is not None
    assert moved.start.is_close(START, mm=0.01)
    assert sim.tcp_pose().is_close(Pose(320, -200, 170, 180, 0, 90), mm=0.01)
    # The tool points down (rx = 180): +z of the tool is down in the base.
    robot.move_by(dz=10, frame="tool")
    assert sim.tcp_pose().is_close(Pose(320, -200, 160, 180, 0, 90), mm=0.01)
    # A turn about the base's z, in place.
    robot.move_by(drz=-30)
    assert sim.tcp_pose().is_close(Pose(320, -200, 160, 180, 0, 60), mm=0.01)
    assert [r.kind for r in sim.motion_log()] == ["ptp", "line", "ptp", "ptp"]


def test_move_by_works_on_the_article_profile_too(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article", **QUICK)
    robot = robots(sim)
    robot.move_to(START, speed=50)
    robot.move_by(dy=20, dz=-30, motion="line", speed=20)
    assert sim.tcp_pose().is_close(Pose(300, -180, 170, 180, 0, 90), mm=0.01)


def test_move_by_refuses_when_the_arm_moved_after_the_read(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], monkeypatch: pytest.MonkeyPatch
) -> None:
    sim = tm_simulator_factory(**QUICK)
    robot = robots(sim)
    robot.move_to(START, speed=50)
    channel = robot._channel
    real = channel.read_plan
    reads = 0

    def elsewhere_first() -> tuple[Pose, tuple[float, ...] | None, dict[str, Value]]:
        # The move_by's reads (away from the last target, it reads until two agree) see
        # the arm elsewhere; the read before the write sees it back.
        nonlocal reads
        reads += 1
        pose, joints, values = real()
        return (pose.offset(dx=5) if reads <= 2 else pose), joints, values

    monkeypatch.setattr(channel, "read_plan", elsewhere_first)
    sim.clear_request_log()
    with pytest.raises(tmmaster.RobotError, match="moved"):
        robot.move_by(dz=10)
    assert writes(sim) == []
    assert len(sim.motion_log()) == 1


# -- move_arc ------------------------------------------------------------------------


def test_move_arc_runs_a_circle_through_the_via_point(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory(**QUICK)
    robot = robots(sim)
    robot.move_to(START, speed=50)
    sim.clear_request_log()
    motion = robot.move_arc(VIA.offset(dz=0), END, speed_mm_s=150)
    assert sim.tcp_pose().is_close(END, mm=0.01)
    assert sim.motion_log()[-1].kind == "circle"
    (write,) = command_writes(sim)
    assert len(write) == 32  # the block, its extension, the session and boot: one request
    assert write[14] == robot.profile.field("command").code_of("circle")
    assert write[28] == 150  # speed_mm_s
    assert write[29] == write[15]  # ext_seq: the command's own number
    arc = Arc.through(START, VIA, END)
    expected = robot.model.arc_time(
        START, VIA, END, speed_percent=150 * 100 / robot.model.tcp_speed_mm_s
    )
    assert motion.expected_s == pytest.approx(expected, rel=0.01)
    assert arc.length_mm == pytest.approx(math.pi * 50)


def test_the_vias_orientation_is_the_one_the_tcp_has_there(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory(**QUICK)
    robot = robots(sim)
    robot.move_to(START, speed=50)
    turned_end = Pose(400, -200, 200, 180, 0, 120)
    motion = robot.move_arc(Pose(350, -150, 200, 0, 0, 0), turned_end, speed=20)
    via = motion.command.via
    assert via is not None
    assert via.distance_to(VIA) < 1e-6
    assert via.rotation_to(Pose(0, 0, 0, 180, 0, 105)) < 1e-3  # half way from 90 to 120
    assert sim.tcp_pose().is_close(turned_end, mm=0.01)


def test_an_arc_below_the_table_plane_is_refused_before_any_write(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory(**QUICK)
    # The TCP's own path against the plane (no tool extent round it).
    robot = robots(
        sim, checks=Checks(workspace=tmmaster.Workspace(floor_z_mm=150, tool_extent_mm=None))
    )
    low_start = Pose(300, -200, 160, 180, 0, 90)
    robot.move_to(low_start, speed=50)
    sim.clear_request_log()
    # Every point given is above z = 150, but the circle through them bottoms out at
    # z = 147.8 between the via and the end.
    with pytest.raises(tmmaster.ConfigError, match=r"arc .* passes .*table plane"):
        robot.move_arc(Pose(320, -200, 152, 180, 0, 90), Pose(400, -200, 160, 180, 0, 90))
    assert writes(sim) == []


@pytest.mark.parametrize("method", ["move_joints", "move_arc"])
def test_the_article_profile_refuses_joint_moves_and_arcs_naming_itself(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], method: str
) -> None:
    sim = tm_simulator_factory("article", **QUICK)
    robot = robots(sim)
    sim.clear_request_log()
    with pytest.raises(tmmaster.ConfigError, match="profile 'article'"):
        new_command(robot, "joints" if method == "move_joints" else "arc")
    with pytest.raises(tmmaster.ConfigError, match="profile 'article'"):
        robot.move_to(START, motion="line", speed_mm_s=100)
    assert sim.request_log == []


# -- speeds and acceleration ----------------------------------------------------------


def test_a_lines_tcp_speed_in_mm_s_reaches_the_program(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory(**QUICK)
    robot = robots(sim)
    robot.move_to(START, speed=50)
    backend = sim.backend
    seen: list[float] = []
    real = backend.start_motion

    def recording(target: Pose, **kw: Any) -> float:
        seen.append(kw["speed_percent"])
        return real(target, **kw)

    backend.start_motion = recording  # type: ignore[method-assign]
    sim.clear_request_log()
    motion = robot.move_to(START.offset(dz=-80), motion="line", speed_mm_s=55)
    assert seen == [pytest.approx(55 * 100 / robot.model.tcp_speed_mm_s)]
    (write,) = command_writes(sim)
    assert write[12] == 5  # the percent it is, rounded up (55 of 1100 mm/s)
    assert write[28] == 55
    assert motion.expected_s == pytest.approx(
        robot.model.line_time(START, START.offset(dz=-80), speed_percent=5.0), rel=0.01
    )
    # A line in % writes the extension too, speed_mm_s 0: a stale one never applies.
    sim.clear_request_log()
    robot.move_to(START, motion="line", speed=30)
    (write,) = command_writes(sim)
    assert (write[28], write[29]) == (0, write[15])
    assert seen[-1] == pytest.approx(30.0)


def test_the_acceleration_time_reaches_the_program_and_the_expected_time(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory(**QUICK)
    robot = robots(sim)
    backend = sim.backend
    seen: list[float] = []
    real = backend.start_motion

    def recording(target: Pose, **kw: Any) -> float:
        seen.append(kw["accel_time_s"])
        return real(target, **kw)

    backend.start_motion = recording  # type: ignore[method-assign]
    robot.move_to(START, speed=50)
    slow = robot.move_to(END, speed=50, accel_time_ms=1500)
    assert seen == [pytest.approx(0.2), pytest.approx(1.5)]
    model = robot.model
    first = model.inverse(START)
    last = model.inverse(END, seed_deg=first)
    expected = model.ptp_time(first, last, speed_percent=50, accel_time_s=1.5)
    assert slow.expected_s == pytest.approx(expected, rel=0.01)
    assert expected > model.ptp_time(first, last, speed_percent=50) + 0.3
    assert slow.accel_s == pytest.approx(1.5)


# -- given up safely -----------------------------------------------------------------


@pytest.mark.parametrize("kind", ["joints", "arc", "line_mm_s"])
def test_a_new_command_not_acknowledged_is_withdrawn_and_never_runs(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], kind: str
) -> None:
    # The ack would come 14 simulated s = 0.35 wall s after the robot sees the command,
    # 0.2 s after the master's 0.15 s ack timeout.
    sim = tm_simulator_factory(faults=["late_ack:delay_s=14,at_move=2"])
    robot = robots(sim, timeouts=TimeoutPolicy(ack_timeout_s=0.15))
    robot.move_to(START, speed=80)
    ticks = sim.ticks
    with pytest.raises(tmmaster.AcknowledgeTimeoutError):
        new_command(robot, kind)
    motion = robot.last_motion
    assert motion is not None
    assert motion.withdrawn is True or motion.stop_delivered is True
    # 22 simulated s after the write (8 s past the late ack), on the simulator's clock.
    sim.wait_for(lambda: sim.ticks >= ticks + 55, 5.0)
    assert len(sim.motion_log()) == 1
    assert sim.tcp_pose().is_close(START, mm=0.01)


@pytest.mark.parametrize("kind", ["joints", "arc"])
def test_a_new_move_that_stalls_is_stopped(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], kind: str
) -> None:
    sim = tm_simulator_factory(faults=["stall:at_move=2"])
    robot = robots(sim)
    robot.move_to(START, speed=80)
    with pytest.raises(tmmaster.MotionTimeoutError):
        new_command(robot, kind, timeout=0.3)
    motion = robot.last_motion
    assert motion is not None
    assert motion.stop_delivered is True
    stops = [r for r in sim.request_log if r.function_code == 5 and r.address == 7105]
    assert stops
    assert not sim.tcp_pose().is_close(END if kind == "arc" else START, mm=1.0)


@pytest.mark.parametrize("kind", ["joints", "arc"])
def test_a_held_frame_of_a_new_command_never_runs_after_the_master_gave_up(kind: str) -> None:
    # As test_8_1 (test_safety_regressions.py) for a PTP: the command write is held in
    # the network until the master gave up, the resend (the same number) dropped; the
    # master gives up and cancels the number, so the frame that lands later can never
    # run. Released by the test, not after a time: a loaded machine took the master past
    # a 0.9 s hold, and the frame landed before it gave up.
    issued: list[Issued] = []
    with (
        Simulator("tmflow", time_scale=20.0, timing=Timing(tick_hz=50.0)) as sim,
        FaultProxy(sim.port) as proxy,
        Robot(
            "127.0.0.1",
            proxy.port,
            # 0.5 s, not 0.15 s: a connect's first read is not retried, and 0.15 s went
            # unanswered beside CPU hogs. The held write times out all the same.
            timeouts=TimeoutPolicy(request_s=0.5, ack_timeout_s=0.5, motion_margin_s=1.0),
            retry=tmmaster.RetryPolicy(attempts=8, total_time_s=3.0, initial_backoff_s=0.02),
            polling=PollPolicy(interval_s=0.01),
        ) as robot,
    ):
        first = Issued(START, time.monotonic())
        robot.move_to(START, speed=80)
        first.outcome, first.ended_at = "done", time.monotonic()
        issued.append(first)
        release = threading.Event()
        proxy.add(Rule("hold", function_code=16, address=9000, release=release))
        proxy.add(Rule("drop_request", function_code=16, address=9000, nth=1))
        given_up = Issued(END if kind == "arc" else robot.model.forward(READY), time.monotonic())
        issued.append(given_up)
        with pytest.raises(tmmaster.TMMasterError) as info:
            new_command(robot, kind)
        given_up.outcome, given_up.ended_at = type(info.value).__name__, time.monotonic()
        landed = len([r for r in sim.request_log if r.function_code == 16 and r.address == 9000])
        release.set()
        sim.wait_for(
            lambda: (
                len([r for r in sim.request_log if r.function_code == 16 and r.address == 9000])
                > landed
            ),
            timeout=5.0,
        )
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 5, timeout=5.0)  # 2 simulated s
        last = Issued(START.offset(dz=-20), time.monotonic())
        robot.move_to(last.target, speed=80)
        last.outcome, last.ended_at = "done", time.monotonic()
        issued.append(last)
        check(issued, sim.motion_log())
        assert [r.kind for r in sim.motion_log()] == ["ptp", "ptp"]
