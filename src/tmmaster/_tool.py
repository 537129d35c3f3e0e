"""The robot's tool and frames, checked: at connect and before every move.

``Robot(tool=...)`` takes a :class:`~tmmaster.Pose` (the TCP in the flange frame) or a
:class:`Tool` (that TCP with its mass). Where the profile publishes Techman's frames
(``tmflow``: 7001-7060, flange, joints and TCP in the current base and in the robot
base, one request), the :class:`FrameGuard` checks that the robot's TCP is its flange x
the master's tool and that its current base is the robot base, at connect and before
every move, from the read the move makes anyway (its start pose and joints). At connect
it also reads the TCP value and mass the robot works with (7354-7366, TMflow 2.24
Appendix C p. 313) and refuses a mismatch with the master's tool. A profile that
publishes none of them (``article``) cannot verify a tool: a Robot with one refuses to
connect unless ``Checks(frame=FrameCheck.off("why"))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from . import _kinematics as kin
from ._channels import CommandChannel, Ticket, pose_from
from ._checks import is_finite_number, shown
from ._codec import Value
from ._exceptions import ConfigError
from ._pose import Pose, refuse_suspect_units
from ._registers import FLANGE_FIELDS, ROBOT_BASE_TCP_FIELDS, TCP_FIELDS

if TYPE_CHECKING:
    from ._options import FrameCheck
    from ._robot_models import RobotModel

_AXES = ("x", "y", "z", "rx", "ry", "rz")
#: The TCP value the robot works with (TMflow 2.24 Appendix C, p. 313), then its mass.
TCP_VALUE_FIELDS = tuple(f"tcp_value_{n}" for n in _AXES)
TCP_MASS_FIELD = "tcp_value_mass"
#: The heaviest tool a Tool may carry, kg (the robot program's bound).
TOOL_MASS_MAX_KG = 100.0
#: How far the robot's tool mass may be from the master's, kg.
MASS_TOLERANCE_KG = 0.01


class ToolMismatchError(ConfigError):
    """The robot's tool or frames are not those the master plans with.

    Raised at :meth:`~tmmaster.Robot.connect` and before a move (nothing is written),
    naming the field that differs (``tcp_value_mass``, ``tool z``, the base) and both
    values. ``Robot(checks=Checks(frame=FrameCheck.off("why")))`` switches the check off.
    """


@dataclass(frozen=True)
class Tool:
    """A tool as TMflow's tool settings hold it: its TCP in the flange frame and its mass.

    ``Robot(host, tool=Tool(Pose(0, 0, 150, 0, 0, 0), mass_kg=1.1))``: at connect the
    master reads the TCP value and mass the robot works with (``tmflow``: Techman's
    7354-7366) and refuses a mismatch.

    Args:
        pose: The TCP in the flange frame (mm, deg).
        mass_kg: The tool's mass, kg (0 to 100).
        name: The tool's name in TMflow, for messages (optional).

    Raises:
        ConfigError: ``pose`` not a Pose, a mass that is not a finite number in
            [0, 100] kg, a name that is not a non-empty string.
    """

    #: The TCP in the flange frame (mm, deg).
    pose: Pose
    #: The tool's mass, kg.
    mass_kg: float
    #: The tool's name in TMflow (None: unnamed).
    name: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.pose, Pose):
            raise ConfigError(f"tool.pose must be a tmmaster.Pose, got {shown(self.pose)}")
        mass = self.mass_kg
        if not is_finite_number(mass) or not 0 <= mass <= TOOL_MASS_MAX_KG:
            raise ConfigError(
                f"tool.mass_kg must be a number in [0, {TOOL_MASS_MAX_KG:g}] kg, got {shown(mass)}"
            )
        object.__setattr__(self, "mass_kg", float(mass))
        if self.name is not None and (not isinstance(self.name, str) or not self.name.strip()):
            raise ConfigError(
                f"tool.name must be a non-empty string or None, got {shown(self.name)}"
            )


def tool_option(tool: object, units: bool, arm: RobotModel) -> tuple[Pose | None, Tool | None]:
    """The ``tool`` option split: its pose (not in metres or radians, checked when
    ``units``) and the Tool, if one, its mass within ``arm``'s rated payload: TMflow
    refuses a heavier TCP load (TMflow 2.24 appendix J, 0x0004003B "Over maximum loading
    with TCP loading": the TCP's mass plus the payload setting)."""
    pose, spec = (tool.pose, tool) if isinstance(tool, Tool) else (tool, None)
    if pose is not None and not isinstance(pose, Pose):
        raise ConfigError(
            "tool must be a tmmaster.Pose (the TCP in the flange frame) or a tmmaster.Tool"
            f" (with its mass), got {tool!r}"
        )
    if units and pose is not None:
        refuse_suspect_units("tool", pose)
    if spec is not None and spec.mass_kg > (arm.payload_kg or math.inf):
        raise ConfigError(
            f"tool.mass_kg {spec.mass_kg:g} kg is over the {arm.name}'s rated payload of"
            f" {arm.payload_kg:g} kg: the robot refuses that TCP load (error 0x0004003B)"
        )
    return pose, spec


class FrameGuard:
    """The frame check of one robot: at connect and before every move.

    Args:
        channel: The robot's command channel (its field sets).
        check: The :class:`FrameCheck` settings.
        tool: The Tool given (with its mass), or None.
        log: The robot's logger.
    """

    def __init__(
        self, channel: CommandChannel, check: FrameCheck, tool: Tool | None, log: Any
    ) -> None:
        self._channel = channel
        self.check = check
        self.tool = tool
        self._log = log
        self.value_fields = channel.profile.published((*TCP_VALUE_FIELDS, TCP_MASS_FIELD))
        #: True where every plan read carries the frames (``tmflow``: 7001-7060).
        self.per_move = bool(channel.flange_fields) and channel.frames_in_plan

    @property
    def enabled(self) -> bool:
        """True when the check is on and the profile publishes the frames."""
        return self.check.enabled and bool(self._channel.flange_fields)

    def refuse_unverifiable(self, tool: Pose | None) -> None:
        """At connect: a tool the profile gives no way to verify is refused (check on).

        Raises:
            ConfigError: a tool, the check on, and no flange pose nor TCP value published.
        """
        channel, enabled = self._channel, self.check.enabled
        if channel.flange_fields and not enabled:
            self._log.warning("robot.frame_check_off", reason=self.check.reason)
        if channel.flange_fields or not enabled or (tool is None and self.tool is None):
            return
        raise ConfigError(
            f"profile {channel.profile.name!r} publishes neither the flange pose nor the TCP"
            " value and mass (Techman's 7001-7060, 7354-7366): the master cannot verify that"
            " the robot works with this Robot's tool, and a wrong tool puts every move off"
            " by its offset. Use a profile that publishes them (tmflow), or pass"
            ' checks=Checks(frame=FrameCheck.off("why")) once you have checked the tool on'
            " the robot"
        )

    def at_connect(self, values: dict[str, Value], tool: Pose | None) -> None:
        """The frames read at connect, and the TCP value and mass (one more read).

        Raises:
            ToolMismatchError: the robot's TCP, base, TCP value or mass are not the
                master's.
        """
        self.frames(values, tool, "at connect")
        if not self.value_fields:
            return
        read = self._channel.read(self.value_fields)
        value = pose_from(read, TCP_VALUE_FIELDS)
        expected = tool or Pose(0, 0, 0, 0, 0, 0)
        mm, deg = value.distance_to(expected), value.rotation_to(expected)
        if mm > self.check.position_tolerance_mm or deg > self.check.orientation_tolerance_deg:
            field = _worst_axis(value, expected)
            raise ToolMismatchError(
                f"frame check at connect: tcp_value_{field} differs: the robot's TCP value"
                f" (7354-7364) is {_pose_text(value)}, this Robot's tool is"
                f" {_pose_text(expected)} ({mm:.1f} mm, {deg:.1f} deg apart)"
            )
        mass = float(read[TCP_MASS_FIELD])
        if self.tool is not None and abs(mass - self.tool.mass_kg) > MASS_TOLERANCE_KG:
            raise ToolMismatchError(
                f"frame check at connect: tcp_value_mass differs: the robot's tool weighs"
                f" {mass:g} kg (7366), this Robot's tool {self.tool.mass_kg:g} kg: the robot"
                " would misread the tool's weight as an external force (TMflow 2.24 p. 156)."
                " Give Robot(tool=Tool(..., mass_kg=...)) the robot's tool, or set the"
                " robot's (tmmaster robot-program --tool-mass)"
            )

    def arm_before(
        self, ticket: Ticket, tool: Pose | None
    ) -> tuple[Pose, tuple[float, ...] | None]:
        """Where a move starts, its frames checked: the checks' read when they made one,
        else one read (7001-7060 where published: no request more than the pose's).

        Raises:
            ToolMismatchError: the robot's TCP is not its flange x ``tool`` now, or its
                base is not the robot base (nothing is written).
        """
        channel = self._channel
        start, joints, values = ticket.start_pose, ticket.start_joints, ticket.start_values
        check = self.per_move and self.check.enabled
        if start is None or (joints is None and channel.joint_fields) or (check and not values):
            start, joints, values = channel.read_plan()
        if check and values:
            self.frames(values, tool, f"before this {ticket.command.kind.value} command")
        return start, joints

    def frames(self, values: dict[str, Value], tool: Pose | None, when: str) -> None:
        """The robot's TCP is its flange x ``tool``, and its current base the robot base.

        Raises:
            ToolMismatchError: naming the tool offset the robot appears to have, or the
                two TCP poses when the current base is not the robot base.
        """
        check = self.check
        flange, tcp = pose_from(values, FLANGE_FIELDS), pose_from(values, TCP_FIELDS)
        offset = kin.IDENTITY if tool is None else kin.pose_to_transform(tool)
        expected = kin.transform_to_pose(kin.multiply(kin.pose_to_transform(flange), offset))
        mm, deg = tcp.distance_to(expected), tcp.rotation_to(expected)
        if mm > check.position_tolerance_mm or deg > check.orientation_tolerance_deg:
            apparent = kin.transform_to_pose(
                kin.multiply(kin.invert(kin.pose_to_transform(flange)), kin.pose_to_transform(tcp))
            )
            mine = "none (the TCP is the flange)" if tool is None else _pose_text(tool)
            field = _worst_axis(apparent, tool or Pose(0, 0, 0, 0, 0, 0))
            raise ToolMismatchError(
                f"frame check {when}: tool {field} differs: the robot's TCP is not its flange"
                f" x this Robot's tool: the robot reports a tool offset of"
                f" {_pose_text(apparent)} (inverse(flange) x TCP; TCP {tcp}, flange {flange}),"
                f" this Robot's tool is {mine} ({mm:.1f} mm, {deg:.1f} deg apart). Give"
                " Robot(tool=...) the robot's tool, or generate the robot program for the"
                " master's (tmmaster robot-program --tool; its ChangeTCP sets the robot's TCP"
                " when the project starts), or pass"
                ' checks=Checks(frame=FrameCheck.off("why"))'
            )
        if not self._channel.robot_base_tcp_fields or ROBOT_BASE_TCP_FIELDS[0] not in values:
            return
        base_tcp = pose_from(values, ROBOT_BASE_TCP_FIELDS)
        if not base_tcp.is_close(
            tcp, mm=check.position_tolerance_mm, deg=check.orientation_tolerance_deg
        ):
            raise ToolMismatchError(
                f"frame check {when}: the base differs: the robot reports its TCP in a base"
                f" other than the robot base ({tcp} in the current base, {base_tcp} in the"
                " robot base); the master's poses are in the robot base (the robot"
                ' program\'s ChangeBase("RobotBase") when the project starts), or pass'
                ' checks=Checks(frame=FrameCheck.off("why"))'
            )


def _worst_axis(got: Pose, wanted: Pose) -> str:
    """The axis (x .. rz) on which two poses differ most (mm and deg taken alike)."""
    diffs = [abs(a - b) for a, b in zip(got.as_list(), wanted.as_list(), strict=True)]
    diffs[3:] = [min(d, 360 - d) for d in diffs[3:]]
    return _AXES[diffs.index(max(diffs))]


def _pose_text(pose: Pose) -> str:
    """``pose`` as ``(x, y, z, rx, ry, rz)`` rounded to 0.01: ``(0, 0, 150, 0, 0, 0)``."""
    values = [round(v, 2) + 0.0 for v in pose.as_list()]  # + 0.0: no "-0"
    return "(" + ", ".join(f"{v:g}" for v in values) + ")"
