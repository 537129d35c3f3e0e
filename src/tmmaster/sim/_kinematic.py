"""The built-in physics backend: analytic motion interpolation, no dynamics.

Motion timing comes from :meth:`RobotModel.motion_time` and the path follows
:func:`trapezoid_progress`, so the simulator and the master's derived timeouts agree by
construction. The path *shape* is not modelled: PTP and Line both move the TCP along
the straight line (only their durations differ). Everything is driven by
:meth:`KinematicBackend.step`; there is no wall clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .._pose import DEFAULT_HOME, MotionType, Pose
from .._robot_models import RobotModel, trapezoid_progress
from ._backend import GripperState, ObjectState
from ._world import World

# Absorbs float drift from summing many small dt values, so a move of T seconds stepped
# in ticks of T/n ends on the n-th tick instead of the (n+1)-th.
_EPS = 1e-9


@dataclass
class _Motion:
    start: Pose
    target: Pose
    duration_s: float
    accel_time_s: float
    elapsed_s: float = 0.0


class KinematicBackend:
    """Analytic :class:`~tmmaster.sim.PhysicsBackend`: interpolated arm, ideal gripper."""

    def __init__(
        self,
        model: RobotModel,
        *,
        home: Pose = DEFAULT_HOME,
        world: World | None = None,
        settle_time_s: float = 0.0,
        gripper_min_width_mm: float = 1.0,
        gripper_max_width_mm: float = 39.0,
    ) -> None:
        if settle_time_s < 0:
            raise ValueError(f"settle_time_s must be >= 0, got {settle_time_s}")
        if not 0 <= gripper_min_width_mm < gripper_max_width_mm:
            raise ValueError(
                "need 0 <= gripper_min_width_mm < gripper_max_width_mm, got "
                f"{gripper_min_width_mm} and {gripper_max_width_mm}"
            )
        self._model = model
        self._world = World() if world is None else world
        self._settle_time_s = settle_time_s
        self._gripper_min = gripper_min_width_mm
        self._gripper_max = gripper_max_width_mm
        self._pose = home
        self._motion: _Motion | None = None
        # Starts "long settled": the arm is at rest when the simulation begins.
        self._rest_s = math.inf
        self._width = gripper_max_width_mm
        self._target_width = gripper_max_width_mm
        self._finger_speed = 0.0
        self._gripper_moving = False
        self._contact = False

    @property
    def model(self) -> RobotModel:
        """The arm model whose limits time the motions."""
        return self._model

    @property
    def world(self) -> World:
        """The objects on the table."""
        return self._world

    @property
    def motion_running(self) -> bool:
        """True while a motion is being interpolated (settling not included)."""
        return self._motion is not None

    # -- arm ---------------------------------------------------------------------------

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        """Begin a motion from the current pose towards ``target``; return its duration in s."""
        if accel_time_s < 0:
            raise ValueError(f"accel_time_s must be >= 0, got {accel_time_s}")
        duration = self._model.motion_time(
            self._pose,
            target,
            speed_percent=speed_percent,
            motion=motion,
            accel_time_s=accel_time_s,
        )
        # A running motion is simply replaced: queueing or rejecting is the controller's job.
        self._motion = _Motion(self._pose, target, duration, accel_time_s)
        self._rest_s = 0.0
        return duration

    def stop_motion(self) -> None:
        """Hold the current pose; the kinematic arm decelerates instantly."""
        if self._motion is not None:
            self._motion = None
            self._rest_s = 0.0

    def tcp_pose(self) -> Pose:
        """Current TCP pose."""
        return self._pose

    def joint_positions_deg(self) -> tuple[float, ...] | None:
        """None: the analytic backend moves the TCP, it has no joint model."""
        return None

    def flange_pose(self) -> Pose | None:
        """None: the analytic backend moves the TCP, it has no joint model."""
        return None

    def is_settled(self) -> bool:
        """True once no motion runs and ``settle_time_s`` has passed since the last one."""
        return self._motion is None and self._rest_s + _EPS >= self._settle_time_s

    def is_ready(self) -> bool:
        """Always True: the analytic model has no physics view to lose."""
        return True

    def reinitialize(self) -> bool:
        """Nothing to rebuild for the analytic model: a running motion always survives."""
        return True

    # -- simulation --------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance arm, gripper and held object by ``dt`` simulated seconds."""
        if dt < 0 or not math.isfinite(dt):
            raise ValueError(f"dt must be a finite number >= 0, got {dt}")
        self._step_arm(dt)
        self._step_gripper(dt)
        self._world.follow(self._pose)

    def _step_arm(self, dt: float) -> None:
        motion = self._motion
        if motion is None:
            self._rest_s += dt
            return
        motion.elapsed_s += dt
        if motion.elapsed_s + _EPS >= motion.duration_s:
            # Land exactly on the target, not on an interpolated approximation of it.
            self._pose = motion.target
            self._motion = None
            self._rest_s = max(0.0, motion.elapsed_s - motion.duration_s)
            return
        progress = trapezoid_progress(motion.elapsed_s, motion.duration_s, motion.accel_time_s)
        self._pose = _interpolate(motion.start, motion.target, progress)

    # -- gripper -----------------------------------------------------------------------

    def drive_gripper(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> None:
        """Move the fingers towards ``width_mm`` (clamped to the stroke); force is ignored."""
        if speed_mm_s <= 0 or not math.isfinite(speed_mm_s):
            raise ValueError(f"speed_mm_s must be > 0, got {speed_mm_s}")
        if force_n < 0:
            raise ValueError(f"force_n must be >= 0, got {force_n}")
        # Real fingers cannot go past their end stops; they stop there.
        self._target_width = min(max(width_mm, self._gripper_min), self._gripper_max)
        self._finger_speed = speed_mm_s
        if self._world.held is not None and self._target_width <= self._width:
            # Squeezing a held object harder: the object blocks the fingers.
            self._contact = True
            self._gripper_moving = False
            return
        self._contact = False
        self._gripper_moving = self._target_width != self._width

    def _step_gripper(self, dt: float) -> None:
        if not self._gripper_moving:
            return
        travel = self._finger_speed * dt
        if self._target_width < self._width:
            candidate = self._world.grasp_candidate(
                self._pose, current_width_mm=self._width, target_width_mm=self._target_width
            )
            new_width = max(self._target_width, self._width - travel)
            if candidate is not None and new_width <= candidate.width_mm:
                self._width = candidate.width_mm
                self._gripper_moving = False
                self._contact = True
                self._world.grasp(candidate.name, self._pose)
                return
        else:
            new_width = min(self._target_width, self._width + travel)
            held = self._world.held
            if held is not None and new_width > held.width_mm:
                self._world.release(self._pose)
        self._width = new_width
        if self._width == self._target_width:
            self._gripper_moving = False

    def gripper_state(self) -> GripperState:
        """Current finger width, motion and contact."""
        return GripperState(
            width_mm=self._width, moving=self._gripper_moving, contact=self._contact
        )

    def objects(self) -> list[ObjectState]:
        """Every object on the table with its pose."""
        return self._world.states()


def _interpolate(start: Pose, target: Pose, progress: float) -> Pose:
    """Pose ``progress`` (0..1) of the way from ``start`` to ``target``, angles the short way."""
    position = [
        a + (b - a) * progress
        for a, b in zip(start.as_list()[:3], target.as_list()[:3], strict=True)
    ]
    angles = [
        _normalize(a + _wrap(b - a) * progress)
        for a, b in zip(start.as_list()[3:], target.as_list()[3:], strict=True)
    ]
    return Pose(*position, *angles)


def _wrap(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0


def _normalize(angle: float) -> float:
    # (-180, 180] rather than [-180, 180): keeps the common rx = 180 from reading as -180.
    angle = math.fmod(angle, 360.0)
    if angle > 180.0:
        return angle - 360.0
    if angle <= -180.0:
        return angle + 360.0
    return angle
