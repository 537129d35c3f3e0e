"""``move_arc`` after a move stopped short: the arc starts where the arm is.

``move_arc`` checked the arc before any request from where the master believed the arm
to be: the last move's target, set when that move was written. A move given up (here
``Motion.cancel()``, as a stop request or a timeout does) leaves the arm short of that
target, and an arc that the arm can take from where it stands was refused, naming the
stale start: "no arc from <the cancelled move's target> through ... : the arc's start,
via and end lie on one line". The arc is now checked from the pose the robot reports
(its plan, before the write), as it always was there too; its end and its via are still
checked before any request.

A Line had the same pre-read check (``Planner.check_path``: its straight path from the
last target): after a move stopped short, a Line the arm can take from where it stands
was refused, its path from the stale target leaving the arm's range. Fixed: after a move
given up, the next move reads where the arm is (and waits for it to settle) before its
checks.

The judge is the simulator: its motion log (tests/safety_invariant.py) and where its
arm ends.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from safety_invariant import Issued, check
from tmmaster import ConfigError, PollPolicy, Pose, Robot
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
A = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)
#: On one line with FAR (along x): no arc from FAR passes through them.
VIA = Pose(350, 200, 200, 180, 0, 90)
END = Pose(400, 200, 200, 180, 0, 90)
#: A Line's end whose straight path from FAR passes 122 mm from the J1 axis (out of
#: reach), but not from where the arm stops short of FAR.
LINE_END = Pose(-200, -300, 200, 180, 0, 90)
#: The tmflow command register.
COMMAND_REGISTER = 9014


def command_writes(sim: Simulator) -> list[object]:
    return [
        r
        for r in sim.request_log
        if r.is_write and r.address <= COMMAND_REGISTER < r.address + r.count
    ]


def stopped_short_of_far(sim: Simulator, robot: Robot, issued: list[Issued]) -> Pose:
    """Move to A, start toward FAR, cancel on the way; Play again. Where the arm rests."""
    robot.move_to(A, speed=100)
    issued.append(Issued(A, 0.0, 0.0, "done"))
    issued.append(Issued(FAR, time.monotonic()))
    motion = robot.start_move(FAR, speed=10)
    sim.wait_for(lambda: len(sim.motion_log()) == 2 and sim.tcp_pose().y > -50, timeout=5.0)
    assert motion.cancel() is True
    issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "cancelled"
    assert motion.stop_delivered is True
    robot.play()  # the Stop stopped the project
    robot.wait_until_ready(timeout_s=5)
    rest = robot.wait_until_at_rest(timeout_s=5).pose
    assert rest.distance_to(FAR) > 100, "the scenario: stopped well short of FAR"
    return rest


def test_an_arc_from_where_a_stopped_move_left_the_arm_is_taken(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    issued: list[Issued] = []
    with Robot(sim.url, profile="tmflow", polling=PollPolicy(interval_s=0.01)) as robot:
        stopped_short_of_far(sim, robot, issued)
        # Before: ConfigError "no arc from (300.00, 200.00, 200.00 ...) through ...: the
        # arc's start, via and end lie on one line", nothing sent.
        motion = robot.move_arc(VIA, END, speed=30)
        issued.append(Issued(END, 0.0, 1.0, "done"))
        assert motion.done
    log = sim.motion_log()
    assert len(log) == 3
    assert log[-1].kind == "circle"
    assert sim.tcp_pose().is_close(END)
    check(issued, log)


def test_an_arc_impossible_from_where_the_arm_is_is_still_refused_unsent(
    tm_simulator_factory: SimFactory,
) -> None:
    # The control: the arc is checked from the arm's reported pose before the write.
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    issued: list[Issued] = []
    with Robot(sim.url, profile="tmflow", polling=PollPolicy(interval_s=0.01)) as robot:
        rest = stopped_short_of_far(sim, robot, issued)
        sim.clear_request_log()
        via, end = rest.offset(dx=30), rest.offset(dx=60)  # on one line with the arm
        with pytest.raises(ConfigError, match="lie on one line"):
            robot.move_arc(via, end, speed=30)
        assert command_writes(sim) == []
    assert len(sim.motion_log()) == 2
    check(issued, sim.motion_log())


def test_a_line_from_where_a_stopped_move_left_the_arm_is_taken(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    issued: list[Issued] = []
    with Robot(sim.url, profile="tmflow", polling=PollPolicy(interval_s=0.01)) as robot:
        rest = stopped_short_of_far(sim, robot, issued)
        joints = robot.check_move(rest, 30)
        robot.check_move(LINE_END, 30, "line", start=rest, seed_deg=joints)  # from there: ok
        robot.move_to(LINE_END, speed=30, motion="line")
        issued.append(Issued(LINE_END, 0.0, 1.0, "done"))
    assert sim.tcp_pose().is_close(LINE_END)
    check(issued, sim.motion_log())
