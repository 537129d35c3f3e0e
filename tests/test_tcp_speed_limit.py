"""The robot's TCP speed limit: the master refuses a PTP past it, the simulator stops one.

[TMF]: TMflow Software Manual 2.24, Rev 1.00. Its Performance Safety "TCP Speed" limit
is 1500 mm/s by default, settable up to 4500 (Appendix B, p. 285 for the TM5-700), and a
stop criterion (3 Safety Settings, Speed & Force, p. 38); "the PTP mode may cause the
TCP to exceed speed limit" (9 Speed of PTP Motion, p. 169). A robot that stops for it
reports 0x0021 "Velocity or Angular Velocity Over Range" (Appendix J, pp. 349 and 409).
"""

from __future__ import annotations

import pytest

import tmmaster
from sim_backends import BACKENDS
from sim_speeds import QUICK
from tmmaster import Checks, ConfigError, PollPolicy, Pose, Robot, robot_model
from tmmaster.sim import KinematicBackend, RobotSetup, Simulator
from tmmaster.sim._backend import PhysicsBackend
from tmmaster.sim._controller import SimErrorCode

ARM = robot_model("tm5-700")
#: A J1 swing of 120 deg, the arm half stretched, the tool down: about 1870 mm/s at 100 %
#: (tests/test_hunt_fidelity.py), 1494 mm/s at 80 %, 1512 mm/s at 81 %.
SWING_FROM = (-60.0, 30.0, 60.0, 0.0, 90.0, 0.0)
SWING_TO = (60.0, 30.0, 60.0, 0.0, 90.0, 0.0)
FROM_POSE, TO_POSE = ARM.forward(SWING_FROM), ARM.forward(SWING_TO)
LIMIT = 1500.0


def _robot(**checks: object) -> Robot:
    return Robot("127.0.0.1", 1, profile="tmflow", checks=Checks(**checks))  # never connected


def test_every_model_carries_the_manuals_default_limit() -> None:
    for name in ("tm5-700", "tm5-900", "tm12", "tm14"):
        assert robot_model(name).tcp_speed_limit_mm_s == LIMIT


def test_the_swing_passes_just_under_the_limit_and_is_refused_just_over_it() -> None:
    robot = _robot()
    assert max(ARM.ptp_tcp_speeds(SWING_FROM, SWING_TO, 80, None, None)) < LIMIT
    robot.check_move(TO_POSE, 80, "ptp", seed_deg=SWING_FROM)
    with pytest.raises(ConfigError, match=r"PTP at 81 % would move the TCP at 15\d\d mm/s"):
        robot.check_move(TO_POSE, 81, "ptp", seed_deg=SWING_FROM)


def test_a_raised_limit_lets_the_full_speed_swing_pass() -> None:
    robot = _robot(tcp_speed_limit_mm_s=2000)
    assert robot.checks.tcp_speed_limit_mm_s == 2000
    robot.check_move(TO_POSE, 100, "ptp", seed_deg=SWING_FROM)
    with pytest.raises(ConfigError, match=r"= 1800\)"):
        _robot(tcp_speed_limit_mm_s=1800).check_move(TO_POSE, 100, "ptp", seed_deg=SWING_FROM)


@pytest.mark.parametrize("value", [0, -1, 4501, float("nan"), True, "3000"])
def test_a_limit_outside_the_manuals_range_is_refused_naming_the_field(value: object) -> None:
    with pytest.raises(ConfigError, match=r"checks\.tcp_speed_limit_mm_s"):
        Checks(tcp_speed_limit_mm_s=value)
    with pytest.raises(ConfigError, match=r"^tcp_speed_limit_mm_s must be a number in \(0, 4500\]"):
        RobotSetup(tcp_speed_limit_mm_s=value)  # type: ignore[arg-type]


