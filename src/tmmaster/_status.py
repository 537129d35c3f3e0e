"""Immutable snapshots of what the robot reports."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

from ._codec import Value
from ._exceptions import ProjectPausedError, RobotFaultError
from ._pose import Pose


class ProjectState(StrEnum):
    """Where a TMflow project stands, as Techman's table reports it (7201-7208)."""

    RUNNING = "running"  # 7202 project running, not paused
    PAUSED = "paused"  # 7204 project paused: Play resumes it
    STOPPED = "stopped"  # neither running nor paused: Play starts it from the beginning
    ERROR = "error"  # 7201 robot error or 7208 e-stop: reset it on the robot first


#: What a command on a stopped project fails with: the state and the fix, one line.
PROJECT_STOPPED = "the TMflow project is stopped: press Play on the robot, or robot.play()"
#: What a command on a paused project fails with (Play resumes a move it interrupted).
PROJECT_PAUSED = (
    "the TMflow project is paused: press Play on the robot, or robot.play()"
    " (Play resumes the move it interrupted, if any)"
)


def project_hint(status: RobotStatus) -> str:
    """``"; <state and fix>"`` for a stopped or paused project, else ``""``.

    Args:
        status: A status snapshot.

    Returns:
        The text to append to a "not ready" message.
    """
    failure = project_failure(status)
    return "" if failure is None else f"; {failure}"


def project_failure(status: RobotStatus) -> RobotFaultError | None:
    """The error a stopped or paused project stands for (it names the fix), else None.

    Args:
        status: A status snapshot.

    Returns:
        RobotFaultError for a stopped project, ProjectPausedError for a paused one.
    """
    state = status.project
    if state is ProjectState.STOPPED:
        return RobotFaultError(PROJECT_STOPPED, pose=status.pose)
    paused = state is ProjectState.PAUSED
    return ProjectPausedError(PROJECT_PAUSED, pose=status.pose) if paused else None


class MovePhase(StrEnum):
    """Where a commanded move stands."""

    SENT = "sent"  # written; the robot has not acknowledged it yet
    RUNNING = "running"  # acknowledged, not finished
    DONE = "done"  # acknowledged, then reported finished
    FAILED = "failed"


@dataclass(frozen=True)
class RobotStatus:
    """One snapshot of the robot's status registers, read block by block."""

    #: "auto", "initialising", "error" (article) or "running", "stopped", "error", "estop" (tmflow).
    mode: str
    #: True while the arm moves (tmflow: while the robot program runs a command; after a
    #: Stop it reads False while the arm still brakes: :meth:`Robot.wait_until_at_rest`).
    moving: bool
    #: True while the robot reports an error.
    error: bool
    #: The robot's error code (0: none).
    error_code: int
    #: True while the emergency stop is pressed.
    estop: bool
    #: Whether the gripper reports an object held; None when the profile has no such field.
    holding: bool | None
    #: The TCP pose the robot reports (mm, deg).
    pose: Pose
    #: Every field that was read, by name (read-only view).
    raw: Mapping[str, Value]
    #: time.monotonic() when the read finished.
    timestamp: float
    #: The joint angles J1..J6 the robot reports, deg; None where the profile does not
    #: publish them (tmflow: Techman's 7013-7024, read with the TCP pose).
    joints: tuple[float, ...] | None = None

    @property
    def ready(self) -> bool:
        """True when the robot can take a motion command (tmflow: its project not paused)."""
        return (
            not self.moving
            and not self.error
            and not self.estop
            and self.mode in ("auto", "running")
            and self.project is not ProjectState.PAUSED
        )

    @property
    def project(self) -> ProjectState | None:
        """The TMflow project's state; None for a profile without a project (article).

        Returns:
            ERROR while the robot is in error or the e-stop is pressed, else PAUSED
            (7204), RUNNING (7202) or STOPPED.
        """
        if "project_running" not in self.raw:
            return None
        if self.error or self.estop:
            return ProjectState.ERROR
        if self.raw.get("paused"):
            return ProjectState.PAUSED
        return ProjectState.RUNNING if self.raw["project_running"] else ProjectState.STOPPED

    def __str__(self) -> str:
        flags = [self.mode, "moving" if self.moving else "idle"]
        if self.error:
            flags.append(f"error {self.error_code}")
        if self.estop:
            flags.append("E-STOP")
        if self.project is ProjectState.PAUSED:
            flags.append("paused")
        if self.holding is not None:
            flags.append("holding" if self.holding else "empty")
        return f"RobotStatus({', '.join(flags)}, pose={self.pose})"


@dataclass(frozen=True)
class MoveProgress:
    """How far a running move has come."""

    #: Where the move stands.
    phase: MovePhase
    #: The last TCP pose read (None before the first read).
    pose: Pose | None
    #: Seconds since the command was written (until it finished, once finished).
    elapsed_s: float
    #: The move's expected duration, s (from the arm model).
    expected_s: float
    #: Fraction of the straight-line distance covered, 0..1 (None before the first pose read).
    fraction: float | None
