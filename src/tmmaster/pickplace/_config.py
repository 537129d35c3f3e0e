"""The pick & place configuration: one TOML file, validated by pydantic before any I/O.

Every default reproduces the article's master: its five poses, 30 % PTP for approach,
place and home, 10 % Line for pick and lift, 50 ms polling; only the register contract
defaults to ``tmflow`` (the one safe on a real robot), not the article's map. Unknown
keys are refused (a typo must not silently fall back to a default), and every error
names the key and the file it came from. The sections that configure the robot API are
its own models (:class:`TimeoutPolicy`, :class:`RetryPolicy`, :class:`Workspace`).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal, Self, get_args, get_origin

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic.json_schema import SkipJsonSchema

from .. import _profiles
from .._address import check_host
from .._cell import DEFAULT_TABLE_TOP_Z_MM
from .._exceptions import ConfigError
from .._io import io_address
from .._options import Checks, GripperDevice
from .._poller import PollPolicy
from .._pose import MotionType, Pose, pose_count_problem, suspect_units, written_list
from .._profiles import DEFAULT_PROFILE
from .._registers import GripperProfile, RobotProfile
from .._retry import RetryPolicy
from .._robot import FrameCheck, Robot, TimeoutPolicy, Workspace
from .._toml import read_toml


def _finite_pose(value: object) -> object:
    if isinstance(value, list | tuple):
        if len(value) != 6:  # said with the values as written and the names missing
            raise ValueError(pose_count_problem(value))
        # A NaN or infinite coordinate would pass a range check ("not < max") by accident;
        # a number written as text ("300") is refused as tmmaster.Pose refuses it.
        for item in value:
            if isinstance(item, bool) or not isinstance(item, int | float):
                raise ValueError(
                    f"pose values must be numbers, got {item!r} in {written_list(value)}"
                )
            if isinstance(item, float) and not math.isfinite(item):
                raise ValueError("pose values must be finite numbers")
    return value


def units_problem(where: str, values: tuple[float, ...], opt_out: str) -> str | None:
    """Why the pose at ``where`` looks like metres or radians (quoting it), or None.

    ``opt_out`` says how to switch the check off in that file.
    """
    problem = suspect_units(values)
    if problem is None:
        return None
    return (
        f"{where}: {written_list(values)}: {problem}; if these really are mm and degrees,"
        f" set {opt_out}"
    )


#: ``[x, y, z, rx, ry, rz]`` in mm and degrees.
PoseValue = Annotated[
    tuple[float, float, float, float, float, float], BeforeValidator(_finite_pose)
]
Speed = Annotated[int, Field(ge=1, le=100, strict=True)]

#: The article's pick pose (its approach and lift derive from it), mm and degrees.
ARTICLE_PICK = (300.0, -200.0, 100.0, 180.0, 0.0, 90.0)
#: The article's place pose, mm and degrees.
ARTICLE_PLACE = (300.0, 200.0, 200.0, 180.0, 0.0, 90.0)
#: The article's HOME: out of a TM5's reach (the wrist offsets keep a tool-down flange
#: ~120 mm from the J1 axis), refused by inverse kinematics; see docs/pickplace.md.
ARTICLE_HOME = (0.0, 0.0, 300.0, 180.0, 0.0, 0.0)
#: The default home: tool down, 250 mm in front of J1 (tmmaster.DEFAULT_HOME).
DEFAULT_HOME_VALUE = (250.0, 0.0, 300.0, 180.0, 0.0, 90.0)


class _Section(BaseModel):
    # Every number in a configuration is finite: NaN and infinity pass range checks by
    # accident ("not < max"), so they are refused here, naming the key.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class RobotSection(_Section):
    """Which robot and how to reach it."""

    #: Register contract: "tmflow" (default), "article", or a profile TOML file.
    profile: str = DEFAULT_PROFILE
    #: Arm model (reach, speed limits): tm5-700, tm5-900, tm12, tm14.
    model: Literal["tm5-700", "tm5-900", "tm12", "tm14"] = "tm5-700"
    #: The robot's IP address or host name (no port, no URL: the port is ``port``).
    host: str | None = None
    #: The robot's Modbus TCP port.
    port: Annotated[int, Field(ge=1, le=65535)] = 502
    #: Highest speed any move may use, %.
    max_speed: Speed = 100
    #: A finished move's TCP must be this close to the target, mm.
    position_tolerance_mm: Annotated[float, Field(gt=0, le=50)] = 1.0
    #: The TCP in the flange frame ``[x, y, z, rx, ry, rz]`` (mm, deg); poses are TCP poses.
    tool: PoseValue | None = None
    #: At connect, the robot's TCP must be its flange x ``tool`` (tmflow). Switched off
    #: only with a reason: ``[robot.frame_check]`` ``enabled = false``, ``reason = "..."``.
    frame_check: FrameCheck = FrameCheck()

    @field_validator("host")
    @classmethod
    def _an_address(cls, host: str | None) -> str | None:
        return None if host is None else check_host(host, field="", port_field="robot.port")

    def tool_pose(self) -> Pose | None:
        """The tool offset as a :class:`Pose`, or None for the bare flange.

        Returns:
            The TCP in the flange frame, or None.
        """
        return None if self.tool is None else Pose.from_sequence(self.tool)


class PosesSection(_Section):
    """Task poses; approach and lift default to the pick pose raised by a z offset."""

    #: Above the pick pose (default: ``pick`` raised by ``approach_z_offset``).
    approach: PoseValue | None = None
    #: Where the part is gripped.
    pick: PoseValue = ARTICLE_PICK
    #: Where the part is lifted to (default: ``pick`` raised by ``lift_z_offset``).
    lift: PoseValue | None = None
    #: Where the part is released.
    place: PoseValue = ARTICLE_PLACE
    #: Where each cycle ends (and the retreat goes, by default).
    home: PoseValue = DEFAULT_HOME_VALUE
    #: approach = pick + this in z, unless ``approach`` is given (article: 100 mm).
    approach_z_offset: Annotated[float, Field(ge=0, le=1000)] = 100.0
    #: lift = pick + this in z, unless ``lift`` is given (article: 150 mm).
    lift_z_offset: Annotated[float, Field(ge=0, le=1000)] = 150.0
    #: Refuse a pose of this file that looks like metres or radians (every pose:
    #: [poses], [robot] tool, [on_error] pose); false: take them as mm and degrees.
    check_units: bool = True

    @model_validator(mode="after")
    def _one_source_each(self) -> Self:
        for pose, offset in (("approach", "approach_z_offset"), ("lift", "lift_z_offset")):
            if getattr(self, pose) is not None and offset in self.model_fields_set:
                raise ValueError(f"give either {pose} or {offset}, not both")
        return self

    def resolved(self) -> dict[str, Pose]:
        """Every pose of the cycle, derived ones included.

        Returns:
            ``approach``, ``pick``, ``lift``, ``place`` and ``home``, as Poses.
        """
        pick = Pose.from_sequence(self.pick)
        approach = (
            Pose.from_sequence(self.approach)
            if self.approach is not None
            else pick.offset(dz=self.approach_z_offset)
        )
        lift = (
            Pose.from_sequence(self.lift)
            if self.lift is not None
            else pick.offset(dz=self.lift_z_offset)
        )
        return {
            "approach": approach,
            "pick": pick,
            "lift": lift,
            "place": Pose.from_sequence(self.place),
            "home": Pose.from_sequence(self.home),
        }


class SpeedsSection(_Section):
    """Speed of each move, % (article: normal 30 %, slow 10 % for pick and lift)."""

    #: Speed to the approach pose, %.
    approach: Speed = 30
    #: Speed down to the pick pose, %.
    pick: Speed = 10
    #: Speed of the lift, %.
    lift: Speed = 10
    #: Speed to the place pose, %.
    place: Speed = 30
    #: Speed home, %.
    home: Speed = 30


class MotionSection(_Section):
    """Motion type of each move: "ptp" (joint interpolation) or "line"."""

    #: Motion type to the approach pose.
    approach: MotionType = MotionType.PTP
    #: Motion type down to the pick pose.
    pick: MotionType = MotionType.LINE
    #: Motion type of the lift.
    lift: MotionType = MotionType.LINE
    #: Motion type to the place pose.
    place: MotionType = MotionType.PTP
    #: Motion type home.
    home: MotionType = MotionType.PTP


class TimeoutsSection(TimeoutPolicy):
    """How long each wait may take, in seconds: the robot API's :class:`TimeoutPolicy`
    (``ack_timeout_s``, ``motion_factor``, ``motion_margin_s``, ``motion_timeout_s``,
    ``gripper_timeout_s``, ``in_flight_s``; the older keys ``ack_s``, ``motion_s`` and
    ``gripper_s`` are accepted) and the two waits the runner and the link add."""

    #: One Modbus request must be answered within this time.
    request_s: Annotated[float, Field(gt=0, le=60)] = 1.0
    #: The robot must be ready (auto, idle, no error) within this time at start.
    ready_s: Annotated[float, Field(gt=0, le=600)] = 10.0
    #: Not a key of this section: the gripper's settle time is ``[gripper] settle_s``.
    gripper_settle_s: SkipJsonSchema[float] = Field(default=0.5, exclude=True)

    @model_validator(mode="before")
    @classmethod
    def _settle_is_the_grippers(cls, data: Any) -> Any:
        if isinstance(data, Mapping) and "gripper_settle_s" in data:
            raise ValueError("gripper_settle_s is not a [timeouts] key: set [gripper] settle_s")
        return data


class RetrySection(RetryPolicy):
    """Retries of Modbus requests that failed transiently (reads, connects; never commands):
    the robot API's :class:`RetryPolicy`, with 5 attempts by default."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    #: Total attempts, the first one included.
    attempts: Annotated[int, Field(ge=1, le=100, strict=True)] = 5
    #: Give up once this much time has passed since the first attempt, s.
    total_time_s: Annotated[float, Field(gt=0, le=600)] = 10.0


