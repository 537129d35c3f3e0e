"""A move checked against where the master believes the arm is, while someone moved it.

A master's checks before any request (``Robot.start_move``'s path check, ``move_joints``'
body check) start from where it believes the arm is: the last target it sent. The
operator may have moved the arm since: pressed Stop, hand-guided or jogged it into the
other wrist configuration (the TCP where it was), and pressed Play. The master reads the
robot's joints again right before its write (docs/safety.md: "the TCP read with the
write decides"; tests/test_arm_state.py) and plans from them; but the plan only solved
the target from there, it did not check the path again: a PTP, a joint move or a Line
that passes the arm through its own body from where it really is was sent, and the
simulated arm stopped in its collision (0x0022). On a real TM5 the wrist hits the camera.

The hand-guiding is modelled by driving the simulated arm directly (no command of the
robot program moves it, so the motion log does not list it) between the operator's Stop
and Play. The judge is the simulator: nothing runs, no error, and the master's answer is
the refusal a fresh master (one that read the joints first) gives, unsent.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, cast

import pytest

from pendant import press_play_pause
from test_hunt11_calibrated_arm import HOME, NOMINAL, THROUGH_ITSELF, wrist_flipped
from test_safety_regressions import operator_resets
from test_withdraw_stopped_project import press_stop
from tmmaster import ConfigError, MotionTimeoutError, Pose, Robot
from tmmaster.sim import Cell, PathBackend, Simulator

#: From HOME wrist-flipped, a joint move here swings wrist 1 into the camera; from HOME
#: as the master left it, the same joint move is clear.
JOINTS_THROUGH_ITSELF = (15.0, -42.9, 153.9, -23.3, 121.7, -9.7)
#: From HOME wrist-flipped, the straight path here passes wrist 1 into the camera; from
#: HOME as the master left it, the Line is clear.
LINE_THROUGH_ITSELF = Pose(387, 224, 164, 147, 27, 118)

MOVES: dict[str, Callable[[Robot], Any]] = {
    "ptp": lambda robot: robot.move_to(THROUGH_ITSELF, speed=60),
    "joints": lambda robot: robot.move_joints(JOINTS_THROUGH_ITSELF, speed=60),
    "line": lambda robot: robot.move_to(LINE_THROUGH_ITSELF, speed=30, motion="line"),
}


def hand_guide(sim: Simulator, joints: list[float]) -> None:
    """The operator's Stop, the arm hand-guided to ``joints``, then Play."""
    press_stop(sim)
    sim.wait_for(lambda: not sim.field("project_running"), timeout=5.0)
    arm = cast(PathBackend, sim.backend)
    sim.call(lambda: arm.start_joint_motion(joints, speed_percent=50, accel_time_s=0.2))
    sim.wait_for(lambda: sim.call(sim.backend.is_settled), timeout=10.0)
    press_play_pause(sim)
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=5.0)
    beat = sim.field("heartbeat")  # the program's loop runs again
    sim.wait_for(lambda: sim.field("heartbeat") != beat, timeout=5.0)


@pytest.mark.parametrize("move", MOVES)
def test_a_move_from_an_arm_moved_since_the_last_target_is_checked_from_where_it_is(
    tm_simulator_factory: Callable[..., Simulator], move: str
) -> None:
    sim = tm_simulator_factory(cell=Cell(scene=[]))
    with Robot(sim.url, gripper=None) as robot:
        robot.move_to(HOME, speed=60)
        before = len(sim.motion_log())
        hand_guide(sim, wrist_flipped(NOMINAL))  # the TCP still at HOME, the wrist flipped
        with pytest.raises(ConfigError, match="self-collision"):
            MOVES[move](robot)
        assert len(sim.motion_log()) == before  # nothing was sent
        assert sim.field("last_error_code") == 0
    # What a master that read the joints first answers: the same refusal, unsent.
    with Robot(sim.url, gripper=None) as fresh, pytest.raises(ConfigError, match="self-coll"):
        MOVES[move](fresh)
    assert len(sim.motion_log()) == before


#: Per profile: a PTP from HOME to the first pose, stopped halfway (the simulator's stall
#: fault), then a PTP to the second: clear from the first pose, it passes wrist 1 through
#: the camera from where the arm stopped. The article's map holds poses within +-327.67.
STOPPED_HALFWAY = {
    "tmflow": (
        Pose(312.3, -252.89, 332.2, 200.86, -8.6, 44.29),
        Pose(-107.45, 272.62, 268.17, 165.38, 2.97, 20.89),
    ),
    "article": (
        Pose(-303.81, -58.46, 231.91, 166.47, -11.74, -77.84),
        Pose(231.68, -82.46, 220.18, 167.38, -26.41, -84.72),
    ),
}


@pytest.mark.parametrize("profile", STOPPED_HALFWAY)
def test_a_move_after_the_masters_own_move_stopped_halfway_is_checked_from_there(
    tm_simulator_factory: Callable[..., Simulator], profile: str
) -> None:
    # The master's belief after a move it gave up is that move's target; the arm stopped
    # halfway. The next PTP, clear from that target, is checked from where the arm is:
    # on tmflow from the joints it reports, on article (no joints published) from its
    # pose, on the branch the master assumes.
    stopped, turned = STOPPED_HALFWAY[profile]
    sim = tm_simulator_factory(profile, cell=Cell(scene=[]), faults=["stall:at_move=2"])
    with Robot(sim.url, profile=profile, gripper=None) as robot:
        robot.move_to(HOME, speed=60)
        with pytest.raises(MotionTimeoutError):
            robot.move_to(stopped, speed=60, timeout=0.3)  # stalled, then stopped
        sim.clear_faults()
        operator_resets(sim)
        before = len(sim.motion_log())
        with pytest.raises(ConfigError, match="self-collision"):
            robot.move_to(turned, speed=60)
        assert len(sim.motion_log()) == before
        assert robot.status().error_code == 0
