"""``move_arc`` after a move given up: its end is checked from where the arm stands.

After a move given up (a cancel, a timeout, a stop request) the arm may have stopped
short, in another pose configuration than the given-up move's target. ``start_move`` and
``move_joints`` read where the robot reports the arm before their checks; ``move_arc``
checked its end first, from the given-up move's target (the planner's seed, set when
that move was written). An arc the arm can take from where it stands was refused:
"pose ... is reachable only in another pose configuration ... than the arm's", and again
on every retry, until another kind of move was made.

Here the arm stands with its wrist flipped (J5 < 0); a joint move toward a posture with
J5 > 0 is stopped early (``Robot.interrupt`` from another thread, as a Ctrl-C handler
does), while J5 is still negative. The arc's end, near the base on the left, a TM5-700
reaches only with the wrist flipped: from the stale seed (J5 > 0) it was refused, from
the arm's own joints it is taken.

The judge is the simulator: its motion log (tests/safety_invariant.py) and where its
arm ends.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from safety_invariant import Issued, check
from tmmaster import ConfigError, PollPolicy, Pose, Robot, StopRequestedError, robot_model
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
ARM = robot_model("tm5-700")
#: Tool down on the left, the wrist flipped (J5 = -90): where the arm starts.
A = Pose(100, 250, 150, 180, 0, 90)
FLIPPED = ARM.inverse(A, seed_deg=(95, 18, 110, 141, -90, -85))
#: Tool down in front, the wrist not flipped (J5 = +90): the given-up move's posture.
B = Pose(250, 0, 200, 180, 0, 90)
UPRIGHT = ARM.inverse(B)
#: Near the base on the left: a TM5-700 reaches it only with the wrist flipped.
END = Pose(0, 200, 150, 180, 0, 90)


def stop_early(sim: Simulator, robot: Robot) -> None:
    """Request a stop once the joint move has turned J5 a little (still negative)."""
    sim.wait_for(lambda: sim.field("joint_5") > FLIPPED[4] + 10, timeout=10.0)
    robot.interrupt()


def given_up_with_the_wrist_flipped(sim: Simulator, robot: Robot, issued: list[Issued]) -> Pose:
    """Move to FLIPPED, start toward UPRIGHT, stop it early; Play again. Where it rests."""
    assert ARM.configuration(FLIPPED) == (True, True, False)
    assert ARM.configuration(UPRIGHT) == (True, True, True)
    robot.move_joints(FLIPPED, speed=50)
    issued.append(Issued(A, 0.0, 0.0, "done"))
    stopper = threading.Thread(target=stop_early, args=(sim, robot))
    stopper.start()
    issued.append(Issued(B, time.monotonic()))
    try:
        robot.move_joints(UPRIGHT, speed=5)
    except StopRequestedError:
        issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "StopRequestedError"
    stopper.join()
    assert issued[-1].outcome == "StopRequestedError"
    robot.clear_stop_request()
    robot.play()  # the stop stopped the project
    robot.wait_until_ready(timeout_s=5)
    rest = robot.wait_until_at_rest(timeout_s=5)
    assert rest.joints is not None
    assert rest.joints[4] < -40, "the scenario: the wrist is still flipped"
    return rest.pose


def test_an_arc_the_arm_takes_from_where_a_given_up_move_left_it_is_taken(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    issued: list[Issued] = []
    with Robot(sim.url, profile="tmflow", polling=PollPolicy(interval_s=0.01)) as robot:
        rest = given_up_with_the_wrist_flipped(sim, robot, issued)
        via = Pose((rest.x + END.x) / 2, (rest.y + END.y) / 2, 175, 180, 0, 90)
        # Before: UnreachablePoseError "pose (0.00, 200.00, 150.00 ...) is reachable only
        # in another pose configuration ... than the arm's ((True, True, True))", unsent.
        motion = robot.move_arc(via, END, speed=20)
        issued.append(Issued(END, 0.0, 1.0, "done"))
        assert motion.done
    log = sim.motion_log()
    assert [m.kind for m in log] == ["ptp_joints", "ptp_joints", "circle"]
    assert sim.tcp_pose().is_close(END)
    check(issued, log)


def test_bad_arguments_after_a_given_up_move_read_nothing(
    tm_simulator_factory: SimFactory,
) -> None:
    # The read after a give-up comes after the argument checks, for every move.
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    issued: list[Issued] = []
    with Robot(sim.url, profile="tmflow", polling=PollPolicy(interval_s=0.01)) as robot:
        rest = given_up_with_the_wrist_flipped(sim, robot, issued)
        calls: list[Callable[[], object]] = [
            lambda: robot.move_arc(rest.offset(dz=20), END, timeout=0),
            lambda: robot.move_arc(rest.offset(dz=20), END, accel_time_ms=-1),
            lambda: robot.move_joints(FLIPPED, speed=0),
            lambda: robot.move_joints(FLIPPED, timeout=-1.0),
            lambda: robot.start_move(A, speed=0),
        ]
        for call in calls:
            sim.clear_request_log()
            with pytest.raises(ConfigError):
                call()
            assert sim.request_log == []
    assert len(sim.motion_log()) == 2
    check(issued, sim.motion_log())
