"""Planning a move: validation, the joints seed, expected times and timeouts (no I/O).

A :class:`~tmmaster.Robot` owns one :class:`Planner`. Before a byte is sent, the
planner checks a move (speed, workspace, the arm's reach and range, a Line's or an
arc's path) and, from the pose and joints the robot reported, plans it: the target's
joints, the expected time by the arm model, the timeout, and the gauge of the path
covered. It keeps the joints seed, where the arm is believed to be, which the next
plan starts from. It reads and writes nothing: the robot reads, the planner decides.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, Protocol

from pydantic import AliasChoices, BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from . import _body as body
from . import _kinematics as kin
from ._cell import (
    DEFAULT_ARM_RADIUS_MM,
    DEFAULT_TABLE_TOP_Z_MM,
    DEFAULT_TOOL_EXTENT_MM,
    arm_lowest_z_mm,
)
from ._channels import Command, CommandKind
from ._checks import Bounds, Policy, bounded, is_finite_number, shown
from ._exceptions import ConfigError, RobotError, UnreachablePoseError
from ._pose import MotionType, Pose, refuse_suspect_units
from ._robot_models import ROBOT_MODELS, PathGauge, RobotModel, arc_through

Joints = tuple[float, ...]

#: Reported joints this close (deg, each) to the seed are the seed's (the registers'
#: float32 rounding, a servo's last hundredths of a degree).
SAME_JOINTS_DEG = 0.05
#: Reported joints whose forward kinematics miss the reported TCP by more (mm, deg) are
#: not the arm's (zeros); a calibrated arm's differ from the nominal chain's by a few mm.
JOINTS_MISS = {"mm": 10.0, "deg": 5.0}
#: A Line or an arc may turn the TCP by at most this much, deg: a half turn has no
#: shorter way round, and the robot, from the pose it holds, may turn either way.
MAX_PATH_TURN_DEG = 179.0


class Workspace(BaseModel):
    """Where the tool may go, in mm (robot base frame): a table plane and a box.

    The defaults describe the default cell (the built-in simulator's): a table whose top
    is at ``floor_z_mm`` = 85 mm and the simulator's gripper around the TCP
    (``tool_extent_mm``). No TCP, no flange and no corner of the tool's extent may go
    below the table plane, so a move validated with these defaults does not run the tool
    into that table. **Another cell states its own:** ``Workspace(floor_z_mm=...)``, the
    top of your table in the robot base frame (``0`` for the plane the robot stands on),
    and ``tool_extent_mm`` for your tool (``None``: only the TCP and the flange); or
    ``floor_z_mm=None`` for an arm that must reach below its mounting plane (mounted on
    a pedestal or a wall). At each target the arm's links (``arm_radius_mm``) must stay
    above the plane too (:meth:`check_arm`). The box (``x``, ``y``, ``z``) bounds the
    TCP only.
    """

    # NaN or infinite bounds would make range checks pass or fail by accident.
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    #: The TCP's range along x (lowest, highest), mm.
    x: tuple[float, float] = (-2000.0, 2000.0)
    #: The TCP's range along y, mm.
    y: tuple[float, float] = (-2000.0, 2000.0)
    #: The TCP's range along z, mm.
    z: tuple[float, float] = (-2000.0, 2000.0)
    #: The table plane, mm: no TCP, no flange and no corner of the tool's extent below
    #: it. Default: the default cell's table top (85 mm). None: no plane.
    floor_z_mm: float | None = DEFAULT_TABLE_TOP_Z_MM
    #: The tool's extent around the TCP in the TCP frame, (x lo, hi), (y lo, hi),
    #: (z lo, hi), mm: a box no corner of which may go below the table plane. Default:
    #: the simulator's gripper with the TCP at the flange. None: the TCP and flange only.
    tool_extent_mm: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] | None = (
        DEFAULT_TOOL_EXTENT_MM
    )
    #: The radius of the arm's links round the segments between its joints, mm: no
    #: link may go below the table plane at a target (:meth:`check_arm`). Default: the
    #: simulator's arm. None: the links are not checked.
    arm_radius_mm: Annotated[float, Field(gt=0, le=500)] | None = DEFAULT_ARM_RADIUS_MM

    @model_validator(mode="after")
    def _extent_is_ordered(self) -> Workspace:
        for axis, (low, high) in zip("xyz", self.tool_extent_mm or (), strict=False):
            if not -2000 <= low <= high <= 2000:
                raise ValueError(
                    f"tool_extent_mm: {axis} needs -2000 <= lo <= hi <= 2000 mm,"
                    f" got ({low}, {high})"
                )
        return self

    def check(self, pose: Pose, *, tool: Pose | None = None) -> None:
        """Refuse a TCP ``pose`` outside the box or with the tool below the table plane.

        Args:
            pose: the TCP pose (mm, deg) in the robot base frame.
            tool: the TCP in the flange frame (None: the TCP is the flange), to place
                the flange for the table plane.

        Raises:
            ConfigError: naming the axis or the point (TCP, tool, flange) and its height.
        """
        for axis, (low, high) in (("x", self.x), ("y", self.y), ("z", self.z)):
            value = getattr(pose, axis)
            if not low <= value <= high:
                raise ConfigError(
                    f"pose {axis} = {value:g} mm is outside the workspace ({low:g}..{high:g} mm)"
                )
        floor = self.floor_z_mm
        if floor is None:
            return
        plane = f"the table plane (workspace floor_z_mm = {floor:g} mm)"
        if pose.z < floor:
            raise ConfigError(f"pose z = {pose.z:g} mm puts the TCP below {plane}")
        lowest = self.tool_lowest_z_mm(pose)
        if lowest <= floor:  # touching the table is hitting it
            raise ConfigError(
                f"pose {pose} puts the tool's lowest point at z = {lowest:.1f} mm, on or"
                f" below {plane}; the tool reaches {pose.z - lowest:.1f} mm below the TCP"
                " in this orientation (workspace tool_extent_mm)"
            )
        if tool is not None and (flange := kin.flange_of(pose, tool)).z < floor:
            raise ConfigError(
                f"pose {pose} puts the flange at z = {flange.z:.1f} mm, below {plane}"
            )

    def check_arm(self, model: RobotModel, joints_deg: Sequence[float]) -> None:
        """Refuse joints that put a link of the arm below the table plane.

        Args:
            model: The arm model.
            joints_deg: The joints, deg.

        Raises:
            ConfigError: naming the link and its lowest point's height.
        """
        floor, radius = self.floor_z_mm, self.arm_radius_mm
        if floor is None or radius is None:
            return
        link, lowest = _arm_lowest(model, tuple(joints_deg), radius)
        if lowest <= floor:
            joints = ", ".join(f"{q:.1f}" for q in joints_deg)
            raise ConfigError(
                f"joints ({joints}) deg put link {link} of the arm at z = {lowest:.1f} mm,"
                f" on or below the table plane (workspace floor_z_mm = {floor:g} mm,"
                f" arm_radius_mm = {radius:g} mm)"
            )

    def tool_lowest_z_mm(self, pose: Pose) -> float:
        """The height of the lowest corner of the tool's extent with the TCP at ``pose``.

        Args:
            pose: the TCP pose (mm, deg) in the robot base frame.

        Returns:
            The lowest corner's z, mm (the TCP's z when ``tool_extent_mm`` is None).
        """
        if self.tool_extent_mm is None:
            return pose.z
        row = kin.pose_to_transform(pose)[2]
        return pose.z + sum(
            min(row[i] * low, row[i] * high) for i, (low, high) in enumerate(self.tool_extent_mm)
        )


#: The range of one Modbus request's bound (``TimeoutPolicy.request_s``) and of a register
#: gripper's settle time (``TimeoutPolicy.gripper_settle_s``), s.
MINUTE_BOUNDS = Bounds(0.0, 60.0, "s", open_low=True)


class TimeoutPolicy(Policy):
    """How long requests and waits may take; motion timeouts derive from the move unless fixed.

    ``Robot(host, timeouts=TimeoutPolicy(request_s=2.0))``. Every bound is finite; the
    pick & place configuration (``[timeouts]``) is this model and also accepts its older
    key names ``ack_s``, ``motion_s`` and ``gripper_s``. ``request_s``,
    ``gripper_settle_s`` and the heartbeat's two are read when the robot is made (its
    link, its gripper, its heartbeat); the others by every wait when it starts. An
    invalid value is a :class:`~tmmaster.ConfigError` naming the field
    (``timeouts.request_s must be ...``).
    """

    model_config = ConfigDict(populate_by_name=True)
    #: The Robot argument that takes it: its fields are named ``timeouts.<field>`` in errors.
    argument: ClassVar[str] = "timeouts"

    #: One Modbus request must be answered within this time, s (up to 60).
    request_s: Annotated[float, BeforeValidator(bounded("timeouts.request_s", MINUTE_BOUNDS))] = 1.0
    #: The robot must acknowledge a command within this time.
    ack_timeout_s: Annotated[
        float, Field(gt=0, le=60, validation_alias=AliasChoices("ack_timeout_s", "ack_s"))
    ] = 2.0
    #: Motion timeout = factor x expected time + margin (the article's ~130 % rule) ...
    motion_factor: Annotated[float, Field(ge=1, le=10)] = 1.3
    #: ... + this margin, s.
    motion_margin_s: Annotated[float, Field(ge=0, le=600)] = 2.0
    #: ... unless fixed here for every move.
    motion_timeout_s: Annotated[
        Annotated[float, Field(gt=0, le=3600)] | None,
        Field(validation_alias=AliasChoices("motion_timeout_s", "motion_s")),
    ] = None
    #: Gripper moves must end within this time.
    gripper_timeout_s: Annotated[
        float, Field(gt=0, le=600, validation_alias=AliasChoices("gripper_timeout_s", "gripper_s"))
    ] = 5.0
    #: A register gripper without a busy flag (the article profile's): how long an open
    #: or a close takes at most, s (up to 60).
    gripper_settle_s: Annotated[
        float, BeforeValidator(bounded("timeouts.gripper_settle_s", MINUTE_BOUNDS))
    ] = 0.5
    #: After a command write whose answer was lost (clear-on-accept profiles, which must
    #: never write a command twice): how long to watch for the write to land late.
    in_flight_s: Annotated[float, Field(gt=0, le=600)] = 5.0
    #: A move whose derived timeout grows with a pace slower than the model's must show
    #: progress (0.1 mm or 0.1 deg) at least this often past its model budget (or every
    #: quarter of that budget, if less, but never under 0.5 s unless set so here); none
    #: for this long is a stall, s.
    stall_s: Annotated[float, Field(gt=0, le=60)] = 1.0
    #: The master's heartbeat (``tmflow``: ``master_heartbeat``, docs/safety.md): written
    #: this often from the first command to close, s (0.02 to 0.5: the robot program asks for a
    #: change at least every 500 ms).
    heartbeat_s: Annotated[float, Field(ge=0.02, le=0.5)] = 0.4
    #: ... and a command on the robot expires once the heartbeat has been silent this
    #: long (``master_ttl_ms``), s (0.5 to 10, at least three heartbeats).
    heartbeat_ttl_s: Annotated[float, Field(ge=0.5, le=10)] = 2.0

    @model_validator(mode="after")
    def _ttl_spans_heartbeats(self) -> TimeoutPolicy:
        if self.heartbeat_ttl_s < 3 * self.heartbeat_s:
            raise ValueError(
                f"heartbeat_ttl_s ({self.heartbeat_ttl_s:g} s) must be at least three"
                f" heartbeats ({3 * self.heartbeat_s:g} s): a late write must not expire a"
                " command"
            )
        return self

    def for_motion(self, expected_s: float) -> float:
        """The timeout of a move expected to take ``expected_s`` seconds.

        Args:
            expected_s: The move's expected duration, s.

        Returns:
            ``motion_timeout_s`` when fixed, else factor x expected + margin, s.
        """
        if self.motion_timeout_s is not None:
            return self.motion_timeout_s
        return expected_s * self.motion_factor + self.motion_margin_s


class WaitSettings(Protocol):
    """What a plan reads of the settings every wait reads (the robot's follower's)."""

    #: How far (mm) a reported TCP may be from a pose the arm is taken to be at.
    position_tolerance_mm: float
    #: ... and its orientation, deg.
    orientation_tolerance_deg: float
    #: Motion and gripper timeouts.
    timeouts: TimeoutPolicy


@dataclass(frozen=True)
class Plan:
    """A command planned before its write: what its :class:`~tmmaster.Motion` carries."""

    #: Where the move starts (the robot's pose); None for a gripper command.
    start: Pose | None
    #: The target's joints; None for a gripper command.
    joints: Joints | None
    #: The TCP target; None for a gripper command.
    target: Pose | None
    #: The expected duration by the arm model, s (0: not a move).
    expected_s: float
    #: How long the command may take before its wait gives up, s.
    timeout_s: float
    #: How much of the path a reported pose has covered (None: not a move).
    gauge: PathGauge | None = None
    #: The move's acceleration time by the arm model, s (0: not a move).
    accel_s: float = 0.0
    #: True when ``timeout_s`` derives from the model's expected time.
    timeout_from_model: bool = False
    #: The project speed the expected time assumes, %.
    project_speed_percent: float = 100.0


class Planner:
    """Checks and plans one robot's moves from where its arm is believed to be (no I/O).

    The joints seed: the joints the robot reported (at connect, before each plan) where
    the profile publishes them, moved on to each commanded target's joints; the pose
    they put the TCP at. Without published joints: the last commanded target's (none at
    first: the model's ready posture is the seed), and where the robot reports the arm
    away from it, that pose solved on the branch so assumed.
    """

    def __init__(
        self,
        model: RobotModel,
        *,
        workspace: Workspace,
        tool: Pose | None,
        check_units: bool,
        max_speed_percent: int,
        settings: WaitSettings,
        log: Any,
    ) -> None:
        self.model, self.workspace, self.tool = model, workspace, tool
        #: The robot's project speed, % (``tmflow``: Techman's 7101, read at connect):
        #: TMflow runs every move at its own speed times this, and so does the plan.
        self.project_speed_percent = 100.0
        self.check_units = check_units
        self.max_speed_percent = max_speed_percent
        self._settings, self._log = settings, log
        #: A PTP whose TCP would run faster is refused, mm/s (None: the model's limit).
        self.tcp_speed_limit_mm_s: float | None = None
        #: The joints the arm is believed to be at (None: the model's ready posture).
        self.joints_hint: Joints | None = None
        #: The pose those joints put the TCP at (None: not known).
        self.hint_pose: Pose | None = None
        self._joints_mismatch_logged = False

    # -- validation ----------------------------------------------------------

    def validate(self, pose: Pose, speed: int, seed_deg: Sequence[float] | None = None) -> Joints:
        """:meth:`Robot.validate_move`: speed, units, workspace, inverse kinematics, and
        the arm's body along the PTP from ``seed_deg`` (or the seed) to the target."""
        seed = tuple(seed_deg) if seed_deg is not None else self.joints_hint
        joints = self._target_joints(pose, speed, seed)
        _check_ptp_body(self.model, seed, joints, self.tool, self.workspace.floor_z_mm)
        return joints

    def _target_joints(self, pose: Pose, speed: int, seed: Joints | None) -> Joints:
        """A target's checks (:meth:`_check_target`), its joints from ``seed`` in the arm's
        pose configuration, and the arm there: :meth:`validate` but the body on the way."""
        self._check_target(pose, speed)
        joints = self.model.inverse(pose, seed_deg=seed, tool=self.tool)
        self._keep_configuration(seed, joints, pose)
        self.workspace.check_arm(self.model, joints)
        return joints

    def _keep_configuration(self, seed: Joints | None, joints: Joints, pose: Pose) -> None:
        """Refuse a Cartesian target the arm reaches only in another pose configuration
        than the one it is in (``seed``): the robot program solves it in the current one
        (TMscript 2.24 ``inversekin``, p. 207) and answers "unreachable".

        Asked before any request (:meth:`validate`) and again by the plan, from the
        joints the robot reports: each joint set's configuration is computed once
        (:func:`_configuration`), so the plan's check costs nothing new unless the
        arm's joints changed meanwhile.
        """
        have = _configuration(self.model, seed or joints)
        need = _configuration(self.model, joints)
        if have != need:
            text = (
                f"pose {pose} is reachable only in another pose configuration (shoulder front,"
                f" J3 >= 0, J5 >= 0: {need}) than the arm's ({have}): the robot solves a Cartesian"
                " target in its current one (TMscript inversekin, p. 207); use move_joints"
            )
            raise UnreachablePoseError(text, reason="configuration", pose=pose)

    def _check_turn(self, start: Pose, target: Pose) -> None:
        """Refuse a Line or an arc that turns the TCP (nearly) half a turn: the master
        checks one way round, the robot may take the other (a joint past its range)."""
        if (turn := start.rotation_to(target)) > MAX_PATH_TURN_DEG:
            text = f"the TCP would turn {turn:.2f} deg from {start} to {target}, about half a turn"
            raise ConfigError(f"{text}: no way round is the shorter, the robot may take either")

    def _share(self, speed: float) -> float:
        """The speed the robot runs a move at ``speed`` % with: TMflow's motion speed x
        project speed."""
        return speed * self.project_speed_percent / 100.0

    def _check_ptp_speed(
        self, start: Sequence[float], joints: Joints, percent: float, accel: float | None = None
    ) -> Joints:
        """Refuse a PTP whose TCP would run faster than the robot's TCP speed limit, a
        stop criterion of its Performance Safety settings (TMflow 2.24, 3 Safety
        Settings, Speed & Force, p. 38; 1500 mm/s by default, Appendix B): "the PTP mode
        may cause the TCP to exceed speed limit" (9 Speed of PTP Motion, p. 169).
        ``percent``: the speed the robot runs it at (:meth:`_share`); ``accel``: its
        time to top speed, s (None: the model's)."""
        peak = max(self.model.ptp_tcp_speeds(tuple(start), joints, percent, accel, self.tool))
        self._refuse_over_limit(f"a PTP at {percent:g} %", peak)
        return joints

    def check_tcp_speed(self, command: Command) -> None:
        """Refuse a Line or an arc whose TCP would run faster than the robot's TCP speed
        limit: at its speed (``speed_mm_s``, or the model's top Line speed x ``speed`` %)
        x the project speed. A robot whose limit is under it stops such a move (0x0021,
        TMflow 2.24 Appendix J, p. 409: "Check if the issued point is LINE ... (ABS)")."""
        if command.kind in (CommandKind.LINE, CommandKind.CIRCLE):
            top = command.speed_mm_s or self.model.tcp_speed_mm_s * (command.speed or 100) / 100
            self._refuse_over_limit(f"a {command.kind.value} at {top:g} mm/s", self._share(top))

    def _refuse_over_limit(self, what: str, tcp_mm_s: float) -> None:
        """A ConfigError when ``tcp_mm_s`` is over the TCP speed limit, naming the setting."""
        if tcp_mm_s > (limit := self.tcp_speed_limit_mm_s or self.model.tcp_speed_limit_mm_s):
            text = f"{what} would move the TCP at {tcp_mm_s:.0f} mm/s, over the"
            raise ConfigError(f"{text} TCP speed limit (checks.tcp_speed_limit_mm_s = {limit:g})")

    def _check_body(self, start: Sequence[float] | None, samples: Sequence[Joints]) -> None:
        """Self-collision, the mounting plane and the gripper's housing at ``samples``."""
        floor = self.workspace.floor_z_mm
        body.check_body(self.model, samples, tool=self.tool, floor_z_mm=floor, start=start)

    def _check_target(self, pose: Pose, speed: int) -> None:
        """A target's checks without its joints: type, speed, units, the workspace."""
        if not isinstance(pose, Pose):
            raise ConfigError(f"target must be a tmmaster.Pose, got {type(pose).__name__}")
        self._check_speed(speed)
        if self.check_units:
            refuse_suspect_units("target", pose)
        self.workspace.check(pose, tool=self.tool)

    def _check_speed(self, speed: object) -> int:
        """``speed`` when it is an integer percent in 1..``max_speed_percent``."""
        if isinstance(speed, bool) or not isinstance(speed, int):
            raise ConfigError(f"speed must be an integer percent, got {speed!r}")
        if not 1 <= speed <= self.max_speed_percent:
            raise ConfigError(f"speed {shown(speed)} % is outside 1..{self.max_speed_percent} %")
        return speed

    def check_move(
        self,
        target: Pose,
        speed: int,
        motion: MotionType,
        start: Pose | None,
        seed_deg: Sequence[float] | None,
    ) -> Joints:
        """:meth:`Robot.check_move`'s model checks (the profile's encoding aside).

        A Line from ``start`` ends where its path from the arm's joints ends (the arm
        keeps its configuration), not where a fresh inverse solution would put it.
        """
        seed = self.joints_hint if seed_deg is None else seed_deg
        if motion is MotionType.PTP and seed is not None:
            return self._check_ptp_speed(
                seed, self.validate(target, speed, seed), self._share(speed)
            )
        if motion is not MotionType.LINE or start is None:
            return self.validate(target, speed, seed_deg)
        self._check_target(target, speed)
        path = self.model.line_joints(start, target, start_joints_deg=seed_deg, tool=self.tool)
        self._check_turn(start, target)
        self.workspace.check_arm(self.model, path[-1])
        self._check_body(path[0], path[1:])
        return path[-1]

    def check_path(self, target: Pose, speed: int, motion: MotionType) -> None:
        """A move's checks before any request, a Line's path from the seed included.

        A Line the arm cannot follow from where it is believed to be is refused without
        touching the robot; it is checked again from the pose the robot reports.
        """
        self.check_move(target, speed, motion, self.hint_pose, self.joints_hint)

    def check_arc_move(self, via: Pose, to: Pose, speed: int) -> None:
        """An arc's checks before its start is read: its end (from the joints the arm is
        believed at: after a move given up, the ones the robot reported) and ``via``. The
        arc itself is checked from the pose the robot reports (its plan), not from the
        last target: a move stopped short left the arm elsewhere, where another arc
        starts."""
        # Its end as validate() checks it, without the body along a PTP there: the arm
        # takes the arc, whose samples' body the plan checks.
        self._target_joints(to, speed, self.joints_hint)
        self.workspace.check(via)  # its position (the TCP passes there)

    def joint_target(self, joints: Sequence[float], speed: int) -> tuple[Joints, Pose]:
        """A joint move's checked joints and the TCP pose they give (validated as a target)."""
        checked = self.model.check_joints(joints, tool=self.tool)
        tcp = self.model.forward(checked, self.tool)
        self.validate(tcp, speed, checked)
        if (hint := self.joints_hint) is not None:
            self._check_body(hint, body.ptp_samples(hint, checked))
            self._check_ptp_speed(hint, checked, self._share(speed))
        return checked, tcp

    def check_arc(
        self, start: Pose, via: Pose, to: Pose, joints: Sequence[float] | None
    ) -> list[Joints]:
        """The arc's joint samples from ``start``; refuses a point outside the workspace."""
        samples = self.model.arc_joints(start, via, to, start_joints_deg=joints, tool=self.tool)
        self._check_turn(start, to)
        arc = arc_through(start, via, to)
        for k, joints in enumerate(samples):
            point = kin.transform_to_pose(arc.at(k / (len(samples) - 1)))
            try:
                self.workspace.check(point, tool=self.tool)
                self.workspace.check_arm(self.model, joints)
            except ConfigError as exc:
                raise ConfigError(f"the arc to {to} passes {point}: {exc}") from exc
        try:
            self._check_body(samples[0], samples[1:])
        except ConfigError as exc:
            raise ConfigError(f"the arc to {to}: {exc}") from exc
        return list(samples)

    def via_on_arc(self, start: Pose, via: Pose, to: Pose) -> Pose:
        """The pose the TCP has where the arc from ``start`` passes ``via``'s position."""
        arc = arc_through(self.origin(start), via, to)
        return kin.transform_to_pose(arc.at(arc.via_fraction))

    def speed_percent(
        self, speed: int | None, speed_mm_s: int | None, motion: MotionType | None
    ) -> int:
        """The speed register's percent for ``speed`` or ``speed_mm_s`` (checked: a
        speed in % as every target's is, without the target).

        ``motion`` None: a Circle (which takes mm/s too).
        """
        if speed_mm_s is None:
            return self._check_speed(30 if speed is None else speed)
        if speed is not None:
            raise ConfigError(
                f"give either speed ({speed!r} %) or speed_mm_s ({speed_mm_s!r} mm/s), not both"
            )
        if motion is MotionType.PTP:
            raise ConfigError(
                "speed_mm_s is a TCP speed, for Line and Circle moves; a PTP's speed is a"
                " percent (speed=)"
            )
        if isinstance(speed_mm_s, bool) or not isinstance(speed_mm_s, int):
            raise ConfigError(f"speed_mm_s must be an integer (mm/s), got {speed_mm_s!r}")
        model = self.model
        top = int(model.tcp_speed_mm_s * self.max_speed_percent / 100)
        if not 1 <= speed_mm_s <= top:
            raise ConfigError(
                f"speed_mm_s {speed_mm_s} mm/s is outside 1..{top} mm/s (max_speed_percent"
                f" {self.max_speed_percent} % of the {model.name}'s"
                f" {model.tcp_speed_mm_s:g} mm/s)"
            )
        return min(self.max_speed_percent, math.ceil(speed_mm_s * 100 / model.tcp_speed_mm_s))

    # -- the joints seed -----------------------------------------------------

    def origin(self, start: Pose) -> Pose:
        """The pose a plan starts from: the last target when the arm reads as being there."""
        last = self.hint_pose
        # The arm is where the last move put it (the read pose differs by the registers'
        # rounding): plan from the exact target, whose joints are known.
        return last if last is not None and self._is_at(start, last) else start

    def check_model(self, flange: Pose, joints: Joints) -> None:
        """At connect: the robot's joints must put its flange where it reports it, by this
        model's kinematics; every check of a move is the model's.

        Joints all zero are not checked (a simulated arm without a joint model publishes
        zeros); a calibrated arm's few mm pass (:data:`JOINTS_MISS`).

        Raises:
            ConfigError: naming ``model``, and the built-in models the joints fit.
        """

        def fits(model: RobotModel) -> bool:
            return model.forward(joints).is_close(flange, **JOINTS_MISS)

        if not any(joints) or fits(self.model):
            return
        names = [name for name, model in ROBOT_MODELS.items() if fits(model)]
        raise ConfigError(
            f"model {self.model.name!r}: the robot's joints {[round(q, 2) for q in joints]}"
            f" put its flange at {self.model.forward(joints)}, not at {flange} where it"
            " reports it: "
            + (f"they fit {', '.join(names)}: give that model" if names else "no model fits")
        )

    def take_robot_joints(self, pose: Pose, joints: Joints | None) -> bool:
        """Plan from the joints the robot reported at ``pose``, unless they are the seed's
        (returns whether it took them). None (a profile that publishes none): away from
        the last target, the joints that put the TCP at ``pose`` on the branch assumed.

        Joints within :data:`SAME_JOINTS_DEG` of the seed keep the seed (the arm is where
        the last move put it: its exact joints and target are kept, and the solver's cache
        hits). Joints whose forward kinematics (with ``tool``) do not put the TCP at
        ``pose`` are not taken (a simulated arm without a joint model publishes zeros).
        """
        hint = self.joints_hint
        if joints is None and self.origin(pose) is not pose:
            return False  # none published, and the arm is at the last target: the seed's
        joints = joints or self.model.start_joints(pose, hint, self.tool)
        if hint is not None and all(
            abs(a - b) <= SAME_JOINTS_DEG for a, b in zip(joints, hint, strict=True)
        ):
            return False
        if not self.model.forward(joints, self.tool).is_close(pose, **JOINTS_MISS):
            if not self._joints_mismatch_logged:
                self._joints_mismatch_logged = True
                self._log.warning(
                    "robot.joints_not_taken",
                    joints=[round(q, 3) for q in joints],
                    pose=pose.as_list(),
                    reason="their forward kinematics with the tool miss the reported TCP",
                )
            return False
        self.joints_hint, self.hint_pose = joints, pose
        return True

    def _check_again(self, command: Command) -> None:
        """A move's checks before any request, again from the joints the robot reported:
        the arm is not where they had it (jogged or hand-guided since, a stopped move's
        brake), so its path from there (the body, the table) is checked anew. An arc's
        plan checks it from there anyway."""
        kind, speed = command.kind, command.speed or 0
        if kind is CommandKind.PTP_JOINTS:
            self.joint_target(command.joints or (), speed)
        elif kind is not CommandKind.CIRCLE and command.target is not None:
            self.check_path(command.target, speed, MotionType(kind.value))

    def sent(self, plan: Plan) -> None:
        """A planned move was written: the next move starts where this one ends."""
        if plan.joints is not None:
            self.joints_hint, self.hint_pose = plan.joints, plan.target

    def _is_at(self, pose: Pose, other: Pose) -> bool:
        settings = self._settings
        return pose.is_close(
            other, mm=settings.position_tolerance_mm, deg=settings.orientation_tolerance_deg
        )

    # -- expected times and timeouts -----------------------------------------

    def expected_time(
        self, start: Pose, target: Pose, speed: float, motion: MotionType, accel_time_ms: int | None
    ) -> float:
        """:meth:`Robot.expected_motion_time`: the arm model's time from the seed, s."""
        speed = self._share(speed)  # TMflow: x the project speed
        return self._model_time(self.origin(start), target, speed, motion, accel_s(accel_time_ms))

    def _model_time(
        self, origin: Pose, target: Pose, speed: float, motion: MotionType, accel: float | None
    ) -> float:
        """The arm model's time of a PTP or a Line from ``origin`` and the seed, s."""
        return self.model.motion_time(
            origin,
            target,
            speed_percent=speed,
            motion=motion,
            accel_time_s=accel,
            start_joints_deg=self.joints_hint,
            tool=self.tool,
        )

    def plan(
        self,
        command: Command,
        start: Pose | None,
        joints: Joints | None,
        *,
        timeout: float | None = None,
        resolved_at: Pose | None = None,
    ) -> Plan:
        """A command's plan from the pose (and joints) the robot reported before the write.

        A gripper command (no target) gets the gripper timeout. A move: its target's
        joints, expected time, timeout and gauge, from the arm's actual joints.

        Raises:
            UnreachablePoseError: the target (or a Line's or an arc's path) cannot be
                taken from the arm's actual joints.
            RobotError: the arm is no longer at ``resolved_at`` (a relative move's or an
                arc's start).
        """
        timeouts, target = self._settings.timeouts, command.target
        if target is None or start is None:
            limit = timeouts.gripper_timeout_s if timeout is None else timeout
            return Plan(None, None, None, 0.0, limit)
        if resolved_at is not None and not self._is_at(start, resolved_at):
            raise RobotError(
                f"the arm moved since the {command.kind.value} command was resolved against"
                f" {resolved_at}: it is at {start}; nothing was sent",
                pose=start,
            )
        if self.take_robot_joints(start, joints):
            self._check_again(command)  # the arm was not where the checks had it
        origin = self.origin(start)
        accel = accel_s(command.accel_time_ms)
        speed = float(command.speed or 100)
        if command.speed_mm_s is not None:
            speed = min(100.0, command.speed_mm_s * 100 / self.model.tcp_speed_mm_s)
        speed = self._share(speed)
        plan = self._plan_arc if command.kind is CommandKind.CIRCLE else self._plan_move
        target_joints, expected, gauge = plan(command, origin, speed, accel)
        return Plan(
            start,
            target_joints,
            target,
            expected,
            timeouts.for_motion(expected) if timeout is None else timeout,
            gauge,
            accel_s=self.model.accel_time_s if accel is None else accel,
            timeout_from_model=timeout is None and timeouts.motion_timeout_s is None,
            project_speed_percent=self.project_speed_percent,
        )

    def take_project_speed(self, values: Mapping[str, object]) -> float | None:
        """The project speed in ``values`` (``project_speed``, %), taken for the next plans.

        Args:
            values: Fields the robot reported (a status, a read of 7101).

        Returns:
            The project speed, %; None where ``values`` has none (or one out of 1..100).
        """
        value = values.get("project_speed")
        if not is_finite_number(value) or not 1 <= value <= 100:
            return None
        self.project_speed_percent = float(value)
        return self.project_speed_percent

    def _plan_move(
        self, command: Command, origin: Pose, speed: float, accel: float | None
    ) -> tuple[Joints, float, PathGauge]:
        """A PTP's, a Line's or a joint move's target joints, expected time and gauge."""
        target, hint = command.target, self.joints_hint
        assert target is not None
        first = self.model.start_joints(origin, hint, self.tool)
        if command.kind is CommandKind.PTP_JOINTS:
            assert command.joints is not None
            target_joints = self.model.check_joints(command.joints, tool=self.tool)
            expected = self.model.ptp_time(
                first, target_joints, speed_percent=speed, accel_time_s=accel
            )
            motion = MotionType.PTP
        else:
            # The same solve as validate()'s when the seed did not change (cached).
            target_joints = self.model.inverse(target, seed_deg=hint, tool=self.tool)
            self._keep_configuration(hint, target_joints, target)
            self._check_own_joints(target_joints, first)
            motion = MotionType(command.kind.value)
            expected = self._model_time(origin, target, speed, motion, accel)
            if motion is MotionType.LINE:
                self._check_turn(origin, target)
        if motion is MotionType.PTP:  # again, from the joints the robot reported
            self._check_ptp_speed(first, target_joints, speed, accel)
        gauge = PathGauge.of(
            self.model,
            origin,
            target,
            motion=motion,
            start_joints_deg=hint,
            target_joints_deg=target_joints,
            tool=self.tool,
        )
        return target_joints, expected, gauge

    def _check_own_joints(self, joints: Joints, first: Sequence[float]) -> None:
        """Refuse a target whose joints on the arm itself are past a range's end: the
        target's ``joints`` on this chain moved as the move's start's (``first``) are
        from the joints the robot reports (a calibrated arm's differ a little). A
        Cartesian target past the end by that is taken the other way round on the arm
        (a swing never planned), a Line's or an arc's not at all
        (tests/test_hunt35_joint_edges.py)."""
        if (hint := self.joints_hint) is not None and tuple(first) != hint:
            real = [t + h - f for t, h, f in zip(joints, hint, first, strict=True)]
            self.model.check_joints(real, tool=self.tool)

    def _plan_arc(
        self, command: Command, origin: Pose, speed: float, accel: float | None
    ) -> tuple[Joints, float, PathGauge]:
        """An arc's target joints, expected time and gauge (its samples checked)."""
        target, via = command.target, command.via
        assert target is not None
        assert via is not None
        samples = self.check_arc(origin, via, target, self.joints_hint)
        target_joints = self.model.check_joints(samples[-1], tool=self.tool)
        self._check_own_joints(target_joints, samples[0])
        expected = self.model.arc_time(
            origin,
            via,
            target,
            speed_percent=speed,
            accel_time_s=accel,
            tool=self.tool,
            samples=samples,
        )
        arc = arc_through(origin, via, target)
        gauge = PathGauge.along(
            origin,
            target,
            [kin.transform_to_pose(arc.at(k / PathGauge.SAMPLES)) for k in range(21)],
        )
        return target_joints, expected, gauge


