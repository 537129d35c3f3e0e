"""A relative move right after a move the master stopped is never resolved mid-brake.

``move_by`` resolves its offset against the pose the robot reports. A move the master
gave up (a stop request) is stopped, and the arm then brakes to rest: the wait returns
once the stop is delivered, not once the arm rests (docs/safety.md, Limits). A
``move_by`` made at once must not take the pose read while the arm still brakes as its
origin: it is refused, nothing written, and the arm ends where the brake left it; the
next one (tmflow: after Play) runs once, from the pose the arm rests at. The judge is
the simulator's motion log and TCP, never what the master believes.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

import tmmaster
from safety_invariant import at_rest
from sim_speeds import QUICK
from tmmaster import Pose, ProjectState, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

START = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_move_by_right_after_a_stopped_move_is_refused_unsent(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = memory_simulator_factory(profile, time_scale=1.0)
    robot = robots(sim)
    robot.move_to(START, speed=100)
    motion = robot.start_move(FAR, speed=100)
    sim.wait_for(lambda: sim.tcp_pose().y > 0, timeout=20)  # half-way, at speed
    robot.interrupt()
    with pytest.raises(tmmaster.StopRequestedError):
        motion.wait()
    robot.clear_stop_request()
    before = len(sim.motion_log())
    # Made at once, while the arm brakes (0.34 s from top speed at 1x): refused unsent,
    # by whichever check sees it first (the arm moving, the program still executing the
    # stopped command, the project the stop ended, or the arm no longer where the
    # move_by was resolved). Should it come only once the arm rests (a loaded machine),
    # it runs from there.
    refusal = ""
    try:
        made = [robot.move_by(dz=-40, speed=50)]
    except tmmaster.RobotError as exc:
        refusal, made = str(exc), []
    refusals = ("moving", "still executing", "project is stopped", "nothing was sent")
    assert made or any(reason in refusal for reason in refusals), refusal
    sim.wait_for(at_rest(sim), timeout=5, interval=0.1)
    rest = sim.tcp_pose() if not made else made[0].start
    assert rest is not None
    assert len(sim.motion_log()) == before + len(made)
    if not made:  # nothing written: the arm rests where it braked; a move_by now
        if profile == "tmflow":
            sim.press_play()  # the stop ended the project
            robot.wait_until_ready(timeout_s=5)
        made = [robot.move_by(dz=-40, speed=50)]
    done = made[0]
    # Resolved against the pose the arm rests at, never a pose read mid-brake nor the
    # given-up target: it ran once, from there, and the arm is there.
    assert done.start is not None
    assert done.start.is_close(rest, mm=0.5)
    assert [m.target for m in sim.motion_log()[before:]] == [done.target]
    assert sim.tcp_pose().is_close(rest.offset(dz=-40), mm=0.5)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_move_by_given_up_before_its_ack_never_runs_and_the_next_resolves_from_the_arm(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # The robot gets to the first move_by only long after the master's acknowledgement
    # timeout (the simulator's late_ack, on that move alone): the master withdraws it
    # (tmflow: its cancel record, unanswered until then, owed). It must never run, not
    # when the robot gets to it nor under the next command, and the next move_by is
    # resolved against where the arm is, not where the withdrawn one would have gone.
    sim = memory_simulator_factory(profile, faults=["late_ack:delay_s=80,at_move=2"], **QUICK)
    robot = robots(sim, timeouts=TimeoutPolicy(ack_timeout_s=0.3))
    robot.move_to(START, speed=50)  # move 1
    before = len(sim.motion_log())
    with pytest.raises(tmmaster.AcknowledgeTimeoutError):
        robot.move_by(dz=-50, speed=50)  # move 2: withdrawn
    ticks = sim.ticks + 250  # 100 simulated seconds (1 s): past the late ack's 80 s
    sim.wait_for(lambda: sim.ticks >= ticks, timeout=10)
    assert sim.motion_log()[before:] == ()  # the robot got to it: it did not run it
    assert sim.tcp_pose().is_close(START, mm=0.5)
    sim.clear_faults()  # it fires for the next move the robot arms: that is move 2 again
    if profile == "tmflow" and robot.status().project is not ProjectState.RUNNING:
        sim.press_play()  # the owed give-up pressed Stop: the operator's Play
        robot.wait_until_ready(timeout_s=5)
    done = robot.move_by(dy=30, speed=50)
    assert [m.target for m in sim.motion_log()[before:]] == [done.target]
    assert done.target is not None
    assert done.target.is_close(START.offset(dy=30), mm=0.5)
    assert sim.tcp_pose().is_close(START.offset(dy=30), mm=0.5)
