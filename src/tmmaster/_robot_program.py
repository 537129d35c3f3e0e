"""The robot-side program of a sequence-handshake profile, as a TMflow Script Project.

One artifact: the text :func:`robot_program` returns is what a user loads into TMflow
(``tmmaster robot-program -o tmmaster.tms``) and what the simulator executes through
:mod:`tmmaster.tmscript`. The template (``robot_program.tms``, beside this module) cites
the TMscript 2.24 section of every construct it uses; this module only fills in the
profile's addresses and codes, the tool and the gripper wiring, after checking that the
profile is one the program can serve.
"""

from __future__ import annotations

import argparse
import math
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from string import Template

from ._exceptions import ConfigError
from ._pose import Pose
from ._registers import (
    EXTENSION_FIELDS,
    TARGET_FIELDS,
    VIA_FIELDS,
    DataType,
    Handshake,
    RobotProfile,
    Table,
    WordOrder,
)
from ._version import version

#: The end module's DO 0 (coil) and DI 0 (discrete input) in Techman's Modbus table.
END_MODULE_DO = 800
END_MODULE_DI = 800

#: The feedback and command fields the program reads or writes, by name.
_FEEDBACK = ("ack_seq", "done_seq", "robot_state", "result_code", "heartbeat", "grasp_status")
_WORDS = ("speed", "accel_time", "command", "seq")


@dataclass(frozen=True)
class GripperWiring:
    """How the program drives the gripper: none, or an end-module output and input.

    ``kind`` "io": end-module digital output ``output`` (0-3) closes the gripper when high
    and opens it when low, the program waits ``settle_ms``, then reads grip detected on
    end-module digital input ``input`` (0-3), both through the robot's own Modbus table
    (coils and discrete inputs 800-803, TMflow 2.24 manual, appendix C, p. 307). ``kind``
    "none": gripper commands are refused with ``gripper_failed``.
    """

    kind: str = "io"
    output: int = 0
    input: int = 0
    settle_ms: int = 500

    def __post_init__(self) -> None:
        if self.kind not in ("io", "none"):
            raise ConfigError(f"gripper must be 'io' or 'none', got {self.kind!r}")
        for name, value, high in (
            ("output", self.output, 3),
            ("input", self.input, 3),
            ("settle_ms", self.settle_ms, 60_000),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= high:
                raise ConfigError(f"gripper {name} must be an integer 0..{high}, got {value!r}")


_GRIP_IO = """// The gripper on the end module, through the robot's own Modbus table ([TMF]
// appendix C, End Module, p. 307: DO 0-3 are coils 800-803, FC 05; DI 0-3 are discrete
// inputs 800-803, FC 02): DO$output closes it when high and opens it when low; after $settle_ms ms
// ([TS] 5.5 Sleep, p. 159) DI$input tells whether a part is held ([TS] 16.11 modbus_write
// Syntax 3, p. 437; 16.5 modbus_read Syntax 2, p. 424). Edit this function for another
// gripper; keep its last two steps (grasp_status, then Done()).
void Grip()
{
    if (cmd == $cmd_close)
    {
        modbus_write("TM", 1, "DO", $do_address, 1)
    }
    else
    {
        modbus_write("TM", 1, "DO", $do_address, 0)
    }
    Sleep($settle_ms)
    grasp = 0
    if (cmd == $cmd_close)
    {
        grasp = modbus_read("TM", 1, "DI", $di_address, 1)[0]
    }
    modbus_write("TM", "fbGrasp", grasp)
    Done()
}"""

_GRIP_NONE = """// No gripper: gripper commands are refused.
void Grip()
{
    Finish($gripper_failed, $state_error)
}"""


def _format_number(value: float) -> str:
    """A number as TMscript source: integers without a fraction, others shortest-exact."""
    if not math.isfinite(value):
        raise ConfigError(f"tool values must be finite, got {value!r}")
    return str(int(value)) if float(value).is_integer() else repr(float(value))


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
        for name in (*TARGET_FIELDS, *_WORDS, *EXTENSION_FIELDS, *_FEEDBACK)
        if not profile.has(name)
    ]
    if missing:
        raise ConfigError(f"profile {profile.name!r} lacks the fields {', '.join(missing)}")
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
    words += [(name, first + 28 + i) for i, name in enumerate(EXTENSION_FIELDS[6:])]
    for name, address in words:
        field = profile.field(name)
        if field.table is not Table.HOLDING or field.address != address:
            raise ConfigError(
                f"profile {profile.name!r}: {name} must be the holding register at"
                f" {address} for the robot program"
            )
    for name in _FEEDBACK:
        if profile.field(name).table is not Table.HOLDING:
            raise ConfigError(f"profile {profile.name!r}: {name} must be a holding register")


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
}


