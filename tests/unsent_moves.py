"""Shared by the tests of moves refused before any write: a robot at a start pose, and
the command writes that reached the simulator after it got there."""

from __future__ import annotations

from collections.abc import Callable

from tmmaster import Pose, Robot
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]


def robot_at(
    robots: Callable[..., Robot], simulators: SimFactory, start: Pose
) -> tuple[Simulator, Robot]:
    """A tmflow robot on an in-process simulator, moved to ``start``, its log cleared."""
    sim = simulators("tmflow")
    robot = robots(sim)
    robot.move_to(start, speed=100)
    sim.clear_request_log()
    return sim, robot


def command_writes(sim: Simulator) -> list[object]:
    """Every FC16 that reached the robot but the master's heartbeat."""
    return [r for r in sim.request_log if r.function_code == 16 and r.address != 9050]
