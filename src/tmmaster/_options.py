"""The option objects of :class:`~tmmaster.Robot` that group what it checks and where its
stand-alone gripper is: :class:`Checks` (with :class:`FrameCheck`) and
:class:`GripperDevice`. The polling and timeout options are :class:`~tmmaster.PollPolicy`
and :class:`~tmmaster.TimeoutPolicy`, next to the code that reads them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, ClassVar

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from ._address import check_host, check_port, is_in_process
from ._checks import Bounds, Policy, bounded, shown
from ._exceptions import ConfigError
from ._planning import Workspace
from ._registers import GripperProfile
from ._robot_models import TCP_SPEED_MAX
from ._transport import Transport


class FrameCheck(BaseModel):
    """At connect: the robot's TCP must be its flange times the master's ``tool``.

    For a profile that publishes the flange pose and the TCP pose (``tmflow``: Techman's
    7001-7012 and 7025-7036, both in the current base), :meth:`Robot.connect` reads both
    in one request and refuses a robot whose TCP is not ``flange x tool`` within the
    tolerances, naming the tool offset the robot appears to have (``inverse(flange) x
    TCP``). Where the profile also publishes the TCP in the robot base (7049-7060), the
    two TCP poses must agree: the master's poses are in the robot base. On by default;
    ``FrameCheck.off("why")`` switches it off, and the reason is logged at warning level
    at every connect.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    #: False: not checked (``reason`` says why).
    enabled: bool = True
    #: Why the check is off (required then); logged at warning level at connect.
    reason: str = ""
    #: Largest distance between the robot's TCP and flange x tool, mm.
    position_tolerance_mm: Annotated[float, Field(gt=0, le=1000)] = 1.0
    #: Largest angle between the two orientations (:meth:`Pose.rotation_to`), deg.
    orientation_tolerance_deg: Annotated[float, Field(gt=0, le=180)] = 1.0

    @model_validator(mode="after")
    def _off_needs_a_reason(self) -> FrameCheck:
        if not self.enabled and not self.reason.strip():
            raise ValueError('a frame check switched off needs a reason: FrameCheck.off("why")')
        return self

    @classmethod
    def off(cls, reason: str) -> FrameCheck:
        """The check switched off, for ``reason`` (logged at warning level at connect).

        Args:
            reason: why the robot's TCP need not match the master's tool (not empty).

        Returns:
            A disabled check.

        Raises:
            ConfigError: ``reason`` is empty.
        """
        if not isinstance(reason, str) or not reason.strip():
            raise ConfigError(f"FrameCheck.off needs a reason, got {reason!r}")
        return cls(enabled=False, reason=reason)


#: The range of a finished move's position tolerance (``Checks.position_tolerance_mm``).
POSITION_BOUNDS = Bounds(0.0, 50.0, "mm", open_low=True)
#: The range of a finished move's orientation tolerance (``Checks.orientation_tolerance_deg``).
ORIENTATION_BOUNDS = Bounds(0.0, 45.0, "deg", open_low=True)


def speed_limit(value: object, name: str = "max_speed_percent") -> int:
    """``value`` when it is an integer in [1, 100]; a ConfigError naming ``name`` otherwise.

    Args:
        value: what the caller gave.
        name: the option's name in the message.

    Returns:
        The speed limit, %.

    Raises:
        ConfigError: not an integer in [1, 100].
    """
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 100:
        raise ConfigError(f"{name} must be an integer in [1, 100] %, got {shown(value)}")
    return value