def _value_codes(profile: RobotProfile) -> dict[str, int]:
    """The codes the program compares and writes, by the template's names."""
    return {name: profile.field(field).code_of(label) for name, (field, label) in _CODES.items()}


def robot_program(
    profile: RobotProfile,
    *,
    tool: Pose | None = None,
    gripper: GripperWiring | None = None,
    arguments: str = "",
) -> str:
    """The TMflow Script Project that implements ``profile``'s contract on the robot.

    Args:
        profile: a sequence-handshake robot profile (``tmflow`` or one extending it).
        tool: the TCP in the flange frame the master plans with (mm, deg); None: the
            flange itself.
        gripper: how the program drives the gripper (end-module I/O by default).
        arguments: the command line that made it, quoted in the program's header.

    Returns:
        The program's text (TMscript 2.24), ending with a newline.

    Raises:
        ConfigError: a profile the program cannot serve, or a bad tool or gripper.
    """
    check_program_profile(profile)
    wiring = gripper if gripper is not None else GripperWiring()
    tool_values = (0.0,) * 6 if tool is None else tool.as_list()
    codes = _value_codes(profile)
    first = profile.field(TARGET_FIELDS[0]).address
    addresses = {name: profile.field(name).address for name in (*_FEEDBACK, "command")}
    grip = Template(_GRIP_IO if wiring.kind == "io" else _GRIP_NONE).substitute(
        output=wiring.output,
        input=wiring.input,
        do_address=END_MODULE_DO + wiring.output,
        di_address=END_MODULE_DI + wiring.input,
        settle_ms=wiring.settle_ms,
        **codes,
    )
    template = resources.files("tmmaster").joinpath("robot_program.tms").read_text("utf-8")
    text = Template(template).substitute(
        version=version(),
        profile=profile.name,
        arguments=arguments,
        block_first=first,
        block_last=first + 29,
        block_count=30,
        words_offset=24,
        via_offset=32,
        ext_offset=56,
        ext_first=first + 16,
        seq_address=first + 15,
        smm_max=int(profile.field("speed_mm_s").maximum or 2000),
        fb_first=min(addresses[name] for name in _FEEDBACK),
        fb_last=max(addresses[name] for name in _FEEDBACK),
        seq_max=profile.seq_max,
        tool=", ".join(_format_number(v) for v in tool_values),
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
    parser.add_argument(
        "--tool",
        type=_tool_argument,
        metavar="X,Y,Z,RX,RY,RZ",
        help="the TCP in the flange frame (mm, deg), as the master's Robot(tool=...)",
    )
    parser.add_argument(
        "--gripper",
        type=_gripper_argument,
        default=GripperWiring(),
        metavar="io[:do=N,di=N,settle_ms=N]|none",
        help="end-module I/O gripper (default io:do=0,di=0,settle_ms=500) or none",
    )
    parser.add_argument("--output", "-o", metavar="FILE.tms", help="write to a file instead")


def run(args: argparse.Namespace, argv: Sequence[str] = ()) -> str:
    """The program for parsed ``args`` (the command line ``argv`` quoted in its header).

    Args:
        args: parsed by a parser that :func:`add_arguments` set up.
        argv: the subcommand's own arguments, for the header.

    Returns:
        The program text.

    Raises:
        ConfigError: a profile the program cannot serve.
    """
    from ._profiles import robot_profile

    quoted = "".join(f" {shlex.quote(a)}" for a in argv)
    return robot_program(
        robot_profile(args.profile), tool=args.tool, gripper=args.gripper, arguments=quoted
    )
