"""Immutable snapshots of what the robot reports."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

from ._codec import Value
from ._pose import Pose


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
    #: True while the arm moves.
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
        """True when the robot can take a motion command."""
        return (
            not self.moving
            and not self.error
            and not self.estop
            and self.mode
            in (
                "auto",
                "running",
            )
        )

    def __str__(self) -> str:
        flags = [self.mode, "moving" if self.moving else "idle"]
        if self.error:
            flags.append(f"error {self.error_code}")
        if self.estop:
            flags.append("E-STOP")
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