class GripperSection(_Section):
    """The gripper: "auto" uses what the robot profile offers (article: gripper register)."""

    #: "auto", "none", "blog-2fg7", "onrobot-2fg7" or a gripper profile TOML file.
    kind: str = "auto"
    #: Host / port of a gripper with its own connection (default: the robot's host).
    host: str | None = None
    #: The port of a gripper with its own connection.
    port: Annotated[int, Field(ge=1, le=65535)] = 502
    #: Register gripper without busy flag: how long a close/open takes at most, s.
    settle_s: Annotated[float, Field(gt=0, le=60)] = 0.5
    #: Open the fingers before the first approach (never approach a part with them closed).
    #: A gripper that reports holding a part is not opened: the run refuses to start.
    open_at_start: bool = True
    #: With ``open_at_start``: a part the gripper reports holding at the start is released
    #: where the arm is then (it falls there). False: the run refuses to start instead.
    release_held_part_at_start: bool = False
    #: The robot's digital input that is high while the fingers hold a part (on a TM the
    #: end module's DI wired to the gripper's grip signal: the robot program's ``--gripper
    #: io:di=N``). The run reads it, not the gripper's grasp flag, at its start and before
    #: each release (where a part lost on the way is caught). None: the gripper's flag.
    held_input: Annotated[int, Field(ge=0, le=15, strict=True)] | None = None
    #: The module of ``held_input``: "end_module" or "control_box".
    held_input_module: Literal["end_module", "control_box"] = "end_module"

    @field_validator("host")
    @classmethod
    def _an_address(cls, host: str | None) -> str | None:
        return None if host is None else check_host(host, field="", port_field="gripper.port")

    @field_validator("release_held_part_at_start")
    @classmethod
    def _release_needs_the_open(cls, release: bool, info: ValidationInfo) -> bool:
        # open_at_start is declared (so validated) first: a bad value of it is its own error.
        if release and info.data.get("open_at_start") is False:
            raise ValueError(
                "needs open_at_start = true (with open_at_start = false nothing is opened at"
                " the start, so nothing is released)"
            )
        return release