def test_a_line_between_the_same_ends_is_not_held_to_the_ptp_limit() -> None:
    # A Line's TCP runs at its commanded speed, at most the model's Line speed at 100 %
    # (1100 mm/s for a TM5-700), under the limit: only the PTP is refused.
    start, end = (-20.0, 30.0, 60.0, 0.0, 90.0, 0.0), (20.0, 30.0, 60.0, 0.0, 90.0, 0.0)
    robot = _robot()
    with pytest.raises(ConfigError, match=r"tcp_speed_limit_mm_s"):
        robot.check_move(ARM.forward(end), 100, "ptp", seed_deg=start)
    robot.check_move(ARM.forward(end), 100, "line", start=ARM.forward(start), seed_deg=start)
    robot.check_move(ARM.forward(end), 100, "line", seed_deg=start)  # no start: no path


def _swing_backend(
    speed: float, limit: float | None = None, name: str = "kinematic"
) -> KinematicBackend:
    """The simulator's arm, its limit ``limit`` (None: the model's), starting the swing."""
    arm = ARM if limit is None else ARM.model_copy(update={"tcp_speed_limit_mm_s": limit})
    if name == "kinematic":
        backend = KinematicBackend(arm, home=FROM_POSE)
    else:
        from tmmaster.sim._mujoco import MuJoCoBackend

        backend = MuJoCoBackend(arm, home=FROM_POSE)  # type: ignore[assignment]
    backend.start_joint_motion(SWING_TO, speed_percent=speed, accel_time_s=0.2)
    return backend


def _run(backend: PhysicsBackend, step_s: float) -> tuple[float, list[str]]:
    """Step ``backend`` until the arm rests: its TCP's top speed measured step by step
    (mm/s) and the faults it handed over."""
    top, faults, before = 0.0, [], backend.tcp_pose()
    for _ in range(int(5 / step_s)):
        backend.step(step_s)
        if (fault := backend.take_fault()) is not None:
            faults.append(fault.kind)
        top = max(top, before.distance_to(before := backend.tcp_pose()) / step_s)
        if backend.is_settled():
            break
    return top, faults


def test_the_simulated_arm_never_runs_its_tcp_past_the_limit_it_stops_at() -> None:
    fine = _swing_backend(100)
    top, faults = _run(fine, 0.001)
    assert faults == ["speed"]
    assert LIMIT * 0.95 < top < LIMIT * 1.01  # braked from the limit, never far past it
    stopped = fine.joint_positions_deg()
    assert stopped is not None
    assert -45 < stopped[0] < 0  # on its way, far from the target's 60 deg
    # Where it stops does not depend on the tick (a tick may carry it further: it is put
    # back where its TCP passed the limit, and brakes from there).
    coarse = _swing_backend(100)
    assert _run(coarse, 0.4)[1] == ["speed"]
    assert coarse.joint_positions_deg() == pytest.approx(stopped, abs=1e-6)


@pytest.mark.parametrize("backend_name", BACKENDS)
@pytest.mark.parametrize(("speed", "stops"), [(80, False), (81, True)])
def test_the_simulator_stops_exactly_the_ptps_the_master_refuses(
    backend_name: str, speed: int, stops: bool
) -> None:
    backend = _swing_backend(speed, name=backend_name)
    faults = _run(backend, 0.02)[1]
    assert faults == (["speed"] if stops else [])
    joints = backend.joint_positions_deg()
    assert joints is not None
    assert (joints[0] < 0) is stops  # stopped on its way, or at the target's 60 deg
    refused = max(ARM.ptp_tcp_speeds(SWING_FROM, SWING_TO, speed, None, None)) > LIMIT
    assert refused is stops