# A cycle checks the same moves again: each pure check is done once per (arm, joints),
# only a passing one kept (a refusal raises, and is checked again next time).
_arm_lowest = functools.lru_cache(maxsize=256)(arm_lowest_z_mm)


# A joint set's pose configuration, once: a move's target is the next move's seed, and
# the plan asks what the check before any request asked (unless the arm moved).
_configuration = functools.lru_cache(maxsize=512)(RobotModel.configuration)


@functools.lru_cache(maxsize=256)
def _check_ptp_body(
    model: RobotModel, seed: Joints | None, joints: Joints, tool: Pose | None, floor: float | None
) -> None:
    """The arm's body along the PTP to ``joints`` from where it starts (``seed``)."""
    # From where the arm starts (not from the target itself: a joint move's seed).
    start = None if seed is None or body.same_joints(seed, joints) else seed
    samples = body.ptp_samples(start, joints)
    body.check_body(model, samples, tool=tool, floor_z_mm=floor, start=start)


def motion_type(motion: MotionType | str) -> MotionType:
    """``motion`` as a :class:`MotionType`; a ConfigError naming the choices otherwise."""
    try:
        return MotionType(motion)
    except ValueError:
        choices = ", ".join(repr(m.value) for m in MotionType)
        raise ConfigError(f"motion must be one of {choices}, got {motion!r}") from None


