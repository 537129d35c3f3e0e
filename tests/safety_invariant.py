"""The command-safety invariant, checked on what the robot actually did (docs/safety.md).

Every motion the robot executed corresponds to exactly one command the master issued, in
order; a command the master gave up on never started after it gave up. The master's side
is a list of :class:`Issued` commands (the test records them); the robot's side is the
simulator's own motion log, never what the master believes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from tmmaster import Pose, Robot, TMMasterError
from tmmaster.sim import MotionRecord, Simulator

#: Targets closer than this are the same command (tests give each command its own target).
SAME_TARGET_MM = 0.05


@dataclass
class Issued:
    """A motion command as the master issued it, and how the master's call ended."""

    target: Pose
    #: time.monotonic() when the call started.
    issued_at: float
    #: time.monotonic() when the call returned or raised (None while it runs).
    ended_at: float | None = None
    #: "done", or the name of the exception the call raised.
    outcome: str = "running"

    @property
    def gave_up(self) -> bool:
        """True when the master's call ended with an error (the master gave the command up)."""
        return self.outcome not in ("done", "running")


def attempt(robot: Robot, target: Pose, issued: list[Issued], *, speed: int = 80) -> str:
    """``robot.move_to(target)``, recorded in ``issued`` with how the call ended."""
    command = Issued(target, time.monotonic())
    issued.append(command)
    try:
        robot.move_to(target, speed=speed)
    except TMMasterError as exc:
        command.outcome = type(exc).__name__
    else:
        command.outcome = "done"
    command.ended_at = time.monotonic()
    return command.outcome


def check(issued: Sequence[Issued], log: Sequence[MotionRecord]) -> None:
    """Raise AssertionError, with the evidence, when the motion log breaks the invariant."""
    motions = [m for m in log if m.target is not None]
    matched: list[int] = []
    for motion in motions:
        assert motion.target is not None
        owners = [
            i
            for i, command in enumerate(issued)
            if command.target.distance_to(motion.target) <= SAME_TARGET_MM
        ]
        assert owners, f"motion {motion.number} to {motion.target} matches no command issued"
        assert len(owners) == 1, f"motion {motion.number} matches several commands: {owners}"
        matched.append(owners[0])
    for index in set(matched):
        count = matched.count(index)
        assert count == 1, f"command {index} ({issued[index].target}) ran {count} times"
    assert matched == sorted(matched), f"motions ran out of the order issued: {matched}"
    for index, motion in zip(matched, motions, strict=True):
        command = issued[index]
        if command.gave_up and command.ended_at is not None:
            late = motion.wall_time - command.ended_at
            assert late <= 0, (
                f"command {index} ({command.outcome}) started {late:.3f} s after the master"
                " gave it up"
            )
    for index, command in enumerate(issued):
        if command.outcome == "done":
            assert index in matched, f"command {index} returned done but never ran"


def at_rest(sim: Simulator) -> Callable[[], bool]:
    """For ``sim.wait_for``: True once the TCP did not move between two looks (braked).

    Each call compares the TCP pose with the previous call's, so the looks are as far
    apart as ``wait_for``'s interval.
    """
    last: list[Pose | None] = [None]

    def still() -> bool:
        now, before = sim.tcp_pose(), last[0]
        last[0] = now
        return before is not None and now.distance_to(before) < 1e-6

    return still


def wait_braked(sim: Simulator, ticks: int = 10, timeout: float = 5.0) -> None:
    """Wait until the TCP stands still over ``ticks`` robot ticks (an arm braked to rest)."""
    pose, since = sim.tcp_pose(), sim.ticks

    def still() -> bool:
        nonlocal pose, since
        if sim.ticks < since + ticks:
            return False
        now = sim.tcp_pose()
        if now.is_close(pose, mm=1e-6, deg=1e-6):
            return True
        pose, since = now, sim.ticks
        return False

    sim.wait_for(still, timeout=timeout)


def record_moves(robot: Robot, issued: list[Issued]) -> None:
    """Record every ``move_to`` of ``robot`` in ``issued`` (a runner's steps' and retreat's),
    with its outcome: "done" or the error's type name."""
    move_to = robot.move_to

    def record(pose: Pose, **kwargs: object) -> object:
        command = Issued(pose, time.monotonic())
        issued.append(command)
        try:
            result = move_to(pose, **kwargs)  # type: ignore[arg-type]
        except TMMasterError as exc:
            command.outcome = type(exc).__name__
            raise
        finally:
            command.ended_at = time.monotonic()
        command.outcome = "done"
        return result

    robot.move_to = record  # type: ignore[method-assign]
