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
- A **joint target** (``start_joint_motion``, the program's ``PTP("JPP", ...)``) moves in
  joint space to exactly those joints (no inverse kinematics), timed like a PTP.
- A **Circle** (``start_arc_motion``) moves the TCP along the arc through the via point
  (:class:`~tmmaster._kinematics.Arc`), its orientation turning uniformly, the joints
  following by inverse kinematics like a Line's; its duration is
  :meth:`RobotModel.arc_time`.
- ``tool`` is the TCP in the flange frame: TCP = flange x tool.
- The gripper follows the grasp rule of :func:`~tmmaster.sim._world.grasp_fit` (the same
  pads, stroke and friction as the MuJoCo scene): a part too heavy for the grip force
  is squeezed but slips out when the arm moves away.
- While the arm moves, its links (capsules round the joint chain, the shapes of the
  MuJoCo scene, :mod:`~tmmaster.sim._collide`), the flange, the palm's and the pads'
  boxes and a held part's box are checked against the table top and the world's
  fixtures, and the pads against the parts: a collision stops the arm and is handed to
  the controller (:meth:`KinematicBackend.take_fault`), as is a carried part that with
  the gripper's own mass weighs more than the arm's rated payload (:mod:`._payload`).
- A PTP whose TCP runs faster than the robot's TCP speed limit
  (:attr:`~tmmaster.RobotModel.tcp_speed_limit_mm_s`, TMflow's Performance Safety "TCP
  Speed", 1500 mm/s by default) stops: the arm brakes from where its TCP first runs
  faster (:meth:`RobotModel.ptp_tcp_speeds`, the master's own check) and the fault
  (``"speed"``) is handed to the controller, which reports Techman's 0x0021.
- A stop (:meth:`KinematicBackend.stop_motion`: the Stop command, an e-stop, a robot
  error, an overload) brakes along the path over a time and a distance
  (:mod:`._stopping`); a collision stops the arm where it touched.

Everything is driven by :meth:`KinematicBackend.step`; there is no wall clock.
"""

from __future__ import annotations

import contextlib
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from .. import _body as body
from .. import _kinematics as kin
from .._exceptions import ConfigError, UnreachablePoseError
from .._pose import DEFAULT_HOME, MotionType, Pose
from .._robot_models import Joints, RobotModel, arc_through, joint_chain, trapezoid_progress
from ._backend import BackendFault, GripperState, MotionRejectedError, ObjectState, RejectReason
from ._collide import (
    FLANGE_RADIUS_MM,
    PALM_CENTRE_MM,
    PALM_HALF_MM,
    Box,
    arm_links,
    box_depth,
    link_contacts,
    segment_depth,
    transform_point,
)
from ._payload import over_payload
from ._stopping import (
    Braking,
    over_speed_at,
    path_gradient,
    plan_braking,
    speed_fault,
    trapezoid_rate,
)
from ._world import (
    GRASP_MODES,
    TABLE_CENTRE_XY_MM,
    TABLE_HALF_SIZE_XY_MM,
    GraspMode,
    GripperGeometry,
    World,
    gripper_geometry,
    held_frame,
    in_tool_frame,
    pad_overlaps,
)

# Absorbs float drift from summing many small dt values, so a move of T seconds stepped
# in ticks of T/n ends on the n-th tick instead of the (n+1)-th.
_EPS = 1e-9

#: The arm deeper in the table than when its motion started by more than this is a
#: collision, mm (the MuJoCo backend's figure).
_COLLISION_DEPTH_MM = 0.2
#: What a contact is keyed by: (what touches: "the tool", "link 3", "held part NAME";
#: what it touches: "the table", "fixture NAME").
_ContactKey = tuple[str, str]
#: The flange disc's rim, as points on the flange plane (flange frame), mm.
_FLANGE_RIM = tuple(
    (
        FLANGE_RADIUS_MM * math.cos(k * math.pi / 4),
        FLANGE_RADIUS_MM * math.sin(k * math.pi / 4),
        0.0,
    )
    for k in range(8)
)
#: The palm's 8 corners in the TCP frame, mm.
_PALM_CORNERS = tuple(
    (PALM_CENTRE_MM[0] + x, PALM_CENTRE_MM[1] + y, PALM_CENTRE_MM[2] + z)
    for x in (-PALM_HALF_MM[0], PALM_HALF_MM[0])
    for y in (-PALM_HALF_MM[1], PALM_HALF_MM[1])
    for z in (-PALM_HALF_MM[2], PALM_HALF_MM[2])
)
#: Halvings of a step that find where in it a collision began (1/128 of the step).
_CONTACT_BISECTIONS = 7


@dataclass(frozen=True)
class _PadContact:
    """A pad against a part at a check: overlaps along the tool's axes and how it got in."""

    overlaps: tuple[float, float, float]
    #: The index of the tool axis nearest the vertical.
    vertical: int
    #: It came down on the part from right above it.
    landed: bool = False
    #: Inside the part when the motion started: its vertical overlap then, mm.
    baseline: float | None = None


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
    #: A circle: the arc the TCP follows (a Line otherwise).
    arc: kin.Arc | None = None
    #: Stopped: how it brakes along its path (:mod:`._stopping`), from ``braking_from_s``.
    braking: Braking | None = None
    braking_from_s: float = 0.0
    #: A PTP whose TCP runs faster than the robot's TCP speed limit: when it first does
    #: (s after the start) and its top speed (mm/s); None: it never does.
    over_speed: tuple[float, float] | None = None

    def progress(self, elapsed_s: float) -> float:
        """The path's progress (0..1) ``elapsed_s`` after the start, braking included."""
        if self.braking is not None and elapsed_s >= self.braking_from_s:
            return self.braking.progress(elapsed_s - self.braking_from_s)
        return trapezoid_progress(elapsed_s, self.duration_s, self.accel_time_s)


class KinematicBackend:
    """Analytic :class:`~tmmaster.sim.PhysicsBackend`: a TM joint chain, ideal gripper.

    The simulator's default backend (``Cell(physics="kinematic")``): joints
    interpolated along the arm model's motion times, fingers at a constant speed,
    objects grasped and dropped by the :class:`World`'s rules.

    Args:
        model: The arm (``tmmaster.robot_model("tm5-700")``).
        home: The TCP pose at the start (must be reachable).
        tool: The TCP in the flange frame (None: the TCP is the flange).
        world: The objects on the table (None: one part at ``DEFAULT_PART_POSE``).
        settle_time_s: How long the arm takes to come to rest after a motion, s.
        gripper_min_width_mm: The fingers' smallest width (None: the gripper's), mm.
        gripper_max_width_mm: The fingers' largest width, their width at the start (None:
            the gripper's), mm.
        gripper: The fingers' stroke, pads and friction (None: an OnRobot 2FG7).
        grasp: ``"friction"`` (a part too heavy for the grip force slips out) or
            ``"weld"`` (a part between the pads is carried whatever its mass).

    Raises:
        ValueError: A negative settle time, an empty finger stroke or a bad grasp mode.
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
        gripper_min_width_mm: float | None = None,
        gripper_max_width_mm: float | None = None,
        gripper: GripperGeometry | None = None,
        grasp: GraspMode = "friction",
    ) -> None:
        if settle_time_s < 0:
            raise ValueError(f"settle_time_s must be >= 0, got {settle_time_s}")
        if grasp not in GRASP_MODES:
            raise ValueError(f"grasp must be one of {', '.join(GRASP_MODES)}, got {grasp!r}")
        self._gripper = gripper_geometry(gripper, gripper_min_width_mm, gripper_max_width_mm)
        self._grasp_mode: GraspMode = grasp
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
        self._gripper_min = self._gripper.min_width_mm
        self._gripper_max = self._gripper.max_width_mm
        self._joints: Joints = joints
        self._pose = home
        self._flange: Pose | None = None
        self._motion: _Motion | None = None
        self._time_rate = 1.0
        # Starts "long settled": the arm is at rest when the simulation begins.
        self._rest_s = math.inf
        self._init_gripper()
        self._init_collisions(model)

    def _init_gripper(self) -> None:
        """The fingers' state: open, at rest, touching nothing."""
        self._width = self._gripper_max
        self._target_width = self._gripper_max
        self._finger_speed = 0.0
        self._force = 40.0
        self._gripper_moving = False
        self._contact = False
        # Where the fingers stopped on the held part (its width, or jammed its edges'), mm.
        self._held_width = 0.0
        # The width the fingers started closing from (a part between them then is pushed
        # along by the first pad that touches it).
        self._close_from = self._gripper_max
        # A part squeezed but too heavy for the grip: it stays while the arm moves away.
        self._pinched: str | None = None

    def _init_collisions(self, model: RobotModel) -> None:
        """The arm's links, the obstacles and the caches the collision checks keep."""
        # Collisions: what touches the table or a fixture, and how deep, when the running
        # motion started (a contact being backed out of is known); the pads in the parts
        # then; and the fault not yet taken.
        self._chain = joint_chain(model)
        self._links = arm_links(self._chain)
        self._link_names = {link: f"link {link}" for link, _, _ in self._links}
        (cx, cy), (sx, sy) = TABLE_CENTRE_XY_MM, TABLE_HALF_SIZE_XY_MM
        self._table_box = Box.table(self._world.table_top_z_mm, (cx, cy), (sx, sy))
        self._fixture_boxes = tuple(
            Box.at(f"fixture {f.name}", f.pose, f.size_mm) for f in self._world.fixtures
        )
        self._obstacles = (self._table_box, *self._fixture_boxes)
        self._start_depths: dict[_ContactKey, float] = {}
        # The tool's points in the TCP frame and their reach, for (finger width, tool).
        self._local: tuple[float, list[tuple[float, float, float]]] = (0.0, [])
        self._local_of: tuple[float, Pose | None] | None = None
        # The joints' frames (the chain's forward kinematics) and origins, for the joints
        # they were computed at: the pose, the links, the body check and the flange of a
        # tick all take the same.
        self._frames: list[kin.Frame] = []
        self._frames_of: Joints | None = None
        self._origins: list[tuple[float, float, float]] = []
        self._origins_of: Joints | None = None
        # The TCP's transform, for the pose it was computed from.
        self._tcp_t_of: Pose | None = None
        self._tcp_t_value = kin.IDENTITY
        self._start_overlaps: dict[tuple[str, int], _PadContact] = {}
        self._overlaps_now: dict[tuple[str, int], _PadContact] = {}
        self._fault: BackendFault | None = None
        self._tool_back_of: Pose | None = None
        self._tool_back_t = kin.IDENTITY

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
    def gripper(self) -> GripperGeometry:
        """The fingers' stroke, pads and friction."""
        return self._gripper

    @property
    def grasp(self) -> GraspMode:
        """``"friction"`` or ``"weld"``: how a part between the pads is held."""
        return self._grasp_mode

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
        return self._begin(planned)

    def start_joint_motion(
        self, joints_deg: Sequence[float], *, speed_percent: float, accel_time_s: float
    ) -> float:
        """Begin a joint-space PTP to exactly ``joints_deg``; return its duration in s.

        Args:
            joints_deg: The six joint angles J1..J6 to reach, deg.
            speed_percent: Speed, % of the joints' top speeds (0 < speed <= 100).
            accel_time_s: Time to reach full speed, s.

        Returns:
            The motion's duration, simulated seconds.

        Raises:
            MotionRejectedError: A joint past its range, a singularity or the flange out
                of reach (the current motion, if any, goes on).
            ValueError: A speed or acceleration time out of range.
        """
        _check_speed(speed_percent, accel_time_s)
        try:
            joints = self._model.check_joints(joints_deg, tool=self._tool)
        except UnreachablePoseError as exc:
            raise MotionRejectedError(_reason(exc.reason), str(exc)) from exc
        target = self._model.forward(joints, self._tool)
        return self._begin(self._ptp(joints, target, speed_percent, accel_time_s))

    def start_arc_motion(
        self, via: Pose, target: Pose, *, speed_percent: float, accel_time_s: float
    ) -> float:
        """Begin a circular arc through ``via``'s position to ``target``; return its duration.

        Args:
            via: A pose whose position the arc passes through.
            target: The TCP pose at the arc's end.
            speed_percent: Speed, % of the arm's top TCP speed (0 < speed <= 100).
            accel_time_s: Time to reach full speed, s.

        Returns:
            The motion's duration, simulated seconds.

        Raises:
            MotionRejectedError: No arc passes through the points, or a point of it
                cannot be taken (the current motion, if any, goes on).
            ValueError: A speed or acceleration time out of range.
        """
        _check_speed(speed_percent, accel_time_s)
        start = self._pose
        try:
            arc = arc_through(start, via, target)
            samples = self._model.arc_joints(
                start, via, target, start_joints_deg=self._joints, tool=self._tool
            )
        except UnreachablePoseError as exc:
            raise MotionRejectedError(_reason(exc.reason), str(exc)) from exc
        except ConfigError as exc:
            raise MotionRejectedError("reach", str(exc)) from exc
        duration = self._model.arc_time(
            start,
            via,
            target,
            speed_percent=speed_percent,
            accel_time_s=accel_time_s,
            tool=self._tool,
            samples=samples,
        )
        samples[0] = self._joints
        return self._begin(
            _Motion(
                MotionType.LINE,
                self._joints,
                samples[-1],
                target,
                duration,
                accel_time_s,
                start_t=arc.start,
                target_t=arc.end,
                samples=samples,
                same_orientation=kin.rotation_error(arc.start, arc.end) == (0.0, 0.0, 0.0),
                start=start,
                arc=arc,
            )
        )

    def _begin(self, planned: _Motion) -> float:
        # A running motion is simply replaced: queueing or rejecting is the controller's job.
        self._motion = planned
        self._rest_s = 0.0
        # Contacts the arm already has (a collision it is backing out of) are known: only
        # deeper ones are collisions.
        self._start_depths = self._contacts()
        self._start_overlaps = self._start_contacts()
        return planned.duration_s

    def _plan_ptp(self, target: Pose, speed_percent: float, accel_time_s: float) -> _Motion:
        joints = self._model.inverse(target, seed_deg=self._joints, tool=self._tool)
        return self._ptp(joints, target, speed_percent, accel_time_s)

    def _ptp(self, joints: Joints, target: Pose, speed_percent: float, accel_s: float) -> _Motion:
        """A PTP from where the arm is to ``joints``, and when its TCP first runs faster than
        the robot's TCP speed limit (:func:`over_speed_at`): the real robot's safety stops it
        there (TMflow 2.24, 3 Safety Settings, Speed & Force, p. 38)."""
        model, start = self._model, self._joints
        duration = model.ptp_time(start, joints, speed_percent=speed_percent, accel_time_s=accel_s)
        motion = _Motion(MotionType.PTP, start, joints, target, duration, accel_s)
        speeds = model.ptp_tcp_speeds(start, joints, speed_percent, accel_s, self._tool)
        motion.over_speed = over_speed_at(speeds, duration, model.tcp_speed_limit_mm_s)
        return motion

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

    def scale_time(self, rate: float) -> None:
        """From now on, run the motion's time ``rate`` times as fast as planned (1: as
        planned), a braking included: the robot's speed override changed mid-move.

        Args:
            rate: Simulated motion seconds per simulated second, > 0.
        """
        self._time_rate = rate

    def stop_motion(self) -> None:
        """Brake to rest along the path (:mod:`._stopping`): the arm moves until at rest."""
        motion = self._motion
        if motion is None or motion.braking is not None:
            return
        t = motion.elapsed_s
        progress = motion.progress(t)
        rate = trapezoid_rate(t, motion.duration_s, motion.accel_time_s)
        samples = motion.samples or [motion.start_joints, motion.target_joints]
        braking = plan_braking(
            progress, rate, path_gradient(samples, progress), self._model.joint_speed_deg_s
        )
        if braking is not None:  # None: the motion's own end comes first
            motion.braking, motion.braking_from_s = braking, t
            motion.duration_s = t + braking.duration_s

    def halt_motion(self) -> None:
        """Stop where the arm is now, with no braking (a stalled arm, or what it hit holds it)."""
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
            # RobotModel.forward's own arithmetic, on the frames the tick computed.
            self._flange = kin.transform_to_pose(self._flange_at(self._joints))
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
        motion = self._motion
        started_s = 0.0 if motion is None else motion.elapsed_s
        self._step_arm(dt)
        if motion is not None:
            braking = motion.braking is not None
            fault = self._check_collision() or (
                None if braking else self._overload() or self._over_speed(motion)
            )
            if fault is None:
                self._start_overlaps = self._overlaps_now  # compared with the next tick's
            elif fault.kind == "collision":
                self._fault = self._back_to_contact(motion, started_s, fault)
                self.halt_motion()
            else:
                self._fault = fault
                self.stop_motion()
        self._step_gripper(dt)
        self._world.follow(self._pose)
        if self._pinched is not None:
            self._check_pinched()

    # -- faults ------------------------------------------------------------------------

    def take_fault(self) -> BackendFault | None:
        """The collision or overload that stopped the arm since the last call, once.

        Returns:
            The fault, or None.
        """
        fault, self._fault = self._fault, None
        return fault

    @property
    def _tool_back_transform(self) -> kin.Transform:
        """The flange in the TCP frame (the tool's inverse)."""
        tool = self._tool
        if tool is not self._tool_back_of:
            self._tool_back_t = kin.invert(
                kin.IDENTITY if tool is None else kin.pose_to_transform(tool)
            )
            self._tool_back_of = tool
        return self._tool_back_t

    def _contacts(self) -> dict[_ContactKey, float]:
        """What touches the table or a fixture now, and how deep (mm).

        The tool (the TCP, the flange's centre and rim, the palm's and the pads' corners)
        as points and the palm and the pads as boxes, the links 2-5 as capsules, the held
        part as its box; each against the table (the points: only over its top, their
        depth measured down from it) and every fixture. A shape is only measured against
        an obstacle whose bounding box its own overlaps: most ticks, far from everything,
        compute no distance at all.

        Returns:
            The depth (>= 0) of each (shape, obstacle) in contact.
        """
        found: dict[_ContactKey, float] = {}
        self._tool_contacts(found)
        origins = self._joint_origins()
        for link, box, depth in link_contacts(origins, self._links, self._obstacles):
            found[self._link_names[link], box.name] = depth
        self._body_contacts(found)
        held = None if self._world.held is None else held_frame(self._world, self._tcp_t)
        if held is not None:
            obj, frame = held
            half = (obj.size_mm[0] / 2, obj.size_mm[1] / 2, obj.size_mm[2] / 2)
            reach = math.hypot(*half)
            centre = (frame[0][3], frame[1][3], frame[2][3])
            low = (centre[0] - reach, centre[1] - reach, centre[2] - reach)
            high = (centre[0] + reach, centre[1] + reach, centre[2] + reach)
            for box in self._obstacles:
                if box.overlaps(low, high):
                    depth = box_depth(box, frame, half)
                    if depth >= 0:
                        found[f"held part {obj.name}", box.name] = depth
        return found

    def _body_contacts(self, found: dict[_ContactKey, float]) -> None:
        """Add the arm's parts meeting each other or the mounting plane (the capsules the
        master checks, :mod:`tmmaster._body`) and the 2FG7 housing in an obstacle."""
        frames = self._frames_at(self._joints)
        for c in body.contacts(self._model, self._joints, self._tool, frames=frames):
            found[c.first, c.second] = -c.distance_mm
        housing = body.housing_segment(self._model, self._joints, self._tool, flange=frames[-1])
        if housing is None:
            return
        a, b, r = housing
        low = tuple(min(a[i], b[i]) - r for i in range(3))
        high = tuple(max(a[i], b[i]) + r for i in range(3))
        for box in self._obstacles:
            if box.overlaps(low, high):
                depth = segment_depth(box, a, b, r)
                if depth >= 0:
                    found["the 2FG7 housing", box.name] = depth

    @property
    def _tcp_t(self) -> kin.Transform:
        """The TCP's transform now (computed once per pose)."""
        if self._tcp_t_of is not self._pose:
            self._tcp_t_value = kin.pose_to_transform(self._pose)
            self._tcp_t_of = self._pose
        return self._tcp_t_value

    def _tool_contacts(self, found: dict[_ContactKey, float]) -> None:
        """Add the tool's points' contacts to ``found``."""
        reach, local = self._tool_local()
        x, y, z = self._pose.x, self._pose.y, self._pose.z
        low, high = (x - reach, y - reach, z - reach), (x + reach, y + reach, z + reach)
        near = [box for box in self._obstacles if box.overlaps(low, high)]
        if not near:
            return
        t = self._tcp_t
        (r00, r01, r02, tx), (r10, r11, r12, ty), (r20, r21, r22, tz) = t[0], t[1], t[2]
        points = [
            (
                r00 * px + r01 * py + r02 * pz + tx,
                r10 * px + r11 * py + r12 * pz + ty,
                r20 * px + r21 * py + r22 * pz + tz,
            )
            for px, py, pz in local
        ]
        solids = self._tool_boxes(t)
        for box in near:
            if box is self._table_box:
                # Over the table's top, a point's depth is measured down from the top.
                (cx, cy), (sx, sy) = TABLE_CENTRE_XY_MM, TABLE_HALF_SIZE_XY_MM
                top = self._world.table_top_z_mm
                depth = max(
                    (
                        top - pz
                        for px, py, pz in points
                        if pz <= top and abs(px - cx) <= sx and abs(py - cy) <= sy
                    ),
                    default=-1.0,
                )
            else:
                depth = max(box.point_depth(point) for point in points)
            # The palm and the pads as the boxes they are: an edge thinner than a pad
            # between two of its corners still meets it (in MuJoCo they are boxes too).
            for frame, half in solids:
                depth = max(depth, box_depth(box, frame, half))
            if depth >= 0:
                found["the tool", box.name] = depth

    def _tool_boxes(self, tcp: kin.Transform) -> list[tuple[kin.Transform, kin.Vector]]:
        """The palm's and each pad's centre frame in the base frame, and half sizes, mm."""
        g = self._gripper
        offset = self._width / 2 + g.pad_thickness_mm / 2
        pad = (g.pad_depth_mm / 2, g.pad_thickness_mm / 2, g.pad_height_mm / 2)
        centres = [(PALM_CENTRE_MM, PALM_HALF_MM)]
        centres += [((0.0, side * offset, 0.0), pad) for side in (1.0, -1.0)]
        return [
            (kin.multiply(tcp, kin.rpy_transform(centre, (0.0, 0.0, 0.0))), half)
            for centre, half in centres
        ]

    def _tool_local(self) -> tuple[float, list[tuple[float, float, float]]]:
        """The tool's points in the TCP frame and how far they reach from it, mm.

        The TCP, the flange's centre and 8 points of its rim, the palm's 8 corners and
        the pads' 16; kept while the finger width and the tool stay.
        """
        key = (self._width, self._tool)
        if key != self._local_of:
            g = self._gripper
            back = self._tool_back_transform
            points = [(0.0, 0.0, 0.0), (back[0][3], back[1][3], back[2][3])]
            points += [transform_point(back, p) for p in _FLANGE_RIM]
            points += _PALM_CORNERS
            inner, outer = self._width / 2, self._width / 2 + g.pad_thickness_mm
            points += [
                (x, y, z)
                for y in (inner, outer, -inner, -outer)
                for x in (-g.pad_depth_mm / 2, g.pad_depth_mm / 2)
                for z in (-g.pad_height_mm / 2, g.pad_height_mm / 2)
            ]
            reach = max(math.sqrt(x * x + y * y + z * z) for x, y, z in points)
            self._local, self._local_of = (reach, points), key
        return self._local

    def _pad_contacts(self) -> dict[tuple[str, int], _PadContact]:
        """Each pad against each part near it (not the one squeezed), after the last check.

        A pad inside a part keeps how it got there: it *landed* when it was right above the
        part at the check before (its horizontal overlaps positive, its vertical one not);
        a contact the motion started with keeps its vertical overlap then as a baseline.
        """
        g = self._gripper
        reach = math.hypot(g.pad_depth_mm, self._width + 2 * g.pad_thickness_mm) + g.pad_height_mm
        contacts: dict[tuple[str, int], _PadContact] = {}
        for obj in self._world.near(self._pose.x, self._pose.y, reach):
            if obj.name == self._pinched:
                continue
            pads, vertical = pad_overlaps(obj, self._pose, width_mm=self._width, gripper=g)
            for k, overlaps in enumerate(pads):
                key = (obj.name, k)
                before = self._start_overlaps.get(key)
                if min(overlaps) <= 0:
                    contacts[key] = _PadContact(overlaps, vertical)
                elif before is None or min(before.overlaps) <= 0:
                    # Entering now: from above, or (no check before) where it is shallowest.
                    if before is None:
                        landed = overlaps[vertical] == min(overlaps)
                    else:
                        landed = (
                            before.overlaps[vertical]
                            <= 0
                            < min(o for i, o in enumerate(before.overlaps) if i != vertical)
                        )
                    contacts[key] = _PadContact(overlaps, vertical, landed=landed)
                else:
                    contacts[key] = _PadContact(
                        overlaps, vertical, landed=before.landed, baseline=before.baseline
                    )
        return contacts

    def _check_collision(self) -> BackendFault | None:
        """A contact the moving arm did not expect: the table, a fixture, a pad on a part.

        Each shape in the table or a fixture is compared with its depth in it when the
        motion started: an arm link or the tool touching what it did not touch then, or
        going 0.2 mm deeper into it, hit it; the held part hit it when more than 0.2 mm
        deeper than then (a part resting on its support touches it: it may be lifted off
        it, slid along it or set down on one, not pushed into one). The pads are
        compared with the last check without a collision (at first, the motion's start,
        ``_start_overlaps``): a pad that came down on a part, or went further down into
        one it started in, hit it; one rising out of a part, or meeting it from the side,
        did not.
        """
        worst: tuple[float, _ContactKey, float] | None = None
        for key, depth in self._contacts().items():
            before = self._start_depths.get(key, -1.0)
            if key[0].startswith("held part "):
                before = max(before, 0.0)
            excess = depth - before - _COLLISION_DEPTH_MM
            if excess > 0 and (worst is None or excess > worst[0]):
                worst = (excess, key, depth)
        if worst is not None:
            _, (what, obstacle), depth = worst
            if what.startswith("held part "):
                text = f"the {what} hit {obstacle} ({depth:.1f} mm deep)"
            else:
                text = f"the arm hit {obstacle} ({what}, {depth:.1f} mm deep)"
            return BackendFault("collision", text)
        contacts = self._pad_contacts()
        self._overlaps_now = contacts
        for (name, _), contact in contacts.items():
            down = contact.overlaps[contact.vertical]
            if min(contact.overlaps) <= 0:
                continue
            if (contact.landed and down > _COLLISION_DEPTH_MM) or (
                contact.baseline is not None and down > contact.baseline + _COLLISION_DEPTH_MM
            ):
                return BackendFault(
                    "collision", f"a finger came down on {name} ({down:.1f} mm deep)"
                )
        return None

    def _start_contacts(self) -> dict[tuple[str, int], _PadContact]:
        """The pads' contacts when a motion starts: those it already has are baselines."""
        self._start_overlaps = {}
        contacts = self._pad_contacts()
        for key, contact in contacts.items():
            if min(contact.overlaps) > 0:
                contacts[key] = _PadContact(
                    contact.overlaps, contact.vertical, baseline=contact.overlaps[contact.vertical]
                )
        return contacts

    def _back_to_contact(
        self, motion: _Motion, started_s: float, fault: BackendFault
    ) -> BackendFault:
        """Put the arm back where, within this step, the collision began (the arm stops there).

        A tick moves the arm up to ~22 mm at full speed: the physics would have stopped it
        at the first touch, not a tick later inside the table.
        """
        low, high = started_s, min(motion.elapsed_s, motion.duration_s)
        for _ in range(_CONTACT_BISECTIONS):
            middle = (low + high) / 2
            self._place(motion, middle)
            if self._check_collision() is None:
                low = middle
            else:
                high = middle
        self._place(motion, high)
        return self._check_collision() or fault

    def _over_speed(self, motion: _Motion) -> BackendFault | None:
        """A PTP that reached the time its TCP first runs past the speed limit: the arm is
        put back there (a tick may have carried it further) to brake from it."""
        if motion.over_speed is None or motion.elapsed_s < motion.over_speed[0]:
            return None
        (motion.elapsed_s, speed), motion.over_speed = motion.over_speed, None
        self._motion = motion  # the step may have ended it: it brakes instead
        self._place(motion, motion.elapsed_s)
        return speed_fault(self._model.tcp_speed_limit_mm_s, speed)

    def _overload(self) -> BackendFault | None:
        """The gripper and the part carried weigh more than the arm's rated payload."""
        return over_payload(self._world.held, self._gripper, self._model.payload_kg)

    def _check_pinched(self) -> None:
        """The squeezed part too heavy to carry slips out once the pads leave it."""
        assert self._pinched is not None
        obj = self._world.get(self._pinched)
        g = self._gripper
        rel, (ex, _, ez) = in_tool_frame(obj, self._pose)
        if abs(rel[0][3]) < g.pad_depth_mm / 2 + ex and abs(rel[2][3]) < g.pad_height_mm / 2 + ez:
            return  # the pads still slide along it
        self._pinched = None
        self._contact = False
        self._width = self._target_width  # nothing between them any more: they close

    def _step_arm(self, dt: float) -> None:
        motion = self._motion
        if motion is None:
            self._rest_s += dt
            return
        motion.elapsed_s += dt * self._time_rate
        if motion.elapsed_s + _EPS >= motion.duration_s:
            # Land exactly on the target (or where the braking ends), not on an
            # interpolated approximation of it.
            self._place(motion, motion.duration_s)
            self._motion = None
            self._rest_s = max(0.0, motion.elapsed_s - motion.duration_s)
            return
        self._place(motion, motion.elapsed_s)

    def _place(self, motion: _Motion, elapsed_s: float) -> None:
        """Put the arm where ``motion`` has it ``elapsed_s`` after its start."""
        if motion.braking is None and elapsed_s + _EPS >= motion.duration_s:
            self._set(motion.target_joints, motion.target)
            return
        progress = motion.progress(elapsed_s)
        if motion.kind is MotionType.PTP:
            joints = _lerp(motion.start_joints, motion.target_joints, progress)
            self._set(joints, self._forward(joints))
        else:
            self._set(*self._line_point(motion, progress))

    def _line_point(self, motion: _Motion, progress: float) -> tuple[Joints, Pose]:
        """Joints and TCP ``progress`` (0..1) of the way along a Line's (or an arc's) path."""
        if motion.arc is not None:
            t = motion.arc.at(progress)
        else:
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
        # Between two checked samples the path may pass inside a singularity margin (the
        # master's, not the arm's): the arm follows its line there all the same, as the
        # joints without the margins have it. Interpolating the samples there instead put
        # the TCP 1.7 mm off the line and jumped J4 at 2.8 times its top speed on leaving
        # the margin (tests/test_hunt24_line_singularity.py).
        for model in (self._model, _without_margins(self._model)):
            with contextlib.suppress(UnreachablePoseError):
                return model.inverse(pose, seed_deg=seed, tool=self._tool, same_branch=True), pose
        return seed, self._model.forward(seed, self._tool)

    def _forward(self, joints: Joints) -> Pose:
        """The TCP at ``joints``, keeping the joints' frames for the collision check.

        :meth:`RobotModel.forward`'s arithmetic on the chain kept here: one forward
        kinematics gives the pose, the links, the body check and the flange (a PTP's tick
        computes no other).
        """
        flange = self._flange_at(joints)
        if self._tool is not None:
            flange = kin.multiply(flange, kin.pose_to_transform(self._tool))
        return kin.transform_to_pose(flange)

    def _joint_origins(self) -> list[tuple[float, float, float]]:
        """The joints' origins (J1..J6, the flange last) where the arm is now, mm."""
        if self._origins_of is not self._joints:
            # Chain.joint_origins: the positions of the frames after the base's.
            frames = self._frames_at(self._joints)
            self._origins = [(f[0][3], f[1][3], f[2][3]) for f in frames[1:]]
            self._origins_of = self._joints
        return self._origins

    def _frames_at(self, joints: Joints) -> list[kin.Frame]:
        """The chain's link frames at ``joints`` (the base first, the flange last), kept
        for the last joints (by identity: the backend's joints tuple of a tick)."""
        if self._frames_of is not joints:
            self._frames = self._chain.link_frames([math.radians(q) for q in joints])
            self._frames_of = joints
        return self._frames

    def _flange_at(self, joints: Joints) -> kin.Transform:
        """The flange's transform at ``joints``: Chain.flange, from the kept frames."""
        return (*self._frames_at(joints)[-1], kin.IDENTITY[3])

    def _set(self, joints: Joints, tcp: Pose) -> None:
        self._joints = joints
        self._pose = tcp
        self._flange = None

    # -- gripper -----------------------------------------------------------------------

    def drive_gripper(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> None:
        """Move the fingers towards ``width_mm`` (clamped to the stroke), gripping with ``force_n``.

        Args:
            width_mm: Target width, mm.
            speed_mm_s: Finger speed, mm/s (> 0).
            force_n: The grip force each finger presses with, N: with the pads' friction it
                decides whether a part is carried or slips out (friction grasp).

        Raises:
            ValueError: A speed that is not > 0 or a negative force.
        """
        if speed_mm_s <= 0 or not math.isfinite(speed_mm_s):
            raise ValueError(f"speed_mm_s must be > 0, got {speed_mm_s}")
        if force_n < 0 or not math.isfinite(force_n):
            raise ValueError(f"force_n must be >= 0, got {force_n}")
        # Real fingers cannot go past their end stops; they stop there.
        self._target_width = min(max(width_mm, self._gripper_min), self._gripper_max)
        self._finger_speed = speed_mm_s
        self._force = force_n
        gripped = self._world.held is not None or self._pinched is not None
        if gripped and self._target_width <= self._width:
            # Squeezing a held object harder: the object blocks the fingers.
            self._contact = True
            self._gripper_moving = False
            return
        self._contact = False
        self._gripper_moving = self._target_width != self._width
        self._close_from = self._width

    def _step_gripper(self, dt: float) -> None:
        if not self._gripper_moving:
            return
        travel = self._finger_speed * dt
        if self._target_width < self._width:
            fit = self._world.grasp_fit(
                self._pose,
                current_width_mm=self._width,
                target_width_mm=self._target_width,
                gripper=self._gripper,
                opening_mm=self._close_from,
            )
            new_width = max(self._target_width, self._width - travel)
            if fit is not None and new_width <= fit.width_mm:
                self._width = fit.width_mm
                self._gripper_moving = False
                self._contact = True
                obj = fit.obj
                if self._grasp_mode == "weld" or self._gripper.holds(obj.mass_kg, self._force):
                    self._world.grasp(obj.name, self._pose, fit.relative)
                    self._held_width = fit.width_mm
                else:
                    self._pinched = obj.name  # squeezed, but it will slip out
                return
        else:
            new_width = min(self._target_width, self._width + travel)
            if self._world.held is not None and new_width > self._held_width:
                self._world.release(self._pose)
            self._pinched = None
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


def _check_speed(speed_percent: float, accel_time_s: float) -> None:
    if accel_time_s < 0:
        raise ValueError(f"accel_time_s must be >= 0, got {accel_time_s}")
    if not 0 < speed_percent <= 100:
        raise ValueError(f"speed_percent must be in (0, 100], got {speed_percent}")


@functools.lru_cache(maxsize=8)
def _without_margins(model: RobotModel) -> RobotModel:
    """``model`` without the master's singularity margins: the arm's own joints."""
    margins = {"wrist_margin_deg": 0.0, "elbow_margin_deg": 0.0, "shoulder_margin_mm": 0.0}
    return model.model_copy(update=margins)


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
