"""Hunt 24: a Line or an arc faster than the TCP speed limit the master was told of.

[TMF]: TMflow Software Manual 2.24, Rev 1.00 (text copy: kenshu528-oss/Modbus-testkit-for-
TMflow, ``TM Doc/``). The Performance Safety "TCP Speed" limit is a stop criterion ([TMF]
3 Safety Settings, Speed & Force, p. 38; 1500 mm/s by default, settable 0-4500: Appendix B,
p. 285). 0x0021, "The robot detected an exceeding TCP speed or Joint speed which is over
the limit of the Safety Settings", names the Line among its causes: "5. Check if the
issued point is LINE on motion setting(ABS)" (Appendix J, p. 409).

``Checks(tcp_speed_limit_mm_s=...)`` tells the master a cell's limit (docs/kinematics.md,
"The robot's TCP speed limit"): a PTP whose TCP would run faster is refused before any
request. A Line or an arc is not held to it ("Lines and arcs are not held to it"): with
the limit at 500 mm/s, a 100 % Line runs its TCP at 1100 mm/s (TM5-700) and is accepted,
2.2 times the robot's limit, which stops it (0x0021) where it does not slow it (Speed
Suppression, [TMF] Motion Settings, p. 110: "always enabled" for Flow nodes; the robot
program's ``Line()`` is TMscript, which the page does not name).
Fixed: a Line or an arc is refused before any request when its TCP speed (its
``speed_mm_s``, or the model's top Line speed x its percent, x the project speed) is over
the limit; one at the limit is taken.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import Checks, ConfigError, Pose, Robot, robot_model
from tmmaster.sim import Cell, Simulator

ARM = robot_model("tm5-700")
NEAR = Pose(300, -200, 200, 180, 0, 90)
READY = (0.0, 0.0, 90.0, 0.0, 90.0, 0.0)
LIMIT_MM_S = 500.0


def _robot() -> Robot:
    """A robot never connected: check_move makes every check a move makes before a write."""
    return Robot("127.0.0.1", 1, profile="tmflow", checks=Checks(tcp_speed_limit_mm_s=LIMIT_MM_S))


def _line_target() -> Pose:
    start = ARM.forward(READY)
    return Pose(start.x, start.y - 300, start.z, start.rx, start.ry, start.rz)


def test_the_same_robot_refuses_a_ptp_over_that_limit() -> None:
    # The premise: the limit is taken, and a PTP over it is refused.
    with pytest.raises(ConfigError, match=r"checks\.tcp_speed_limit_mm_s = 500\)"):
        _robot().check_move(_line_target(), 100, "ptp", seed_deg=READY)


def test_the_line_is_under_the_models_default_limit() -> None:
    # The Line itself is fine on a robot at the default limit (1500 mm/s).
    robot = Robot("127.0.0.1", 1, profile="tmflow")
    assert len(robot.check_move(_line_target(), 100, "line", seed_deg=READY)) == 6
    assert ARM.tcp_speed_mm_s > LIMIT_MM_S


def test_a_line_faster_than_the_limit_is_refused_before_any_request() -> None:
    with pytest.raises(ConfigError, match=r"a line at 1100 mm/s would move the TCP at 1100"):
        _robot().check_move(_line_target(), 100, "line", seed_deg=READY)
    assert len(_robot().check_move(_line_target(), 45, "line", seed_deg=READY)) == 6  # 495


def _writes(sim: Simulator, robot: Robot) -> list[object]:
    """Every write but the heartbeat's (tmflow's master beats on its own schedule)."""
    beat = robot.profile.field("master_heartbeat").address
    return [r for r in sim.request_log if r.is_write and r.address != beat]


def test_a_line_or_an_arc_over_the_limit_writes_nothing_and_one_at_it_runs(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    sim = tm_simulator_factory(cell=Cell(scene=[]))
    limit = Checks(tcp_speed_limit_mm_s=LIMIT_MM_S)
    with Robot(sim.url, gripper=None, checks=limit) as robot:
        robot.move_to(NEAR, speed=30)
        moves, writes = len(sim.motion_log()), len(_writes(sim, robot))
        with pytest.raises(ConfigError, match="a line at 501 mm/s"):
            robot.move_to(NEAR.offset(dy=100), motion="line", speed_mm_s=501)
        with pytest.raises(ConfigError, match="a line at 550 mm/s"):
            robot.move_to(NEAR.offset(dy=100), motion="line", speed=50)
        with pytest.raises(ConfigError, match="a circle at 1100 mm/s"):
            robot.move_arc(NEAR.offset(dx=50, dy=50), NEAR.offset(dy=100), speed=100)
        with pytest.raises(ConfigError, match="a line at 501 mm/s"):
            robot.move_by(dy=100, motion="line", speed_mm_s=501)
        assert len(_writes(sim, robot)) == writes  # no command written
        robot.move_to(NEAR.offset(dy=100), motion="line", speed_mm_s=500)  # at the limit
        assert len(sim.motion_log()) == moves + 1
        assert sim.motion_log()[-1].target == NEAR.offset(dy=100)
