"""The physics backend interface the simulated controller drives.

The controller (Modbus handshake, faults, error codes) knows nothing about how the
arm and gripper are simulated; it talks to one :class:`PhysicsBackend`. The built-in
:class:`~tmmaster.sim.KinematicBackend` interpolates motions analytically; an Isaac
Sim, MuJoCo or PyBullet scene plugs in by implementing the same methods (see
``docs/physics-backends.md``).

All times are *simulated* seconds: the controller calls :meth:`PhysicsBackend.step`
with the simulated time that passed since the previous tick.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol, get_args, runtime_checkable

from .._exceptions import TMMasterError
from .._pose import MotionType, Pose

#: Why a backend refused a motion: the target is out of reach, needs a joint beyond its
#: limits, or lies on a singularity.
RejectReason = Literal["reach", "joint_limit", "singularity"]
REJECT_REASONS: tuple[str, ...] = get_args(RejectReason)


class MotionRejectedError(TMMasterError):
    """Raised by :meth:`PhysicsBackend.start_motion`: the target cannot be reached (no motion)."""

    def __init__(self, reason: RejectReason, message: str = "") -> None:
        if reason not in REJECT_REASONS:
            raise ValueError(f"reason must be one of {', '.join(REJECT_REASONS)}, got {reason!r}")
        self.reason: RejectReason = reason
        super().__init__(message or f"motion rejected: {reason}")


class PhysicsUnavailableError(TMMasterError, ImportError):
    """A physics backend's engine is not installed (the message names the extra to install)."""


@dataclass(frozen=True)
class ObjectState:
    """Where one object is, whether the gripper holds it, and what it rests on."""

    name: str
    #: Pose of the object's centre (its grasp point), mm / deg, robot base frame.
    pose: Pose
    held: bool
    #: Size along the object's own x, y (across the fingers) and z axes, mm.
    size_mm: tuple[float, float, float] = (30.0, 30.0, 30.0)
    mass_kg: float = 0.1
    #: What it lies on at rest: "table" or another object's name; None while it is held,
    #: falling or still moving.
    resting_on: str | None = None


@dataclass(frozen=True)
class GripperState:
    """What the fingers are doing right now."""

    width_mm: float
    moving: bool
    #: Fingers stopped on an object (a grip is detected).
    contact: bool


@runtime_checkable
class PhysicsBackend(Protocol):
    """Moves the arm and gripper and reports what the physics did."""

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        """Begin a motion towards ``target``; return its expected duration in seconds.

        Raises :class:`MotionRejectedError` (and starts nothing) when the target cannot be
        reached; any other exception is reported as a backend failure.
        """

    def stop_motion(self) -> None:
        """Decelerate and hold the current pose."""

    def step(self, dt: float) -> None:
        """Advance the physics by ``dt`` simulated seconds."""

    def tcp_pose(self) -> Pose:
        """Current TCP pose."""

    def joint_positions_deg(self) -> tuple[float, ...] | None:
        """Current joint angles J1..J6 in degrees, or None without a joint model."""

    def flange_pose(self) -> Pose | None:
        """Current flange pose (no tool), or None without a joint model; TCP = flange x tool."""

    def is_settled(self) -> bool:
        """True when the arm is at rest (no motion running, oscillation died out)."""

    def is_ready(self) -> bool:
        """True while the physics view is valid and commands can be executed."""

    def reinitialize(self) -> bool:
        """Rebuild the physics view; return True when a running motion survived (or none ran).

        False means the motion that was running is lost: the controller stops it and
        reports it failed, never done.
        """

    def drive_gripper(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> None:
        """Start moving the fingers towards ``width_mm``."""

    def gripper_state(self) -> GripperState:
        """Current finger width, motion and contact."""

    def objects(self) -> list[ObjectState]:
        """Every object in the scene with its pose."""
