"""A relative move from an arm at rest past the article map's pose range is refused unsent.

The article map's pose registers are int16 x100 (±327.67 mm). A PTP's curved path can
leave that range between two targets inside it (lift → place swings out to x ≈ 362 mm),
and an arm stopped out there reads x = 327.67, saturated (docs/simulator-model.md, the
encodable range rule). ``move_by`` resolved its target against that reading: asked for
10 mm back, the arm went to x = 317.67, tens of mm from the pose the caller asked for,
and the move was reported done. Found by ``benchmarks/soak_faults.py`` (seed 227, hunt
39). A move to an absolute target (``move_to``) is still how the arm is brought back.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from safety_invariant import wait_braked
from tmmaster import MotionType, Pose, Robot, RobotError, RobotFaultError
from tmmaster.sim import Cell, Simulator

#: The PTP between these passes x ≈ 362 mm halfway (tests/test_kinematics.py).
LIFT, PLACE = Pose(300, -200, 250, 180, 0, 90), Pose(300, 200, 200, 180, 0, 90)
EDGE_MM = 327.67


def test_move_by_from_a_saturated_pose_reading_is_refused_unsent(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    sim = tm_simulator_factory("article", cell=Cell(scene=[]), faults=["stall:at_move=2"])
    with Robot(sim.url, profile="article", gripper=None) as robot:
        robot.move_to(LIFT, speed=60)
        expected = robot.expected_motion_time(LIFT, PLACE, 10, MotionType.PTP)
        # Stalled halfway: at rest where the registers cannot say, a robot error.
        with pytest.raises(RobotFaultError, match="0x0103"):
            robot.move_to(PLACE, speed=10, timeout=expected)
        wait_braked(sim)
        sim.clear_faults()
        sim.clear_error()  # the operator's reset: the arm stays where it is
        stopped = sim.tcp_pose()
        assert stopped.x > EDGE_MM + 10  # past what the registers can say
        assert robot.pose().x == pytest.approx(EDGE_MM)  # what they say instead
        moves = len(sim.motion_log())
        with pytest.raises(RobotError, match="register"):
            robot.move_by(dx=-10, speed=60)
        assert len(sim.motion_log()) == moves  # nothing was sent
        assert sim.tcp_pose().is_close(stopped, mm=1e-6, deg=1e-6)
        robot.move_to(LIFT, speed=60)  # an absolute target still brings it back
        assert sim.tcp_pose().is_close(LIFT, mm=0.5, deg=0.5)
