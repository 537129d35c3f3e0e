"""The project speed: TMflow runs every move at its speed times the project's (7101).

The simulator has the setting (``RobotSetup(project_speed=...)``) and behaves so; the
master reads 7101 at connect (and with every status) and plans its expected times and
derived timeouts with it, so a project at 50 % and an arm slower than the model give no
false MotionTimeoutError.
"""

from __future__ import annotations

import threading
import time

import pytest

from sim_backends import BACKENDS
from sim_speeds import QUICK
from test_sim_controller import MODEL, run_until, send_tmflow, tmflow
from tmmaster import ConfigError, MotionType, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster._channels import Command, CommandKind, Ticket
from tmmaster._command import Motion, _MotionFollower
from tmmaster._following import FollowState
from tmmaster._logging import get_logger
from tmmaster._planning import Plan
from tmmaster.sim import Cell, RobotSetup, Simulator

LEFT = Pose(300, -200, 200, 180, 0, 90)
RIGHT = Pose(300, 200, 200, 180, 0, 90)


def simulated_seconds_of_a_move(project_speed: int) -> float:
    ctl, bank, _, _ = tmflow()
    bank.set("project_speed", project_speed)  # the operator's setting, as 7101 holds it
    run_until(ctl, lambda: bank.get("robot_state") == 0)
    send_tmflow(bank, 1, target=RIGHT, speed=50)
    run_until(ctl, lambda: bank.get("ack_seq") == 1, limit_s=2.0)
    started = ctl.time_s  # type: ignore[attr-defined]
    run_until(ctl, lambda: bank.get("done_seq") == 1, limit_s=60.0)
    return float(ctl.time_s) - started  # type: ignore[attr-defined]


def test_the_simulated_project_speed_scales_every_move() -> None:
    full, half = simulated_seconds_of_a_move(100), simulated_seconds_of_a_move(50)
    # Motion speed x project speed: twice as long at 50 % (the acceleration aside).
    assert 1.6 < half / full < 2.2


def simulated_seconds_with_a_change(first: int, then: int, physics: str) -> float:
    """A move started at project speed ``first``, 7101 set to ``then`` 0.3 s into it."""
    if physics == "mujoco":
        from tmmaster.sim._mujoco import MuJoCoBackend

        ctl, bank, _, _ = tmflow(backend=MuJoCoBackend(MODEL))  # type: ignore[arg-type]
    else:
        ctl, bank, _, _ = tmflow()
    bank.set("project_speed", first)
    run_until(ctl, lambda: bank.get("robot_state") == 0)
    send_tmflow(bank, 1, target=RIGHT, speed=50)
    run_until(ctl, lambda: bank.get("ack_seq") == 1, limit_s=2.0)
    started = ctl.time_s  # type: ignore[attr-defined]
    run_until(ctl, lambda: ctl.time_s - started >= 0.3)  # type: ignore[attr-defined]
    bank.set("project_speed", then)  # the operator's + or - on the Robot Stick
    run_until(ctl, lambda: bank.get("done_seq") == 1, limit_s=60.0)
    return float(ctl.time_s) - started  # type: ignore[attr-defined]


@pytest.mark.parametrize("physics", BACKENDS)
def test_a_project_speed_changed_mid_move_applies_to_the_running_move(physics: str) -> None:
    # TMflow 2.24, 4.5 table 4 (p. 53): + and - change the project speed while the
    # project runs; the simulator applies it to the move under way (ramped over 0.2 s).
    full, slow = simulated_seconds_of_a_move(100), simulated_seconds_of_a_move(5)
    raised = simulated_seconds_with_a_change(5, 100, physics)
    assert full < raised < 0.3 + 1.3 * full < slow / 4  # the rest of the move at 100 %
    lowered = simulated_seconds_with_a_change(100, 20, physics)
    assert lowered > 0.3 + 3 * (full - 0.3)  # the rest at a fifth of the speed, or so


