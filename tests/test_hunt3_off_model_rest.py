"""A move returns done only once the arm is at rest, on an arm the model does not predict.

The master's polling is scheduled from the arm model's expected time. Against a
simulated arm deliberately slower or faster than that model (``Cell(speed_factor=)``),
every kind of move (PTP, Line, a TCP speed in mm/s, a relative move, an arc, a joint
move) must still return only when the robot reports it finished: the arm then holds
still over the next ticks, and each call ran exactly one motion on the robot.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import Motion, PollPolicy, Pose, Robot
from tmmaster.sim import Cell, Simulator, Timing

START = Pose(300, -200, 200, 180, 0, 90)
OTHER = Pose(320, -100, 120, 180, 0, 120)
VIA = Pose(330, -160, 170, 180, 0, 100)
JOINTS = [0.0, 10.0, 80.0, 0.0, 90.0, 0.0]

Move = Callable[[Robot], Motion]

#: The moves each profile has (the article profile has no arc, joint move nor mm/s).
MOVES: dict[str, list[tuple[str, Move]]] = {
    "article": [
        ("ptp", lambda robot: robot.move_to(OTHER, speed=35)),
        ("line", lambda robot: robot.move_to(START, speed=35, motion="line")),
        ("relative", lambda robot: robot.move_by(dz=-30, speed=30)),
    ],
    "tmflow": [
        ("ptp", lambda robot: robot.move_to(OTHER, speed=35)),
        ("line", lambda robot: robot.move_to(START, speed=35, motion="line")),
        ("arc", lambda robot: robot.move_arc(VIA, OTHER, speed=30)),
        ("joints", lambda robot: robot.move_joints(JOINTS, speed=30)),
        ("relative", lambda robot: robot.move_by(dz=30, speed=30)),
        ("mm/s", lambda robot: robot.move_to(START, speed_mm_s=100, motion="line")),
    ],
}


def held_still(sim: Simulator, ticks: int = 5) -> float:
    """How far (mm) the TCP moved over the next ``ticks`` robot ticks."""
    before, start = sim.tcp_pose(), sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)
    return before.distance_to(sim.tcp_pose())


@pytest.mark.parametrize("speed_factor", [0.3, 2.5], ids=["slower", "faster"])
@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_every_kind_of_move_returns_at_rest_on_an_arm_off_the_model(
    profile: str, speed_factor: float
) -> None:
    with (
        Simulator(
            profile=profile,
            listen=False,
            time_scale=20.0,
            timing=Timing(tick_hz=50.0),
            cell=Cell(speed_factor=speed_factor),
        ) as sim,
        Robot(sim.url, profile=profile, gripper=None, polling=PollPolicy(interval_s=0.05)) as robot,
    ):
        robot.wait_until_ready()
        robot.move_to(START, speed=30)
        for name, move in MOVES[profile]:
            runs_before = len(sim.motion_log())
            motion = move(robot)
            assert motion.done, name
            assert held_still(sim) < 0.01, f"{name}: the arm still moved after done"
            assert not robot.status().moving, name
            assert len(sim.motion_log()) == runs_before + 1, f"{name}: not exactly one motion"
