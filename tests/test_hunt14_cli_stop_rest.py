"""``tmmaster robot stop`` says "the arm is at rest" only once the arm is at rest.

The command presses Stop, then reads the status until the robot reports the arm still
(docs: exit 0 means "stop: the arm at rest"). On ``tmflow`` the status's ``moving`` is the
robot program's state, which leaves busy as soon as the project stops, before the arm has
braked: the rest is judged from the reported TCP pose alone. A real controller's pose
registers can stand still for a few status cycles while the arm moves (a controller or
network hiccup): the master's own waits allow for one up to ``STALL_FLOOR_S`` (0.5 s,
``_following.py``; ``tests/test_hunt12_lagging_reports.py``). The command took two reads
one poll apart (0.05 s) with the same pose for the arm at rest.

Found by this hunt (fails without its fix): the reports frozen for 8 robot ticks
(0.16 s) as the brake began, the command answered exit 0 "the arm is at rest" while the
arm went on braking for about 150 mm (a Stop at full speed). It now takes the pose
``STALL_FLOOR_S`` apart, so a hiccup shorter than the master's own stall floor never
passes for a rest. The judge is the simulated arm (``true_pose``), never what the robot
reports.
"""

from __future__ import annotations

import contextlib
import io

import pytest

from test_hunt12_lagging_reports import ReportingBackend, connect, simulator
from tmmaster import Pose
from tmmaster._cli import main

FAR = Pose(300, 200, 200, 180, 0, 90)
#: How long the reports stand still once the brake begins, robot ticks (50 Hz).
FROZEN_TICKS = 8


class FrozenAtStop(ReportingBackend):
    """The kinematic arm, whose reports stand still for a few ticks as a Stop's brake
    begins (the hiccup falls on the Stop, not on a share of the motion's time)."""

    def __init__(self) -> None:
        super().__init__(freeze=(2.0, 0))  # never by the motion's time: set at the stop

    def stop_motion(self) -> None:
        braking = self._motion is not None and self._motion.braking is None
        super().stop_motion()
        if braking:
            self._frozen_motion, self._frozen_left = self._motion, FROZEN_TICKS


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_robot_stop_answers_at_rest_only_once_the_arm_is_still(profile: str) -> None:
    backend = FrozenAtStop()
    with simulator(profile, backend, time_scale=1.0) as sim, connect(sim, profile) as robot:
        robot.wait_until_ready(timeout_s=5)
        start = sim.call(backend.true_pose)
        robot.start_move(FAR, speed=100)
        sim.wait_for(lambda: backend.true_pose().distance_to(start) > 50, timeout=5.0)
        said = io.StringIO()
        with contextlib.redirect_stdout(said):
            code = main(["robot", "stop", "--host", sim.url, "--profile", profile])
        answered = sim.call(backend.true_pose)
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 10, timeout=5.0)
        assert code == 0
        assert "at rest" in said.getvalue()
        moved = sim.call(backend.true_pose).distance_to(answered)
        assert moved < 0.05, f"the arm moved {moved:.1f} mm after the command said at rest"
        robot.interrupt()