def accel_s(accel_time_ms: int | None) -> float | None:
    """A command's acceleration time in s; None (the model's) for None or 0 (the default)."""
    return accel_time_ms / 1000.0 if accel_time_ms else None


def check_accel(ms: object) -> None:
    """An acceleration time is None, 0 (the program's default) or an integer in TMflow's
    range, 150..9999 ms (TMflow 2.24, 9 Motion Programming, Speed of Line Motion, p. 171)."""
    if ms is not None and (type(ms) is not int or not (ms == 0 or 150 <= ms <= 9999)):
        text = "accel_time_ms must be 0 (the program's default) or an integer 150..9999 ms"
        raise ConfigError(f"{text} (TMflow's time to top speed), got {shown(ms)}")


def joint_values(joints: object) -> Joints:
    """Six finite joint angles as floats; ConfigError naming what is wrong."""
    if isinstance(joints, str | bytes | Pose) or not isinstance(joints, Sequence):
        raise ConfigError(
            f"joints must be a sequence of six angles J1..J6 (deg), got {type(joints).__name__}"
        )
    if len(joints) != 6:
        raise ConfigError(f"joints need six angles J1..J6 (deg), got {len(joints)}")
    for i, q in enumerate(joints, start=1):
        if not is_finite_number(q):
            raise ConfigError(f"J{i} must be a finite number of degrees, got {shown(q)}")
    return tuple(float(q) for q in joints)


def offset_pose(*values: object) -> Pose:
    """A relative move's offsets as a Pose; ConfigError naming a value that is no number."""
    for name, v in zip(("dx", "dy", "dz", "drx", "dry", "drz"), values, strict=True):
        if not is_finite_number(v):
            raise ConfigError(f"{name} must be a finite number, got {shown(v)}")
    return Pose(*(float(v) for v in values))  # type: ignore[arg-type]


def moved(start: Pose, offset: Pose, frame: str) -> Pose:
    """``start`` moved by ``offset``: in the tool frame (start x offset), or in the base's.

    In the base frame the TCP moves along the base's axes and turns about them in place.
    """
    here = kin.pose_to_transform(start)
    if frame == "tool":
        return kin.transform_to_pose(kin.multiply(here, kin.pose_to_transform(offset)))
    turn = kin.pose_to_transform(Pose(0, 0, 0, offset.rx, offset.ry, offset.rz))
    turned = kin.transform_to_pose(kin.multiply(turn, here))
    x, y, z = start.x + offset.x, start.y + offset.y, start.z + offset.z
    return Pose(x, y, z, turned.rx, turned.ry, turned.rz)