class WorkspaceSection(Workspace):
    """Where the tool may go: the robot API's :class:`Workspace`, with the table plane at
    the top of the table the default plan is written for (85 mm: the article's 30 mm part,
    gripped at its centre at z = 100 mm, rests on it; the built-in simulator's table).

    A plan for another cell states its own table: ``floor_z_mm`` (the top of your table
    in the robot base frame, mm), or ``floor_z_mm = -2000`` for an arm that reaches below
    its base. A target below the plane is refused before anything connects.
    """

    #: The table plane, mm: no TCP and no flange below it. None: no plane.
    floor_z_mm: float | None = DEFAULT_TABLE_TOP_Z_MM


class RunSection(_Section):
    """How the cycle runs."""

    #: How many cycles to run.
    cycles: Annotated[int, Field(ge=1, le=1_000_000, strict=True)] = 1
    #: Seconds between two status reads of a wait.
    poll_interval_s: Annotated[float, Field(ge=0.005, le=5)] = 0.05
    #: After a failed grasp: open, re-approach and try again up to this many times.
    grasp_retries: Annotated[int, Field(ge=0, le=20, strict=True)] = 2


class OnErrorSection(_Section):
    """What the robot does after a failure (never anything after an e-stop or robot error)."""

    #: "stay" where it stopped, or "retreat" to ``pose``.
    reaction: Literal["stay", "retreat"] = "stay"
    #: Safe pose to retreat to (default: home), reached at low speed.
    pose: PoseValue | None = None
    #: Speed of the retreat, %.
    speed: Speed = 10
    #: Motion type of the retreat.
    motion: MotionType = MotionType.PTP


