"""The robot-side program of a sequence-handshake profile, as a TMflow Script Project.

One artifact: the text :func:`robot_program` returns is what a user loads into TMflow
(``tmmaster robot-program -o tmmaster.tms``) and what the simulator executes through
:mod:`tmmaster.tmscript`. The template (``robot_program.tms``, beside this module, with
the gripper's ``Grip()`` in ``robot_program_grip_io.tms`` or ``robot_program_grip_none.tms``)
cites the TMscript 2.24 section of every construct it uses; this module only fills in the
profile's addresses and codes, the tool and the gripper wiring, after checking that the
profile is one the program can serve.
"""

from __future__ import annotations

import argparse
import math
import re
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from string import Template

from ._exceptions import ConfigError
from ._io import END_MODULE_DI, END_MODULE_DO, GripperWiring
from ._logging import add_logging_arguments
from ._pose import Pose
from ._registers import (
    BOOT_FIELD,
    EXTENSION_FIELDS,
    SESSION_FIELD,
    TARGET_FIELDS,
    VIA_FIELDS,
    DataType,
    Handshake,
    RobotProfile,
    Table,
    WordOrder,
)
from ._version import version

#: The feedback and command fields the program reads or writes, by name.
_FEEDBACK = (
    "ack_seq",
    "done_seq",
    "robot_state",
    "result_code",
    "heartbeat",
    "grasp_status",
    "ack_session",
    "boot_id",
)
_WORDS = ("speed", "accel_time", "command", "seq")
#: The block's end: the extension, then the master's session and the program's start.
_BLOCK_END = (*EXTENSION_FIELDS, SESSION_FIELD, BOOT_FIELD)
#: The master's heartbeat, its time-to-live and its session, read together.
_MASTER = ("master_heartbeat", "master_ttl_ms", "master_session")
#: The read/write timeout of the program's Modbus device, ms (TMscript 2.24 §16.1,
#: p. 414: 0..10000, 10000 by default): well inside the 12 s closestop and errorstop get.
MODBUS_TIMEOUT_MS = 1000


#: The largest tool values the program writes, by field: a TCP within 2 m of the flange
#: (the profile's target range), angles within one turn, a tool up to 100 kg, principal
#: moments of inertia up to 1e8 kg mm^2 (100 kg m^2). Each is written as a float literal
#: with six decimals at most, never an integer (TMscript's int is 32-bit, [TS] 2.2).
TOOL_POSITION_MAX_MM = 2000.0
TOOL_ANGLE_MAX_DEG = 360.0
TOOL_MASS_MAX_KG = 100.0
TOOL_INERTIA_MAX = 1e8
_TCP_NAMES = ("x", "y", "z", "rx", "ry", "rz")
#: ChangeTCP's inertia array (TMscript 2.24 §13.6 syntax 4, pp. 327-328): principal
#: moments Ixx, Iyy, Izz, then the mass centre frame X, Y, Z, RX, RY, RZ.
INERTIA_NAMES = ("ixx", "iyy", "izz", "cx", "cy", "cz", "crx", "cry", "crz")
#: A tool name as TMflow's Tool Settings shows it, written into a string literal.
_TOOL_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_\-]{0,63}$")


#: The range of each TCP value (X, Y, Z, RX, RY, RZ) and of each inertia value (the
#: moments, then the mass centre frame, which is bounded as a TCP).
_POSITION = (-TOOL_POSITION_MAX_MM, TOOL_POSITION_MAX_MM)
_ANGLE = (-TOOL_ANGLE_MAX_DEG, TOOL_ANGLE_MAX_DEG)
_TCP_BOUNDS = (_POSITION, _POSITION, _POSITION, _ANGLE, _ANGLE, _ANGLE)
_INERTIA_BOUNDS = ((0.0, TOOL_INERTIA_MAX),) * 3 + _TCP_BOUNDS


