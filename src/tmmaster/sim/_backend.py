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

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Protocol, get_args, runtime_checkable

from .._exceptions import TMMasterError
from .._pose import MotionType, Pose

#: Why a backend refused a motion: the target is out of reach, needs a joint beyond its
#: limits, or lies on a singularity.
RejectReason = Literal["reach", "joint_limit", "singularity"]
REJECT_REASONS: tuple[str, ...] = get_args(RejectReason)


class MotionRejectedError(TMMasterError):
    """Raised by :meth:`PhysicsBackend.start_motion`: the target cannot be reached (no motion).

    Args:
        reason: ``"reach"``, ``"joint_limit"`` or ``"singularity"``.
        message: The explanation; default: "motion rejected: REASON".

    Raises:
        ValueError: An unknown reason.
    """

    def __init__(self, reason: RejectReason, message: str = "") -> None:
        if reason not in REJECT_REASONS:
            raise ValueError(f"reason must be one of {', '.join(REJECT_REASONS)}, got {reason!r}")
        self.reason: RejectReason = reason
        super().__init__(message or f"motion rejected: {reason}")


class PhysicsUnavailableError(TMMasterError, ImportError):
    """A physics backend's engine is not installed (the message names the extra to install)."""


#: Why a backend stopped the arm on its own: it hit something (the table, a fixture, a
#: part it pressed on), it carries more than the arm's rated payload, or its TCP ran
#: faster than the robot's TCP speed limit (:attr:`RobotModel.tcp_speed_limit_mm_s`).
FaultKind = Literal["collision", "payload", "speed"]


@dataclass(frozen=True)
class BackendFault:
    """The physics stopped the arm: what happened (the controller reports it as a robot error).

    A backend that detects collisions or an overloaded arm stops its motion itself, in the
    physics step where it happened, and hands the fault to the controller once through
    its optional ``take_fault()`` method (see ``docs/physics-backends.md``).
    """

    #: ``"collision"``, ``"payload"`` or ``"speed"``.
    kind: FaultKind
    #: What happened, for the log (which link touched what, the mass carried).
    message: str


@dataclass(frozen=True)
class ObjectState:
    """Where one object is, whether the gripper holds it, and what it rests on."""

    #: The object's name.
    name: str
    #: Pose of the object's centre (its grasp point), mm / deg, robot base frame.
    pose: Pose
    #: True while the gripper holds it.
    held: bool
    #: Size along the object's own x, y (across the fingers) and z axes, mm.
    size_mm: tuple[float, float, float] = (30.0, 30.0, 30.0)
    #: Its mass, kg.
    mass_kg: float = 0.1
    #: What it lies on at rest: "table" or another object's name; None while it is held,
    #: falling or still moving.
    resting_on: str | None = None


@dataclass(frozen=True)
class GripperState:
    """What the fingers are doing right now."""

    #: Finger width, mm.
    width_mm: float
    #: True while the fingers move.
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

        Args:
            target: The TCP pose to reach.
            motion: PTP (joint interpolation) or LINE (a straight TCP path).
            speed_percent: Speed, % of the arm's maximum (0 < speed <= 100).
            accel_time_s: Time to reach full speed, s.

        Returns:
            The motion's expected duration, simulated seconds.

        Raises:
            MotionRejectedError: The target cannot be reached (nothing starts); any other
                exception is reported as a backend failure.
        """

    def stop_motion(self) -> None:
        """Decelerate and hold the current pose."""

    def step(self, dt: float) -> None:
        """Advance the physics by ``dt`` simulated seconds.

        Args:
            dt: Simulated seconds, >= 0.
        """

    def tcp_pose(self) -> Pose:
        """Current TCP pose.

        Returns:
            The TCP pose, mm / deg.
        """

    def joint_positions_deg(self) -> tuple[float, ...] | None:
        """Current joint angles J1..J6 in degrees, or None without a joint model.

        Returns:
            The six joint angles, or None.
        """

    def flange_pose(self) -> Pose | None:
        """Current flange pose (no tool), or None without a joint model; TCP = flange x tool.

        Returns:
            The flange pose, or None.
        """

    def is_settled(self) -> bool:
        """True when the arm is at rest (no motion running, oscillation died out).

        Returns:
            Whether the arm is at rest.
        """

    def is_ready(self) -> bool:
        """True while the physics view is valid and commands can be executed.

        Returns:
            Whether commands can be executed.
        """

    def reinitialize(self) -> bool:
        """Rebuild the physics view; return True when a running motion survived (or none ran).

        Returns:
            False when the motion that was running is lost: the controller stops it and
            reports it failed, never done.
        """

    def drive_gripper(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> None:
        """Start moving the fingers towards ``width_mm``.

        Args:
            width_mm: Target width, mm.
            speed_mm_s: Finger speed, mm/s (> 0).
            force_n: Gripping force, N (a backend may ignore it).
        """

    def gripper_state(self) -> GripperState:
        """Current finger width, motion and contact.

        Returns:
            The fingers' state.
        """

    def objects(self) -> list[ObjectState]:
        """Every object in the scene with its pose.

        Returns:
            One state per object.
        """


@runtime_checkable
class PathBackend(Protocol):
    """A :class:`PhysicsBackend` that also follows joint targets and circular arcs.

    The robot program's ``PTP("JPP", ...)`` and ``Circle(...)`` need these two methods;
    a backend without them refuses such motions (the program's motion function returns
    False: nothing moves). :class:`~tmmaster.sim.KinematicBackend` and the MuJoCo backend
    have both.
    """

    def start_joint_motion(
        self, joints_deg: Sequence[float], *, speed_percent: float, accel_time_s: float
    ) -> float:
        """Begin a joint-space PTP to ``joints_deg``; return its expected duration in s.

        Args:
            joints_deg: The six joint angles J1..J6 to reach, deg.
            speed_percent: Speed, % of the joints' top speeds (0 < speed <= 100).
            accel_time_s: Time to reach full speed, s.

        Returns:
            The motion's expected duration, simulated seconds.

        Raises:
            MotionRejectedError: The joints cannot be taken (nothing starts).
        """

    def start_arc_motion(
        self, via: Pose, target: Pose, *, speed_percent: float, accel_time_s: float
    ) -> float:
        """Begin a circular arc from the TCP through ``via``'s position to ``target``.

        The orientation turns uniformly from the start's to ``target``'s (a TMscript
        ``Circle`` with arc angle 0).

        Args:
            via: A pose whose position the arc passes through.
            target: The TCP pose at the arc's end.
            speed_percent: Speed, % of the arm's top TCP speed (0 < speed <= 100).
            accel_time_s: Time to reach full speed, s.

        Returns:
            The motion's expected duration, simulated seconds.

        Raises:
            MotionRejectedError: A point of the arc cannot be taken, or no arc passes
                through the points (nothing starts).
        """
