"""The TMflow project speed (7101) changed by the operator around and during a move.

docs/robot-api.md: TMflow runs every move at its speed times the project speed; the
master plans with the value it last read (at connect, with every ``status()``), and a
move that reaches its derived deadline reads 7101 once more: lowered since the plan,
its budget grows instead of ending in ``MotionTimeoutError``. The simulator runs each
move at the project speed 7101 holds, a change mid-move applying to the move under way
(docs/simulator-model.md).

What must hold, judged on the simulator: a move that is merely slower is neither timed
out nor stopped (it ends done, at its target, the arm at rest there), and no call
returns done while the arm still moves.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

import tmmaster
from safety_invariant import Issued, at_rest, check
from tmmaster import Fleet, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

LEFT = Pose(300, -200, 200, 180, 0, 90)
RIGHT = Pose(300, -140, 200, 180, 0, 90)
BACK = Pose(300, -190, 200, 180, 0, 90)  # each command its own target (safety_invariant)
#: At speed 50 the master expects LEFT -> RIGHT in about 0.31 s (real time) and, with a
#: 0.2 s margin, gives it about 0.6 s, grown with the pace it observes up to 20 times
#: (12 s) while the arm keeps moving. At 20 % the move takes about 1.3 s, at 5 % about
#: 6 s: the pace covers both, and when 7101 was lowered since the plan, so does its
#: re-read at the deadline (tests/test_project_speed.py).
MARGIN = TimeoutPolicy(motion_margin_s=0.2)
SPEED = 50
PACE_PERCENT = 20
SLOW_PERCENT = 5


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=1.0)


def open_robot(sim: Simulator, link: Fleet | None = None) -> Robot:
    """A robot that moved to LEFT and read 7101 (100 %) last with its ``status()``."""
    r = Robot(
        "127.0.0.1",
        sim.port,
        profile="tmflow",
        gripper=None,
        link=link,
        polling=PollPolicy(interval_s=0.02),
        timeouts=MARGIN,
    )
    r.connect()
    r.wait_until_ready(timeout_s=5)
    r.move_to(LEFT, speed=100)
    r.status()  # the master reads 7101 here: 100 %
    return r


@pytest.fixture
def robot(sim: Simulator) -> Iterator[Robot]:
    with open_robot(sim) as r:
        yield r


def set_project_speed(sim: Simulator, percent: int) -> None:
    """The operator's Change Project Speed on the pendant: 7101 holds ``percent`` now."""
    controller = sim._controller  # the pendant, as tests/pendant.py does
    sim.call(lambda: controller.bank.set("project_speed", percent))


def moves(sim: Simulator) -> int:
    return sum(1 for m in sim.motion_log() if m.target is not None)


def done_at_rest_on(sim: Simulator, target: Pose) -> None:
    """The arm at ``target`` and not moving (looked at 0.1 s apart) right after "done"."""
    pose = sim.tcp_pose()
    assert pose.is_close(target), f"returned done with the arm at {pose}"
    sim.wait_for(at_rest(sim), timeout=5, interval=0.1)
    assert sim.tcp_pose().is_close(pose), "the arm moved on after the call returned done"


def move_recorded(robot: Robot, target: Pose, issued: list[Issued]) -> str:
    command = Issued(target, time.monotonic())
    issued.append(command)
    try:
        robot.move_to(target, speed=SPEED)
    except tmmaster.TMMasterError as exc:
        command.outcome = type(exc).__name__
    else:
        command.outcome = "done"
    command.ended_at = time.monotonic()
    return command.outcome


def test_a_project_speed_lowered_after_the_masters_last_read_gives_no_timeout(
    tm_simulator_factory: Factory, driver_or_fleet: Fleet | None
) -> None:
    # Twice real time: at 5 % the move still takes over twice its 0.5 s deadline. (The
    # next test's 20 % move needs real time to outlast its deadline.)
    sim = tm_simulator_factory("tmflow", time_scale=2.0)
    issued = [Issued(LEFT, 0.0, 0.0, "done")]
    with open_robot(sim, driver_or_fleet) as robot:
        set_project_speed(sim, SLOW_PERCENT)  # after the master's read: its plan says 100 %
        assert move_recorded(robot, RIGHT, issued) == "done", issued
        done_at_rest_on(sim, RIGHT)
    check(issued, sim.motion_log())


def test_a_project_speed_lowered_mid_move_slows_the_next_move_without_a_timeout(
    sim: Simulator, robot: Robot
) -> None:
    issued = [Issued(LEFT, 0.0, 0.0, "done")]
    lowered = threading.Thread(
        target=lambda: (
            sim.wait_for(lambda: moves(sim) == 2, timeout=5),
            set_project_speed(sim, PACE_PERCENT),
        )
    )
    lowered.start()
    try:
        assert move_recorded(robot, RIGHT, issued) == "done", issued
    finally:
        lowered.join(10)
    done_at_rest_on(sim, RIGHT)
    # No status() since: the next move is planned at 100 % and runs at 20 %.
    assert move_recorded(robot, BACK, issued) == "done", issued
    done_at_rest_on(sim, BACK)
    check(issued, sim.motion_log())


def test_a_move_started_slow_whose_project_speed_is_raised_back_mid_move_is_not_stopped(
    sim: Simulator, robot: Robot
) -> None:
    """Planned at 100 %, started at 5 %, raised back to 100 % while it runs: the move
    speeds up (docs/simulator-model.md: a change applies to the move under way), and
    ends done at its target, whichever of the budget's growth with the pace the polls
    see (tests/test_stall.py) and the master's own end window meets it first."""
    issued = [Issued(LEFT, 0.0, 0.0, "done")]
    set_project_speed(sim, SLOW_PERCENT)  # after the master's read: its plan says 100 %
    raised = threading.Thread(
        target=lambda: (
            sim.wait_for(lambda: moves(sim) == 2, timeout=5),
            set_project_speed(sim, 100),  # back to 100 % while the move runs
        )
    )
    raised.start()
    try:
        outcome = move_recorded(robot, RIGHT, issued)
    finally:
        raised.join(10)
    check(issued, sim.motion_log())
    sim.wait_for(at_rest(sim), timeout=30, interval=0.1)
    assert outcome == "done", f"{outcome}: stopped at {sim.tcp_pose()}"
    done_at_rest_on(sim, RIGHT)