def test_the_simulators_project_speed_setting() -> None:
    with Simulator(listen=False, robot=RobotSetup(project_speed=50)) as sim:
        assert sim.field("project_speed") == 50
    for bad in (0, 7, 105, True, 50.0):
        with pytest.raises(ConfigError, match="project_speed"):
            RobotSetup(project_speed=bad)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="project_speed is a TMflow project setting"):
        Simulator("article", listen=False, robot=RobotSetup(project_speed=50))


def test_the_master_plans_with_the_robots_project_speed() -> None:
    expected = {}
    for percent in (100, 50):
        with (
            Simulator(time_scale=100, listen=False, robot=RobotSetup(project_speed=percent)) as sim,
            Robot(sim.url) as robot,
        ):
            robot.move_to(LEFT, speed=50)
            motion = robot.move_to(RIGHT, speed=50)
            assert motion.timeout_s == pytest.approx(robot.timeouts.for_motion(motion.expected_s))
            expected[percent] = motion.expected_s
            at_25 = robot.expected_motion_time(LEFT, RIGHT, 25, MotionType.PTP)
            at_50 = robot.expected_motion_time(LEFT, RIGHT, 50, MotionType.PTP)
            if percent == 50:  # the robot's 50 % runs as the model's 25 %
                assert at_50 > 1.6 * robot.expected_motion_time(LEFT, RIGHT, 100, MotionType.PTP)
            assert at_25 > at_50
    assert 1.6 < expected[50] / expected[100] < 2.2


def test_a_half_speed_project_on_a_slow_arm_gives_no_false_timeout() -> None:
    # 30 ordinary PTPs on an arm half as fast as the model, in a project at 50 %: every
    # one ends done (a MotionTimeoutError would stop an arm moving normally).
    with (
        Simulator(
            listen=False, robot=RobotSetup(project_speed=50), cell=Cell(speed_factor=0.5), **QUICK
        ) as sim,
        Robot(sim.url) as robot,
    ):
        robot.move_to(LEFT, speed=50)
        for i in range(30):
            target = Pose(300, -100 - 100 * (i % 2), 200 - 10 * (i % 3), 180, 0, 90)
            assert robot.move_to(target, speed=50).done


def test_a_project_speed_lowered_since_the_plan_grows_the_moves_budget() -> None:
    # At the move's derived deadline the master reads 7101 once: lowered from 100 % to
    # 25 % since the plan, the move takes four times as long, and is given that time.
    follower = _MotionFollower(
        channel=None,  # type: ignore[arg-type]  # nothing here reads the robot
        stop_event=threading.Event(),
        log=get_logger("test"),
        polling=PollPolicy(),
        timeouts=TimeoutPolicy(),
        position_tolerance_mm=1.0,
        orientation_tolerance_deg=1.0,
    )

    def follow_of(timeout_s: float | None) -> tuple[Motion, FollowState]:
        ticket = Ticket(Command(CommandKind.PTP, RIGHT, 50), [], time.monotonic())
        plan = Plan(LEFT, None, RIGHT, expected_s=2.0, timeout_s=4.6, timeout_from_model=True)
        motion = Motion(follower, ticket, plan)
        state = FollowState(
            motion,
            timeout_s,
            stop_event=follower.stop_event,
            polling=PollPolicy(),
            timeouts=TimeoutPolicy(ack_timeout_s=2.0, stall_s=1.0),
        )
        return motion, state

    motion, follow = follow_of(None)
    follower.project_speed = lambda: 25.0
    assert follower._project_slowed(motion, follow)
    assert (follow.budget, motion.expected_s) == (pytest.approx(18.4), pytest.approx(8.0))
    motion, follow = follow_of(None)
    follower.project_speed = lambda: 100.0  # not lowered: the deadline stands
    assert not follower._project_slowed(motion, follow)
    motion, follow = follow_of(3.0)  # a timeout given is never changed
    follower.project_speed = lambda: 25.0
    assert not follower._project_slowed(motion, follow)
    assert follow.budget == 3.0