def test_a_cell_with_a_raised_limit_runs_the_full_speed_swing() -> None:
    raised = 2000.0
    backend = _swing_backend(100, raised)
    assert _run(backend, 0.02)[1] == []
    assert backend.tcp_pose().is_close(TO_POSE, mm=0.01)
    setup = RobotSetup(tcp_speed_limit_mm_s=raised)
    assert setup.arm.tcp_speed_limit_mm_s == raised
    with (
        Simulator("tmflow", robot=setup, listen=False, **QUICK) as sim,
        tmmaster.connect(
            sim.url, profile="tmflow", checks=Checks(tcp_speed_limit_mm_s=raised)
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_joints(SWING_FROM, speed=50)
        robot.move_joints(SWING_TO, speed=100)
        assert sim.tcp_pose().is_close(TO_POSE, mm=0.1)
        assert sim.field("last_error_code") == 0


def test_a_master_set_above_the_robots_limit_sends_the_ptp_and_the_robot_stops_it() -> None:
    with (
        Simulator("tmflow", listen=False, **QUICK) as sim,
        tmmaster.connect(
            sim.url,
            profile="tmflow",
            polling=PollPolicy(interval_s=0.01),
            checks=Checks(tcp_speed_limit_mm_s=4500),  # the robot's own is the default
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_joints(SWING_FROM, speed=50)
        with pytest.raises(tmmaster.RobotFaultError) as caught:
            robot.move_joints(SWING_TO, speed=100)
        assert caught.value.error_code == SimErrorCode.OVER_SPEED == 0x21
        assert "Velocity or Angular Velocity Over Range" in str(caught.value)
        # The arm stopped on its way (it never reached the target), and stays stopped.
        assert not sim.tcp_pose().is_close(TO_POSE, mm=50)
        joints = sim.call(sim.backend.joint_positions_deg)
        assert joints is not None
        assert -45 < joints[0] < 0
        record = sim.motion_log()[-1]
        assert record.kind == "ptp_joints"
        assert record.done_wall_time is None  # stopped by the error, never reported done
        rest, ticks = sim.tcp_pose(), sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 10)  # 10 ticks later, 4 s simulated
        status = robot.status()
        assert status.pose.is_close(rest, mm=0.01)
        assert sim.tcp_pose() == rest
        assert sim.field("last_error_code") == 0x21
        assert len(sim.motion_log()) == 2  # nothing started since


def test_the_master_refuses_a_move_joints_past_the_limit_before_sending_it() -> None:
    with (
        Simulator("tmflow", listen=False, **QUICK) as sim,
        tmmaster.connect(sim.url, profile="tmflow") as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_joints(SWING_FROM, speed=50)
        with pytest.raises(ConfigError, match=r"checks\.tcp_speed_limit_mm_s = 1500\)"):
            robot.move_joints(SWING_TO, speed=100)
        with pytest.raises(ConfigError, match=r"checks\.tcp_speed_limit_mm_s"):
            robot.move_to(TO_POSE, speed=100)
        assert len(sim.motion_log()) == 1  # neither was sent
        robot.move_joints(SWING_TO, speed=80)
        assert sim.tcp_pose().is_close(TO_POSE, mm=0.1)


def test_the_limit_is_held_to_the_project_speeds_share_of_the_move() -> None:
    # TMflow runs a move at its speed times the project speed: at 85 %, a 100 % PTP runs
    # at 85 % (1587 mm/s: refused), a 90 % one at 76.5 % (1428 mm/s: sent, and it runs).
    with (
        Simulator("tmflow", robot=RobotSetup(project_speed=85), listen=False, **QUICK) as sim,
        tmmaster.connect(sim.url, profile="tmflow") as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_joints(SWING_FROM, speed=50)
        with pytest.raises(ConfigError, match=r"PTP at 85 %"):
            robot.move_joints(SWING_TO, speed=100)
        robot.move_joints(SWING_TO, speed=90)
        assert sim.tcp_pose().is_close(TO_POSE, mm=0.1)
        assert sim.field("last_error_code") == 0


def test_a_first_move_from_joints_the_master_did_not_know_is_checked_before_the_write() -> None:
    # article publishes no joints: the check before the move has no start to plan from,
    # so the plan made from the pose the robot reports (read before the write) refuses it.
    target = Pose(200, 300, 100, 180, 0, 90)  # from the ready posture: 1509 mm/s at 100 %
    with (
        Simulator("article", listen=False, **QUICK) as sim,
        tmmaster.connect(sim.url, profile="article", gripper=None) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.check_move(target, 100)  # nothing to plan from yet: passes
        with pytest.raises(ConfigError, match=r"checks\.tcp_speed_limit_mm_s = 1500\)"):
            robot.move_to(target, speed=100)
        assert not sim.motion_log()  # nothing was sent
        robot.move_to(target, speed=90)
        assert sim.tcp_pose().is_close(target, mm=0.1)
        assert sim.field("error_code") == 0