def _literals(
    what: str, names: Sequence[str], values: Sequence[float], bounds: Sequence[tuple[float, float]]
) -> str:
    """``values`` as TMscript float literals, comma-separated, each checked in its bounds."""
    return ", ".join(
        _float_literal(f"{what} {name}", value, *bound)
        for name, value, bound in zip(names, values, bounds, strict=True)
    )


def _float_literal(field: str, value: float, low: float, high: float) -> str:
    """``value`` as a TMscript float literal: checked in ``low..high``, six decimals at most.

    Raises:
        ConfigError: Not a finite number in range (the message names ``field``).
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{field} must be a number, got {value!r}")
    if not math.isfinite(value) or not low <= value <= high:
        raise ConfigError(f"{field} must be a finite number in {low:g}..{high:g}, got {value!r}")
    text = f"{float(value):.6f}".rstrip("0")
    text = text + "0" if text.endswith(".") else text
    return "0.0" if float(text) == 0 else text


@dataclass(frozen=True)
class ToolSetting:
    """The TCP the program sets when it starts: a TMflow tool by name, or values with mass.

    ``name``: a tool defined in TMflow's Tool Settings with its mass and inertia (TMflow
    2.24 Software Manual, §8 "Create the TCP", pp. 156-157); the program calls
    ``ChangeTCP("name")`` (TMscript 2.24 §13.6 syntax 1, p. 327). Otherwise ``tcp`` (X,
    Y, Z, RX, RY, RZ of the TCP in the flange frame, mm and degrees) and ``mass_kg``,
    required (a tool is never weightless by default): ``ChangeTCP(tool, mass)`` (syntax
    3, p. 327), or with ``inertia`` (Ixx, Iyy, Izz in kg mm^2, then the mass centre frame
    X, Y, Z in mm and RX, RY, RZ in degrees, w.r.t. the flange)
    ``ChangeTCP(tool, mass, inertia)`` (syntax 4, pp. 327-328). ``mass_kg=0`` is a
    deliberate choice (a bare flange), never a default.

    Raises:
        ConfigError: Neither or both ways, a missing mass, a value out of range (the
            message names it), a name TMflow would not show.
    """

    name: str | None = None
    tcp: Pose | None = None
    mass_kg: float | None = None
    inertia: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.name is not None:
            if self.tcp is not None or self.mass_kg is not None or self.inertia is not None:
                raise ConfigError(
                    "tool: give a TMflow tool name or values with mass, not both (the named"
                    " tool carries its own mass and inertia)"
                )
            if not isinstance(self.name, str) or not _TOOL_NAME.match(self.name):
                raise ConfigError(
                    "tool name must be 1-64 letters, digits, '_' or '-' as TMflow shows it,"
                    f" got {self.name!r}"
                )
            return
        if self.tcp is None:
            raise ConfigError("tool: give a TMflow tool name, or the TCP values and mass_kg")
        if self.mass_kg is None:
            raise ConfigError(
                "tool mass_kg is required with the TCP values: TMflow needs the tool's mass"
                " (0 only for a bare flange, given on purpose)"
            )
        if self.inertia is not None and len(self.inertia) != len(INERTIA_NAMES):
            raise ConfigError(
                f"tool inertia needs {len(INERTIA_NAMES)} values"
                f" ({', '.join(INERTIA_NAMES)}), got {len(self.inertia)}"
            )
        self.statements()  # every value checked now, naming the one out of range

    def statements(self) -> tuple[str, str]:
        """The program's declarations (``define``) and its ChangeTCP call (``main``).

        Returns:
            ``(declarations, call)``, TMscript source lines without indentation.
        """
        if self.name is not None:
            return f"// The tool: {self.name}, as defined in TMflow", f'ChangeTCP("{self.name}")'
        assert self.tcp is not None
        assert self.mass_kg is not None
        values = _literals("tool", _TCP_NAMES, self.tcp.as_list(), _TCP_BOUNDS)
        mass = _float_literal("tool mass_kg", self.mass_kg, 0.0, TOOL_MASS_MAX_KG)
        declarations = f"float[] tool = {{{values}}}"
        if self.inertia is None:
            return declarations, f"ChangeTCP(tool, {mass})"
        inertia = _literals("tool inertia", INERTIA_NAMES, self.inertia, _INERTIA_BOUNDS)
        declarations += f"\n    float[] inertia = {{{inertia}}}"
        return declarations, f"ChangeTCP(tool, {mass}, inertia)"


def check_program_profile(profile: RobotProfile) -> None:
    """Refuse a profile the Script Project cannot serve (:class:`ConfigError` naming why).

    Args:
        profile: the robot profile the program is for.

    Raises:
        ConfigError: not a sequence-handshake profile, a field missing, the target not
            six big-endian float32 registers followed by speed, accel, command and seq
            and the extension (via as six float32, speed_mm_s, ext_seq), or a feedback
            field outside the holding registers.
    """
    if profile.handshake is not Handshake.SEQUENCE:
        raise ConfigError(
            f"profile {profile.name!r} uses the {profile.handshake.value} handshake: the robot"
            " program implements the sequence handshake (the tmflow contract)"
        )
    missing = [
        name
        for name in (*TARGET_FIELDS, *_WORDS, *_BLOCK_END, *_FEEDBACK, *_MASTER)
        if not profile.has(name)
    ]
    if missing:
        raise ConfigError(f"profile {profile.name!r} lacks the fields {', '.join(missing)}")
    _check_command_block(profile)
    for name in _FEEDBACK:
        if profile.field(name).table is not Table.HOLDING:
            raise ConfigError(f"profile {profile.name!r}: {name} must be a holding register")
    _check_heartbeat(profile)


def _check_command_block(profile: RobotProfile) -> None:
    """The target, via and words where the program reads them (ConfigError if not)."""
    first = profile.field(TARGET_FIELDS[0]).address
    floats = [(name, first + 2 * i) for i, name in enumerate(TARGET_FIELDS)]
    floats += [(name, first + 16 + 2 * i) for i, name in enumerate(VIA_FIELDS)]
    for name, address in floats:
        field = profile.field(name)
        if (
            field.table is not Table.HOLDING
            or field.dtype is not DataType.FLOAT32
            or field.word_order is not WordOrder.BIG
            or field.address != address
        ):
            raise ConfigError(
                f"profile {profile.name!r}: {name} must be a big-endian float32 holding"
                f" register at {address} for the robot program"
            )
    words = [(name, first + 12 + i) for i, name in enumerate(_WORDS)]
    words += [(name, first + 28 + i) for i, name in enumerate(_BLOCK_END[6:])]
    for name, address in words:
        field = profile.field(name)
        if field.table is not Table.HOLDING or field.address != address:
            raise ConfigError(
                f"profile {profile.name!r}: {name} must be the holding register at"
                f" {address} for the robot program"
            )


def _check_heartbeat(profile: RobotProfile) -> None:
    """master_heartbeat, master_ttl_ms and master_session as one FC16 request
    (ConfigError if not)."""
    fields = [profile.field(name) for name in _MASTER]
    first = fields[0].address
    if not all(
        f.table is Table.HOLDING and f.dtype.width == 1 and f.address == first + i
        for i, f in enumerate(fields)
    ):
        raise ConfigError(
            f"profile {profile.name!r}: master_ttl_ms and master_session must be the holding"
            f" registers right after master_heartbeat ({first}) for the robot program"
        )


#: The template's names for the codes of the handshake's fields: name -> (field, label).
_CODES = {
    "cmd_none": ("command", "none"),
    "cmd_ptp": ("command", "ptp"),
    "cmd_line": ("command", "line"),
    "cmd_joints": ("command", "ptp_joints"),
    "cmd_circle": ("command", "circle"),
    "cmd_open": ("command", "gripper_open"),
    "cmd_close": ("command", "gripper_close"),
    "state_idle": ("robot_state", "idle"),
    "state_busy": ("robot_state", "busy"),
    "state_error": ("robot_state", "error"),
    "result_ok": ("result_code", "ok"),
    "unreachable": ("result_code", "unreachable"),
    "invalid_command": ("result_code", "invalid_command"),
    "motion_failed": ("result_code", "motion_failed"),
    "gripper_failed": ("result_code", "gripper_failed"),
    "cancelled": ("result_code", "cancelled"),
    "another_master": ("result_code", "another_master"),
}


def _template(name: str) -> Template:
    """A TMscript template beside this module (its last newline left to the caller)."""
    return Template(resources.files("tmmaster").joinpath(name).read_text("utf-8").rstrip("\n"))


def robot_program(
    profile: RobotProfile,
    *,
    tool: ToolSetting,
    gripper: GripperWiring | None = None,
    arguments: str = "",
) -> str:
    """The TMflow Script Project that implements ``profile``'s contract on the robot.

    Args:
        profile: a sequence-handshake robot profile (``tmflow`` or one extending it).
        tool: the TCP the program sets, with its mass: a TMflow tool by name, or the
            values the master plans with (mm, deg) and the mass (:class:`ToolSetting`).
        gripper: how the program drives the gripper (end-module I/O by default).
        arguments: the command line that made it, quoted in the program's header.

    Returns:
        The program's text (TMscript 2.24), ending with a newline.

    Raises:
        ConfigError: a profile the program cannot serve, a tool that is not a
            ToolSetting, or a bad gripper.
    """
    check_program_profile(profile)
    if not isinstance(tool, ToolSetting):
        raise ConfigError(
            "robot_program: tool must be a ToolSetting (a TMflow tool name, or the TCP"
            f" values with mass_kg), got {tool!r}"
        )
    wiring = gripper if gripper is not None else GripperWiring()
    tool_define, tool_change = tool.statements()
    # The codes the program compares and writes, by the template's names.
    codes = {name: profile.field(field).code_of(label) for name, (field, label) in _CODES.items()}
    first = profile.field(TARGET_FIELDS[0]).address
    addresses = {name: profile.field(name).address for name in (*_FEEDBACK, *_MASTER, "command")}
    grip = _template(f"robot_program_grip_{wiring.kind}.tms").substitute(
        output=wiring.output,
        input=wiring.input,
        do_address=END_MODULE_DO + wiring.output,
        di_address=END_MODULE_DI + wiring.input,
        settle_ms=wiring.settle_ms,
        **codes,
    )
    text = _template("robot_program.tms").substitute(
        version=version(),
        profile=profile.name,
        arguments=arguments,
        block_first=first,
        block_last=first + 31,
        block_count=32,
        words_offset=24,
        via_offset=32,
        ext_offset=56,
        ext_first=first + 16,
        seq_address=first + 15,
        smm_max=int(profile.field("speed_mm_s").maximum or 2000),
        fb_first=min(addresses[name] for name in _FEEDBACK),
        fb_last=max(addresses[name] for name in _FEEDBACK),
        seq_max=profile.seq_max,
        tool_define=tool_define,
        tool_change=tool_change,
        timeout_ms=MODBUS_TIMEOUT_MS,
        gripper=grip,
        **addresses,
        **codes,
    )
    return text if text.endswith("\n") else text + "\n"


def _tool_argument(text: str) -> Pose:
    """``--tool X,Y,Z,RX,RY,RZ`` as a Pose (argparse type; the error names the problem)."""
    try:
        return Pose.parse(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (got {text!r})") from exc


def _numbers_argument(text: str) -> tuple[float, ...]:
    """Comma-separated numbers (argparse type)."""
    try:
        return tuple(float(part) for part in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"expected numbers separated by commas, got {text!r}"
        ) from exc


def tool_from_arguments(args: argparse.Namespace) -> ToolSetting:
    """The :class:`ToolSetting` of ``--tool-name`` or ``--tool``/``--tool-mass``/``--tool-inertia``.

    Args:
        args: parsed by a parser that :func:`add_arguments` set up.

    Returns:
        The tool setting.

    Raises:
        ConfigError: No tool given, both ways given, no mass, or a value out of range.
    """
    if args.tool_name is None and args.tool is None:
        raise ConfigError(
            "robot-program needs the tool: --tool-name NAME (a tool defined in TMflow, with"
            " its mass), or --tool X,Y,Z,RX,RY,RZ with --tool-mass KG"
        )
    if args.tool_name is not None:
        if args.tool is not None or args.tool_mass is not None or args.tool_inertia is not None:
            raise ConfigError(
                "--tool-name takes the tool's values from TMflow: leave out --tool,"
                " --tool-mass and --tool-inertia"
            )
        return ToolSetting(name=args.tool_name)
    if args.tool_mass is None:
        raise ConfigError("--tool needs --tool-mass KG: TMflow needs the tool's mass")
    return ToolSetting(tcp=args.tool, mass_kg=args.tool_mass, inertia=args.tool_inertia)


def _gripper_argument(text: str) -> GripperWiring:
    """``--gripper none`` or ``io[:do=N,di=N,settle_ms=N]`` as a GripperWiring."""
    kind, _, options = text.partition(":")
    values: dict[str, int] = {}
    for item in filter(None, (o.strip() for o in options.split(","))):
        key, _, value = item.partition("=")
        names = {"do": "output", "di": "input", "settle_ms": "settle_ms"}
        if key not in names or not value.strip().isdigit():
            raise argparse.ArgumentTypeError(f"option {item!r}: expected do=N, di=N or settle_ms=N")
        values[names[key]] = int(value)
    try:
        return GripperWiring(kind, **values)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Mount ``tmmaster robot-program``'s options on ``parser``.

    Args:
        parser: the subcommand's parser.
    """
    parser.add_argument(
        "--profile", default="tmflow", help="a sequence-handshake profile name or .toml file"
    )
    tool = parser.add_argument_group(
        "tool (required: --tool-name, or --tool with --tool-mass)",
        "the TCP the program sets when it starts, with the tool's mass",
    )
    tool.add_argument(
        "--tool-name",
        metavar="NAME",
        help="a tool defined in TMflow (Configuration > Tool Settings) with its mass and"
        " inertia: ChangeTCP(NAME); the simulator knows no tool by name (use --tool there)",
    )
    tool.add_argument(
        "--tool",
        type=_tool_argument,
        metavar="X,Y,Z,RX,RY,RZ",
        help="the TCP in the flange frame (mm, deg), as the master's Robot(tool=...)",
    )
    tool.add_argument(
        "--tool-mass", type=float, metavar="KG", help="the tool's mass in kg (with --tool)"
    )
    tool.add_argument(
        "--tool-inertia",
        type=_numbers_argument,
        metavar="IXX,IYY,IZZ,X,Y,Z,RX,RY,RZ",
        help="principal moments of inertia (kg mm^2) and the mass centre frame w.r.t. the"
        " flange (mm, deg), with --tool",
    )
    parser.add_argument(
        "--gripper",
        type=_gripper_argument,
        default=GripperWiring(),
        metavar="io[:do=N,di=N,settle_ms=N]|none",
        help="end-module I/O gripper (default io:do=0,di=0,settle_ms=500) or none",
    )
    parser.add_argument("--output", "-o", metavar="FILE.tms", help="write to a file instead")
    add_logging_arguments(parser, default_level="warning")


def run(args: argparse.Namespace, argv: Sequence[str] = ()) -> str:
    """The program for parsed ``args`` (the command line ``argv`` quoted in its header).

    Args:
        args: parsed by a parser that :func:`add_arguments` set up.
        argv: the subcommand's own arguments, for the header.

    Returns:
        The program text.

    Raises:
        ConfigError: a profile the program cannot serve, or a tool missing or out of range.
    """
    from ._profiles import robot_profile

    quoted = "".join(f" {shlex.quote(a)}" for a in argv)
    return robot_program(
        robot_profile(args.profile),
        tool=tool_from_arguments(args),
        gripper=args.gripper,
        arguments=quoted,
    )