class PickPlaceConfig(_Section):
    """The whole pick & place configuration (every section optional)."""

    #: ``[robot]``: which robot and how to reach it.
    robot: RobotSection = RobotSection()
    #: ``[poses]``: the task poses.
    poses: PosesSection = PosesSection()
    #: ``[speeds]``: the speed of each move.
    speeds: SpeedsSection = SpeedsSection()
    #: ``[motion]``: the motion type of each move.
    motion: MotionSection = MotionSection()
    #: ``[timeouts]``: how long each wait may take.
    timeouts: TimeoutsSection = TimeoutsSection()
    #: ``[retry]``: retries of transiently failed requests.
    retry: RetrySection = RetrySection()
    #: ``[gripper]``: the gripper.
    gripper: GripperSection = GripperSection()
    #: ``[run]``: how the cycle runs.
    run: RunSection = RunSection()
    #: ``[on_error]``: what the robot does after a failure.
    on_error: OnErrorSection = OnErrorSection()
    #: ``[workspace]``: the table plane (default: the default plan's table, 85 mm) and an
    #: optional box the TCP must stay inside, mm (base frame).
    workspace: WorkspaceSection = WorkspaceSection()
    # The register maps robot.profile and gripper.kind name, once loaded (load_config
    # loads them): the robot and the simulator get the very maps that were checked.
    # Kept with the name they were loaded for (a model_copy may change the name).
    _robot_profile: tuple[str, RobotProfile] | None = PrivateAttr(default=None)
    _gripper_profile: tuple[str, GripperProfile] | None = PrivateAttr(default=None)

    def digest(self) -> str:
        """sha256 of the normalised configuration (defaults filled in, keys sorted).

        Returns:
            ``"sha256:..."``, the run report's ``config.digest``.
        """
        text = json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))
        return "sha256:" + hashlib.sha256(text.encode()).hexdigest()

    def robot_profile(self) -> RobotProfile:
        """The register map ``robot.profile`` names, loaded once.

        Returns:
            The robot profile.

        Raises:
            RegisterMapError: The profile cannot be loaded.
        """
        name = self.robot.profile
        if self._robot_profile is None or self._robot_profile[0] != name:
            self._robot_profile = (name, _profiles.robot_profile(name))
        return self._robot_profile[1]

    def gripper_profile(self) -> GripperProfile | None:
        """The gripper map ``gripper.kind`` names, loaded once (None: "auto", "none").

        Returns:
            The gripper profile, or None.

        Raises:
            RegisterMapError: The profile cannot be loaded.
        """
        kind = self.gripper.kind
        if kind in ("auto", "none"):
            return None
        if self._gripper_profile is None or self._gripper_profile[0] != kind:
            self._gripper_profile = (kind, _profiles.gripper_profile(kind))
        return self._gripper_profile[1]

    def retreat_pose(self) -> Pose:
        """Where the "retreat" error reaction goes.

        Returns:
            ``on_error.pose``, else the home pose.
        """
        if self.on_error.pose is not None:
            return Pose.from_sequence(self.on_error.pose)
        return self.poses.resolved()["home"]


def check_profiles(config: PickPlaceConfig, source: str) -> None:
    """Load the robot and gripper profiles the config names; errors name key and file."""
    try:
        config.robot_profile()
    except (ConfigError, OSError) as exc:
        raise ConfigError(f"{source}: robot.profile: {exc}") from None
    try:
        config.gripper_profile()
    except (ConfigError, OSError) as exc:
        raise ConfigError(f"{source}: gripper.kind: {exc}") from None


