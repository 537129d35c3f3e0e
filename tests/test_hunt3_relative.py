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
from tmmaster import Pose, Robot
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

START = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)


def at_rest(sim: Simulator) -> Callable[[], bool]:
    """True once the TCP did not move between two looks a few ticks apart (braked)."""
    last: list[Pose | None] = [None]

    def still() -> bool:
        now, before = sim.tcp_pose(), last[0]
        last[0] = now
        return before is not None and now.distance_to(before) < 1e-6

    return still


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
    # Made at once, while the arm brakes (0.34 s from top speed at 1x): refused unsent.
    # Should it come only once the arm rests (a loaded machine), it runs from there.
    refusal = ""
    try:
        made = [robot.move_by(dz=-40, speed=50)]
    except tmmaster.RobotError as exc:
        refusal, made = str(exc), []
    assert made or "moving" in refusal or "still executing" in refusal
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
