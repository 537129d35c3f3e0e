"""The built-in physics backend: a TM arm moved through its joint chain, no dynamics.

The arm's state is its six joint angles; poses come from the shared arm model
(:class:`~tmmaster.RobotModel`: forward and inverse kinematics, limits, motion times),
the same model the master validates targets and derives its timeouts with, so the two
agree by construction.

- **PTP** moves in joint space: the target's joints are solved nearest the current
  ones, every joint follows the same trapezoid (:func:`trapezoid_progress`) over
  :meth:`RobotModel.ptp_time`, and the TCP is the forward kinematics of the joints, so
  its path curves.
- **Line** moves the TCP along the straight segment (position linear, orientation by the
  shortest turn); the joints follow by inverse kinematics, and the whole path is
  checked before the motion starts (:meth:`RobotModel.line_joints`); its duration is
  :meth:`RobotModel.line_time`.
- A target (or a straight path) the arm cannot take is refused before anything moves:
  :class:`~tmmaster.sim.MotionRejectedError` with the reason ``reach``, ``joint_limit`` or
  ``singularity``.
- ``tool`` is the TCP in the flange frame: TCP = flange x tool.

Everything is driven by :meth:`KinematicBackend.step`; there is no wall clock.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from .. import _kinematics as kin
from .._exceptions import ConfigError, UnreachablePoseError
from .._pose import DEFAULT_HOME, MotionType, Pose
from .._robot_models import Joints, RobotModel, trapezoid_progress
from ._backend import GripperState, MotionRejectedError, ObjectState, RejectReason
from ._world import World

# Absorbs float drift from summing many small dt values, so a move of T seconds stepped
# in ticks of T/n ends on the n-th tick instead of the (n+1)-th.
_EPS = 1e-9


@dataclass
class _Motion:
    kind: MotionType
    start_joints: Joints
    target_joints: Joints
    #: The commanded TCP pose: reported exactly once the motion is over.
    target: Pose
    duration_s: float
    accel_time_s: float
    #: Line only: the TCP at the start, the target as transforms, joint samples along
    #: the path at evenly spaced path fractions (the first is the start joints).
    start_t: kin.Transform = kin.IDENTITY
    target_t: kin.Transform = kin.IDENTITY
    samples: list[Joints] = field(default_factory=list)
    #: Line only: the orientation does not change (reported as the start's angles).
    same_orientation: bool = False
    start: Pose | None = None
    elapsed_s: float = 0.0


class KinematicBackend:
    """Analytic :class:`~tmmaster.sim.PhysicsBackend`: a TM joint chain, ideal gripper.

    The simulator's default backend (``Simulator(physics="kinematic")``): joints
    interpolated along the arm model's motion times, fingers at a constant speed,
    objects grasped and dropped by the :class:`World`'s rules.

    Args:
        model: The arm (``tmmaster.robot_model("tm5-700")``).
        home: The TCP pose at the start (must be reachable).
        tool: The TCP in the flange frame (None: the TCP is the flange).
        world: The objects on the table (None: one part at ``DEFAULT_PART_POSE``).
        settle_time_s: How long the arm takes to come to rest after a motion, s.
        gripper_min_width_mm: The fingers' smallest width, mm.
        gripper_max_width_mm: The fingers' largest width (their width at the start), mm.

    Raises:
        ValueError: A negative settle time or an empty finger stroke.
        ConfigError: ``tool`` is not a Pose.
        UnreachablePoseError: ``home`` cannot be reached.
    """

    def __init__(
        self,
        model: RobotModel,
        *,
        home: Pose = DEFAULT_HOME,
        tool: Pose | None = None,
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
        if tool is not None and not isinstance(tool, Pose):
            raise ConfigError(
                f"tool must be a tmmaster.Pose (the TCP in the flange frame), got {tool!r}"
            )
        self._model = model
        self._tool = tool
        try:
            joints = model.inverse(home, tool=tool)
        except UnreachablePoseError as exc:
            raise UnreachablePoseError(f"home: {exc}", reason=exc.reason, pose=exc.pose) from exc
        self._world = World() if world is None else world
        self._settle_time_s = settle_time_s
        self._gripper_min = gripper_min_width_mm
        self._gripper_max = gripper_max_width_mm
        self._joints: Joints = joints
        self._pose = home
        self._flange: Pose | None = None
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
        """The arm model: joint chain, limits, motion times."""
        return self._model

    @property
    def tool(self) -> Pose | None:
        """The TCP in the flange frame (None: the TCP is the flange)."""
        return self._tool

    def set_tool(self, tool: Pose | None) -> None:
        """Change the TCP (a program's ``ChangeTCP``) at rest: the joints stay, the TCP moves.

        Args:
            tool: The new TCP in the flange frame (None: the flange).

        Raises:
            ConfigError: a motion is running (TMflow changes the tool for the motions
                that follow, not the one under way).
        """
        if self._motion is not None:
            raise ConfigError("the tool cannot change while the arm moves")
        self._tool = tool
        self._pose = self._model.forward(self._joints, tool)

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
        """Begin a motion from the current pose towards ``target``; return its duration in s.

        Args:
            target: The TCP pose to reach.
            motion: PTP (joint interpolation) or LINE (a straight TCP path).
            speed_percent: Speed, % of the arm's maximum (0 < speed <= 100).
            accel_time_s: Time to reach full speed, s.

        Returns:
            The motion's duration, simulated seconds.

        Raises:
            MotionRejectedError: The target, or for a Line any point of the straight path,
                cannot be taken by the arm (the current motion, if any, goes on).
            ValueError: A speed or acceleration time out of range.
        """
        if accel_time_s < 0:
            raise ValueError(f"accel_time_s must be >= 0, got {accel_time_s}")
        if not 0 < speed_percent <= 100:
            raise ValueError(f"speed_percent must be in (0, 100], got {speed_percent}")
        try:
            if motion is MotionType.LINE:
                planned = self._plan_line(target, speed_percent, accel_time_s)
            else:
                planned = self._plan_ptp(target, speed_percent, accel_time_s)
        except UnreachablePoseError as exc:
            raise MotionRejectedError(_reason(exc.reason), str(exc)) from exc
        # A running motion is simply replaced: queueing or rejecting is the controller's job.
        self._motion = planned
        self._rest_s = 0.0
        return planned.duration_s

    def _plan_ptp(self, target: Pose, speed_percent: float, accel_time_s: float) -> _Motion:
        start = self._joints
        joints = self._model.inverse(target, seed_deg=start, tool=self._tool)
        duration = self._model.ptp_time(
            start, joints, speed_percent=speed_percent, accel_time_s=accel_time_s
        )
        return _Motion(MotionType.PTP, start, joints, target, duration, accel_time_s)

    def _plan_line(self, target: Pose, speed_percent: float, accel_time_s: float) -> _Motion:
        start = self._pose
        samples = self._model.line_joints(
            start, target, start_joints_deg=self._joints, tool=self._tool
        )
        duration = self._model.line_time(
            start,
            target,
            speed_percent=speed_percent,
            accel_time_s=accel_time_s,
            tool=self._tool,
            samples=samples,
        )
        # The path starts where the joints are (the solver's copy differs by its tolerance).
        samples[0] = self._joints
        start_t, target_t = kin.pose_to_transform(start), kin.pose_to_transform(target)
        return _Motion(
            MotionType.LINE,
            self._joints,
            samples[-1],
            target,
            duration,
            accel_time_s,
            start_t=start_t,
            target_t=target_t,
            samples=samples,
            same_orientation=kin.rotation_error(start_t, target_t) == (0.0, 0.0, 0.0),
            start=start,
        )

    def stop_motion(self) -> None:
        """Hold the current joints; the kinematic arm decelerates instantly."""
        if self._motion is not None:
            self._motion = None
            self._rest_s = 0.0

    def tcp_pose(self) -> Pose:
        """Current TCP pose: the flange pose times the tool (the commanded pose at rest).

        Returns:
            The TCP pose, mm / deg.
        """
        return self._pose

    def joint_positions_deg(self) -> tuple[float, ...] | None:
        """Current joint angles J1..J6, degrees.

        Returns:
            The six joint angles.
        """
        return self._joints

    def flange_pose(self) -> Pose | None:
        """Current flange pose: the forward kinematics of the joints, no tool.

        Returns:
            The flange pose.
        """
        if self._flange is None:
            self._flange = self._model.forward(self._joints)
        return self._flange

    def is_settled(self) -> bool:
        """True once no motion runs and ``settle_time_s`` has passed since the last one.

        Returns:
            Whether the arm is at rest.
        """
        return self._motion is None and self._rest_s + _EPS >= self._settle_time_s

    def is_ready(self) -> bool:
        """Always True: the analytic model has no physics view to lose.

        Returns:
            True.
        """
        return True

    def reinitialize(self) -> bool:
        """Nothing to rebuild for the analytic model: a running motion always survives.

        Returns:
            True.
        """
        return True

    # -- simulation --------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance arm, gripper and held object by ``dt`` simulated seconds.

        Args:
            dt: Simulated seconds, >= 0.

        Raises:
            ValueError: A negative or non-finite ``dt``.
        """
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
            self._set(motion.target_joints, motion.target)
            self._motion = None
            self._rest_s = max(0.0, motion.elapsed_s - motion.duration_s)
            return
        progress = trapezoid_progress(motion.elapsed_s, motion.duration_s, motion.accel_time_s)
        if motion.kind is MotionType.PTP:
            joints = _lerp(motion.start_joints, motion.target_joints, progress)
            self._set(joints, self._model.forward(joints, self._tool))
        else:
            self._set(*self._line_point(motion, progress))

    def _line_point(self, motion: _Motion, progress: float) -> tuple[Joints, Pose]:
        """Joints and TCP ``progress`` (0..1) of the way along a Line's straight path."""
        t = kin.interpolate(motion.start_t, motion.target_t, progress)
        pose = kin.transform_to_pose(t)
        if motion.same_orientation and motion.start is not None:
            # An unchanged orientation reads unchanged (no round trip through a matrix).
            pose = Pose(pose.x, pose.y, pose.z, motion.start.rx, motion.start.ry, motion.start.rz)
        # The precomputed samples bracket the point: their interpolation is the seed.
        samples = motion.samples
        where = progress * (len(samples) - 1)
        i = min(int(where), len(samples) - 2)
        seed = _lerp(samples[i], samples[i + 1], where - i)
        try:
            joints = self._model.inverse(pose, seed_deg=seed, tool=self._tool, same_branch=True)
        except UnreachablePoseError:
            # Between two checked samples the solver may still touch a margin; the
            # interpolated samples are then the joints (off the line by far under 1 mm).
            return seed, self._model.forward(seed, self._tool)
        return joints, pose

    def _set(self, joints: Joints, tcp: Pose) -> None:
        self._joints = joints
        self._pose = tcp
        self._flange = None

    # -- gripper -----------------------------------------------------------------------

    def drive_gripper(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> None:
        """Move the fingers towards ``width_mm`` (clamped to the stroke); force is ignored.

        Args:
            width_mm: Target width, mm.
            speed_mm_s: Finger speed, mm/s (> 0).
            force_n: Ignored by this backend.

        Raises:
            ValueError: A speed that is not > 0.
        """
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
        """Current finger width, motion and contact.

        Returns:
            The fingers' state.
        """
        return GripperState(
            width_mm=self._width, moving=self._gripper_moving, contact=self._contact
        )

    def objects(self) -> list[ObjectState]:
        """Every object on the table with its pose.

        Returns:
            One state per object.
        """
        return self._world.states()


def _lerp(a: Sequence[float], b: Sequence[float], fraction: float) -> Joints:
    q = [x + (y - x) * fraction for x, y in zip(a, b, strict=True)]
    return (q[0], q[1], q[2], q[3], q[4], q[5])


def _reason(reason: str) -> RejectReason:
    # UnreachablePoseError.reason is one of the same three words.
    if reason == "joint_limit":
        return "joint_limit"
    if reason == "singularity":
        return "singularity"
    return "reach"