def format_validation_error(exc: ValidationError, source: str) -> str:
    """One line naming every bad key (dotted path) and the file it came from."""
    problems = []
    for error in exc.errors():
        where = ".".join(str(part) for part in error["loc"]) or "(top level)"
        message = error["msg"].removeprefix("Value error, ")  # our own validators' text
        if error["type"] == "extra_forbidden":
            message = "unknown key"
        problems.append(f"{where}: {message}")
    return f"{source}: " + "; ".join(problems)


def validate_config(data: Mapping[str, Any], *, source: str = "<defaults>") -> PickPlaceConfig:
    """Validate a mapping; raises :class:`ConfigError` naming the key and ``source``.

    Args:
        data: The configuration's sections (a parsed TOML file).
        source: Where the data comes from, for the messages.

    Returns:
        The configuration.

    Raises:
        ConfigError: A bad key or value (naming every one), or a pose that looks like
            metres or radians.
    """
    if problems := _numbers_not_given_as_numbers(data):
        raise ConfigError(f"{source}: " + "; ".join(problems))
    try:
        config = PickPlaceConfig.model_validate(dict(data))
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc, source)) from None
    check_pose_units(config, source)
    return config


def _numbers_not_given_as_numbers(data: Mapping[str, Any]) -> list[str]:
    """Each number key given as text or a switch (``floor_z_mm = true``, ``port = "502"``),
    and each switch given as a number or text (``check_units = 0``).

    pydantic's lax mode would read ``true`` as 1 and ``"85"`` as 85: a typed value the
    user did not write (a table plane at 1 mm); ``0`` as false (the units check off) and
    ``1`` or ``"yes"`` as true (a held part released). Said as ``section.key``, as the rest.
    """
    problems = []
    for section, values in data.items():
        field = PickPlaceConfig.model_fields.get(section)
        model = None if field is None else field.annotation
        if not isinstance(values, dict) or not isinstance(model, type):
            continue  # an unknown section or a section that is not a table: pydantic says
        for key, value in values.items():
            sub = getattr(model, "model_fields", {}).get(key)
            if sub is None:
                continue
            kinds = {  # float, float | None, Annotated[float, ...] | None: the types named
                get_args(a)[0] if get_origin(a) is Annotated else a
                for a in get_args(sub.annotation) or (sub.annotation,)
            }
            if kinds == {bool} and not isinstance(value, bool):
                problems.append(
                    f"{section}.{key}: must be true or false, got {json.dumps(value, default=str)}"
                )
            elif kinds & {int, float} and not kinds & {bool, str} and isinstance(value, bool | str):
                problems.append(f"{section}.{key}: must be a number, got {json.dumps(value)}")
    return problems


def check_pose_units(config: PickPlaceConfig, source: str) -> None:
    """Refuse a pose that looks like metres or radians, unless ``[poses] check_units = false``.

    Raises:
        ConfigError: naming the key and quoting its values as written.
    """
    if not config.poses.check_units:
        return
    given: list[tuple[str, tuple[float, ...] | None]] = [
        ("robot.tool", config.robot.tool),
        *((f"poses.{name}", getattr(config.poses, name)) for name in _POSE_KEYS),
        ("on_error.pose", config.on_error.pose),
    ]
    for where, values in given:
        if values is not None:
            problem = units_problem(where, values, "[poses] check_units = false")
            if problem is not None:
                raise ConfigError(f"{source}: {problem}")


_POSE_KEYS = ("approach", "pick", "lift", "place", "home")


def read_config_data(path: str | Path) -> dict[str, Any]:
    """Read a TOML file into a mapping; unreadable or malformed files raise ConfigError.

    Args:
        path: The file.

    Returns:
        The parsed document.

    Raises:
        ConfigError: The file is unreadable, too large, not UTF-8 or not TOML tmmaster
            reads (``tmmaster._toml.read_toml``); the message names the file.
    """
    return read_toml(path)