class Checks(Policy):
    """What the master checks of a move before it sends it and at its end, and of the
    robot at connect.

    ``Robot(host, checks=Checks(max_speed_percent=50, workspace=Workspace(floor_z_mm=0)))``.
    Before a byte is sent: the tool inside ``workspace``, the speed at most
    ``max_speed_percent``, the target's units (``units``), a PTP's TCP speed at most
    ``tcp_speed_limit_mm_s``; at the end of a move: the TCP within the two tolerances
    of the target; at connect: the robot's TCP against its flange x ``tool``
    (``frame``). The defaults are the safe ones. An invalid value
    is a :class:`~tmmaster.ConfigError` naming the field (``checks.max_speed_percent
    must be an integer in [1, 100] %, got 0``).
    """

    #: The Robot argument that takes it: its fields are named ``checks.<field>`` in errors.
    argument: ClassVar[str] = "checks"

    #: Where the tool may go (a table plane and a box): the default cell's table.
    workspace: Workspace = Workspace()
    #: Faster moves are refused, an integer 1..100 (%).
    max_speed_percent: Annotated[
        int, BeforeValidator(functools.partial(speed_limit, name="checks.max_speed_percent"))
    ] = 100
    #: A finished move's TCP must be this close to the target, mm (up to 50).
    position_tolerance_mm: Annotated[
        float, BeforeValidator(bounded("checks.position_tolerance_mm", POSITION_BOUNDS))
    ] = 1.0
    #: ... and its orientation this close, deg (up to 45).
    orientation_tolerance_deg: Annotated[
        float, BeforeValidator(bounded("checks.orientation_tolerance_deg", ORIENTATION_BOUNDS))
    ] = 1.0
    #: A PTP whose TCP would run faster is refused, mm/s (up to 4500): the robot's TCP
    #: speed limit (TMflow's Safety Settings, Performance Safety "TCP Speed", a stop
    #: criterion). None: the arm model's, TMflow's default 1500 mm/s; raise it to the
    #: robot's own where its safety settings raise it (docs/kinematics.md).
    tcp_speed_limit_mm_s: Annotated[float, Field(gt=0, le=TCP_SPEED_MAX, strict=True)] | None = None
    #: Refuse (UnitsError, before anything is sent) a target or a ``tool`` that looks
    #: like metres or radians; False takes them as written.
    units: bool = Field(default=True, strict=True)
    #: At connect, the robot's TCP must be its flange x ``tool``;
    #: ``FrameCheck.off("why")`` switches it off.
    frame: FrameCheck = FrameCheck()


@dataclass(frozen=True)
class GripperDevice:
    """A gripper on a Modbus connection of its own: ``Robot(host, gripper=GripperDevice(...))``.

    Args:
        profile: The gripper's register map: ``"blog-2fg7"``, ``"onrobot-2fg7"``, a
            gripper TOML file or a GripperProfile.
        host: Where it listens; None: the robot's host.
        port: Its Modbus TCP port.
        transport: A ready Transport for its link instead of one opened to
            ``host:port``.

    Raises:
        ConfigError: An invalid host or port (named ``gripper.host``, ``gripper.port``),
            a profile that is not a name, a file or a GripperProfile, or a transport
            that is not a Transport.
    """

    #: The gripper's register map: a built-in name, a TOML file or a GripperProfile.
    profile: str | Path | GripperProfile
    #: Where it listens; None: the robot's host.
    host: str | None = None
    #: Its Modbus TCP port.
    port: int = 502
    #: A ready link instead of one opened to ``host:port``.
    transport: Transport | None = None

    def __post_init__(self) -> None:
        if self.profile in ("auto", "none") or not isinstance(
            self.profile, str | Path | GripperProfile
        ):
            raise ConfigError(
                "gripper.profile must be a gripper profile's name, a TOML file or a"
                f" GripperProfile, got {shown(self.profile)}"
            )
        if self.transport is not None:
            if not isinstance(self.transport, Transport):
                raise ConfigError(
                    f"gripper.transport must be a tmmaster.Transport, got {shown(self.transport)}"
                )
            return
        if self.host is None:
            return  # at the robot's host: the robot checks the port (none for sim://)
        host = check_host(self.host, field="gripper.host", port_field="gripper.port")
        object.__setattr__(self, "host", host)
        if not is_in_process(host):
            object.__setattr__(self, "port", check_port(self.port, field="gripper.port"))
