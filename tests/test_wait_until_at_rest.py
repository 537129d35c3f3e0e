"""``Robot.wait_until_at_rest()`` answers only once the simulated arm is still.

On ``tmflow``, ``status().moving`` is the robot program's state: a Stop ends the project
and it reads False at once, while the arm still brakes (hunt 18). The wait judges the
arm: two reads ``STALL_FLOOR_S`` apart, the TCP within 0.5 mm / 0.5 deg, and (tmflow)
Techman's Joint Speed under ``REST_SPEED_DEG_S`` on every read. The pose alone cannot
tell a slow creep from a rest: here the arm's wrist (J6) goes on turning at 0.2 deg/s
for 4 simulated seconds after the brake (a sagging or slipping joint), which moves the
reported TCP less than the pose tolerance between two reads. The joint speeds say it
moves (tmflow); the article's motion flag stays 1 while its arm is not settled.

Found by hunt 18's follow-up (fails without the change: there was no such wait; the
command line's pose-only rest check answered during the creep, and the simulator's
Joint Speed read 0). The judge is the simulated arm (``sim.tcp_pose()``): it must not
move after the answer. The stall floor is scaled down with the simulator's clock (20x)
so that the test stays short; the margins (creep 4x the rest speed, 0.1 deg of the
0.5 deg tolerance per floor) do not depend on the machine's speed.
"""

from __future__ import annotations

import pytest

import tmmaster._robot
from tmmaster import PollPolicy, Pose, Robot, robot_model
from tmmaster.sim import KinematicBackend, Simulator, Timing

MODEL = robot_model("tm5-700")
FAR = Pose(300, 200, 200, 180, 0, 90)
TIME_SCALE = 20.0
#: The wrist's creep after the brake: speed (deg/s) and how long (simulated s).
CREEP_DEG_S, CREEP_S = 0.2, 4.0


class CreepAfterStop(KinematicBackend):
    """The kinematic arm, whose wrist (J6) creeps on for ``CREEP_S`` once a Stop's brake
    has ended (the arm is not settled meanwhile)."""

    def __init__(self) -> None:
        super().__init__(MODEL)
        self.creep_left_s = 0.0
        self.creeps = 0

    def stop_motion(self) -> None:
        if self._motion is not None:
            self.creep_left_s, self.creeps = CREEP_S, self.creeps + 1
        super().stop_motion()

    def step(self, dt: float) -> None:
        super().step(dt)
        if self._motion is None and self.creep_left_s > 0.0:
            turn = min(dt, self.creep_left_s)
            self.creep_left_s -= turn
            joints = (*self._joints[:5], self._joints[5] + CREEP_DEG_S * turn)
            self._set(joints, MODEL.forward(joints, self._tool))

    def is_settled(self) -> bool:
        return self.creep_left_s <= 0.0 and super().is_settled()


@pytest.fixture
def fast_floor(monkeypatch: pytest.MonkeyPatch) -> None:
    # The stall floor is wall time: scaled with the clock, it stays 0.5 simulated s.
    monkeypatch.setattr(tmmaster._robot, "STALL_FLOOR_S", 0.5 / TIME_SCALE)


def _connect(sim: Simulator, profile: str) -> Robot:
    return Robot(sim.url, profile=profile, gripper=None, polling=PollPolicy(interval_s=0.02))


@pytest.mark.usefixtures("fast_floor")
@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_the_wait_answers_only_once_the_arm_no_longer_creeps(profile: str) -> None:
    backend = CreepAfterStop()
    sim = Simulator(
        profile=profile,
        listen=False,
        time_scale=TIME_SCALE,
        timing=Timing(tick_hz=100.0),
        cell=backend,
    )
    with sim, _connect(sim, profile) as robot:
        robot.wait_until_ready(timeout_s=5)
        start = sim.tcp_pose()
        # Slow enough that the Stop comes mid-move however late a loaded machine runs it.
        robot.start_move(FAR, speed=5)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(start) > 10, timeout=5.0)
        robot.stop()
        status = robot.wait_until_at_rest(timeout_s=5)
        answered, creep_left = sim.call(lambda: (backend.tcp_pose(), backend.creep_left_s))
        ticks = sim.call(lambda: sim.ticks)  # a call runs the ticks due first
        sim.wait_for(lambda: sim.call(lambda: sim.ticks) >= ticks + 5, timeout=5.0)
        assert backend.creeps == 1  # the Stop came mid-move
        assert creep_left == 0.0, f"answered with {creep_left:.2f} s of creep left"
        assert sim.tcp_pose() == answered, "the arm moved after the wait said at rest"
        assert not status.moving
        robot.interrupt()


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_timeout_shorter_than_the_stall_floor_still_finds_an_arm_at_rest(
    profile: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The rest takes two reads a floor apart: a timeout shorter than the floor used to cut
    # the second read's sleep at the deadline and answer "arm still moving" for an arm
    # that never moved (`tmmaster robot stop --timeout 0.3` exit 4, where it answered at
    # rest before the wait was a method). The read that found it still must be confirmed.
    monkeypatch.setattr(tmmaster._robot, "STALL_FLOOR_S", 1.0)
    with Simulator(profile=profile, listen=False) as sim, _connect(sim, profile) as robot:
        robot.wait_until_ready(timeout_s=5)
        before = sim.tcp_pose()
        status = robot.wait_until_at_rest(timeout_s=0.9)
        assert not status.moving
        assert status.pose.is_close(before)
        assert sim.tcp_pose() == before  # it never moved