def load_config(
    path: str | Path | None = None, *, overrides: Mapping[str, Mapping[str, Any]] | None = None
) -> PickPlaceConfig:
    """Load and validate a config file (None = the article's defaults) with overrides.

    The file must be valid on its own; the overrides (the command line's options) are
    applied to it and the result validated again; the profiles it names are loaded.

    Example:
        ```python
        from tmmaster.pickplace import load_config

        config = load_config(overrides={"robot": {"host": "127.0.0.1", "port": 5020}})
        print(config.robot.host, config.poses.resolved()["pick"])
        ```

    Args:
        path: A TOML file; None: the defaults.
        overrides: Keys to replace, by section: ``{"robot": {"port": 5020}}``.

    Returns:
        The configuration (its profiles loaded).

    Raises:
        ConfigError: An unreadable file, a bad key or value, or a profile that cannot
            be loaded; the message names the key and the file.
    """
    data: dict[str, Any] = {} if path is None else read_config_data(path)
    source = "<defaults>" if path is None else str(path)
    if path is not None:
        # The file must be valid on its own: a command-line option that overrides a
        # key must not hide that key's bad value in the file.
        validate_config(data, source=source)
    if overrides:
        host = overrides.get("robot", {}).get("host")
        if host is not None:  # said as the option it came from, before anything else
            check_host(host, field="--host", port_field="--port")
        for section, values in overrides.items():
            current = data.get(section, {})
            if not isinstance(current, dict):
                break  # the file's own error is reported by validation below
            data[section] = {**current, **values}
        source += " (with command-line overrides)"
    config = validate_config(data, source=source)
    check_profiles(config, source)
    return config


def check_held_input(profile: RobotProfile, module: str, channel: int, key: str) -> None:
    """Refuse a held input the robot's profile has not, naming the setting (``key``).

    Raises:
        ConfigError: ``channel`` is not a DI of ``module`` in ``profile``.
    """
    try:
        io_address(profile, module, "di", channel)
    except ConfigError as exc:
        raise ConfigError(f"{key} = {channel} ({module}): {exc}") from None


def robot_from_config(
    config: PickPlaceConfig,
    host: str | None = None,
    port: int | None = None,
    *,
    gripper_port: int | None = None,
    settle_scale: float = 1.0,
) -> Robot:
    """A :class:`Robot` set up from the configuration; opens no connection.

    It reaches ``robot.host``:``robot.port`` unless ``host`` / ``port`` name another
    address (a simulator's); the other sections are handed over as they are, the
    robot API's own models (``timeouts``, ``retry``, ``workspace``) included.

    Args:
        config: The configuration.
        host: Another address than ``robot.host`` (None: that one).
        port: Another port than ``robot.port``.
        gripper_port: Another port than ``gripper.port``.
        settle_scale: Divides ``gripper.settle_s`` (a faster simulator; never below
            0.1 s).

    Returns:
        The robot, not connected.

    Raises:
        ConfigError: No robot address, or an invalid one; a ``gripper.held_input`` the
            robot's profile has not.
    """
    target = host if host is not None else config.robot.host
    if target is None:
        raise ConfigError("robot.host: no robot address (set [robot] host, or pass host)")
    g = config.gripper
    # Never below 0.1 s: a scaled settle time must still span a few 50 Hz ticks.
    settle_s = max(g.settle_s / settle_scale, min(g.settle_s, 0.1))
    profile = config.robot_profile()
    if g.held_input is not None:  # one the profile has not: refused before any I/O
        check_held_input(profile, g.held_input_module, g.held_input, "gripper.held_input")
    return Robot(
        target,
        port if port is not None else config.robot.port,
        profile=profile,
        model=config.robot.model,
        gripper=_gripper(config, gripper_port),
        tool=config.robot.tool_pose(),
        polling=PollPolicy(interval_s=config.run.poll_interval_s),
        timeouts=config.timeouts.model_copy(update={"gripper_settle_s": settle_s}),
        retry=config.retry,
        checks=Checks(
            workspace=config.workspace,
            max_speed_percent=config.robot.max_speed,
            position_tolerance_mm=config.robot.position_tolerance_mm,
            # The configuration's poses were checked as written (check_pose_units).
            units=False,
            frame=config.robot.frame_check,
        ),
    )


def _gripper(config: PickPlaceConfig, port: int | None) -> str | GripperDevice:
    """``[gripper]`` as Robot's gripper: "auto" or "none", else a device at its address."""
    g = config.gripper
    if g.kind in ("auto", "none"):
        return g.kind
    loaded = config.gripper_profile()
    return GripperDevice(
        g.kind if loaded is None else loaded,
        host=g.host,
        port=port if port is not None else g.port,
    )
