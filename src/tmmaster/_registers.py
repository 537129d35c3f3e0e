"""Register maps as validated data: fields, maps, robot and gripper profiles.

A field says where a value lives (table, address), how it is encoded (data type,
scale, word order), who may write it and what range it may take. A map groups fields
by role and is validated as a whole: no two fields of one table overlap, nothing runs
past address 65535, and nothing in a read-only table is writable.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterable
from enum import StrEnum
from typing import Annotated, Any, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from ._exceptions import UnknownNameError

#: Registers a data type occupies.
_WIDTHS = {"int16": 1, "uint16": 1, "int32": 2, "uint32": 2, "float32": 2, "bool": 1}

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


class Table(StrEnum):
    """The four Modbus data tables."""

    HOLDING = "holding"
    INPUT = "input"
    COIL = "coil"
    DISCRETE_INPUT = "discrete_input"

    @property
    def read_only(self) -> bool:
        """True for input registers and discrete inputs, which a master cannot write."""
        return self in (Table.INPUT, Table.DISCRETE_INPUT)

    @property
    def is_bit(self) -> bool:
        """True for coils and discrete inputs (one bit per address)."""
        return self in (Table.COIL, Table.DISCRETE_INPUT)


class DataType(StrEnum):
    """How a value is stored in one or two 16-bit registers, or one bit."""

    INT16 = "int16"
    UINT16 = "uint16"
    INT32 = "int32"
    UINT32 = "uint32"
    FLOAT32 = "float32"
    BOOL = "bool"

    @property
    def width(self) -> int:
        """Number of addresses the type occupies."""
        return _WIDTH_OF[self]


#: Width of each data type, keyed by member: no ``.value`` lookup on the hot path.
_WIDTH_OF: dict[DataType, int] = {t: _WIDTHS[t.value] for t in DataType}


class WordOrder(StrEnum):
    """Order of the two registers of a 32-bit value; bytes inside a register are big-endian."""

    BIG = "big"  # high word first ("AB CD"), the Techman and Modbus convention
    LITTLE = "little"  # low word first ("CD AB")


class Access(StrEnum):
    """Who writes a field: the device only (r), the master only (w), or both (rw)."""

    READ = "r"
    WRITE = "w"
    READ_WRITE = "rw"

    @property
    def writable(self) -> bool:
        """True when the master may write the field."""
        return self is not Access.READ


class Role(StrEnum):
    """What a field is for, so that code asks for groups, never for addresses."""

    STATUS = "status"
    POSE = "pose"
    COMMAND = "command"
    FEEDBACK = "feedback"
    GRIPPER = "gripper"
    CONTROL = "control"
    INFO = "info"


class RegisterField(BaseModel):
    """One value in a device's register map."""

    model_config = ConfigDict(
        frozen=True, extra="forbid", populate_by_name=True, allow_inf_nan=False
    )

    #: The field's name (lower_snake_case), its key in the map.
    name: str
    #: What the field is for.
    role: Role
    #: The Modbus table it lives in.
    table: Table
    #: Its first address in the table, 0-based.
    address: Annotated[int, Field(ge=0, le=65535)]
    #: How its words encode the value (``type`` in a profile file).
    dtype: DataType = Field(alias="type")
    #: register value = engineering value x scale (e.g. 100 for "mm x100 in int16").
    scale: Annotated[float, Field(gt=0)] = 1.0
    #: Word order of a 32-bit value.
    word_order: WordOrder = WordOrder.BIG
    #: Who may write it.
    access: Access = Access.READ
    #: Unit of the engineering value ("mm", "deg", "%"...).
    unit: str = ""
    #: Allowed engineering range; values outside are refused before any I/O.
    minimum: float | None = None
    #: Upper end of the allowed engineering range (None: the type's own limit).
    maximum: float | None = None
    #: Meaning of enumerated values, e.g. {0: "idle", 1: "moving"}.
    values: dict[int, str] = Field(default_factory=dict)
    #: Named bits of a status word, e.g. {"busy": 0, "grip_detected": 1}.
    bits: dict[str, Annotated[int, Field(ge=0, le=15)]] = Field(default_factory=dict)
    #: What the field means, for people.
    description: str = ""

    @model_validator(mode="after")
    def _check(self) -> Self:
        if not _NAME.match(self.name):
            raise ValueError(f"field name {self.name!r} must be lower_snake_case")
        if self.table.is_bit != (self.dtype is DataType.BOOL):
            raise ValueError(
                f"field {self.name}: type {self.dtype.value} does not fit table {self.table.value}"
                " (coils and discrete inputs hold bool, registers hold numbers)"
            )
        if self.address + self.dtype.width - 1 > 65535:
            raise ValueError(
                f"field {self.name}: {self.dtype.value} at {self.address} runs past address 65535"
            )
        if self.table.read_only and self.access.writable:
            raise ValueError(
                f"field {self.name}: access {self.access.value!r} is impossible in the"
                f" read-only {self.table.value} table"
            )
        if self.minimum is not None and self.maximum is not None and self.minimum > self.maximum:
            raise ValueError(f"field {self.name}: minimum {self.minimum} > maximum {self.maximum}")
        if self.bits and self.dtype not in (DataType.UINT16, DataType.INT16):
            raise ValueError(f"field {self.name}: named bits need a 16-bit register")
        return self

    @property
    def width(self) -> int:
        """Number of addresses the field occupies."""
        return _WIDTH_OF[self.dtype]

    @property
    def end(self) -> int:
        """Last address the field occupies."""
        return self.address + _WIDTH_OF[self.dtype] - 1

    def label(self, value: int) -> str:
        """Meaning of an enumerated value, or the number itself.

        Args:
            value: A raw value of the field.

        Returns:
            Its label from ``values``, or the number as text.
        """
        return self.values.get(value, str(value))

    def code_of(self, label: str) -> int:
        """The raw value whose meaning is ``label`` (inverse of :meth:`label`).

        Args:
            label: A label of ``values``.

        Returns:
            Its raw value.

        Raises:
            RegisterMapError: No value has that label (the message lists the labels).
        """
        for code, meaning in self.values.items():
            if meaning == label:
                return code
        choices = ", ".join(repr(v) for v in self.values.values()) or "none defined"
        raise UnknownNameError(f"field {self.name} has no value labelled {label!r} ({choices})")

    def bit(self, raw: int, name: str) -> bool:
        """True when the named bit is set in ``raw``.

        Args:
            raw: The register's raw word.
            name: A bit name of ``bits``.

        Returns:
            Whether the bit is set.
        """
        return bool(raw >> self.bits[name] & 1)


class RegisterMap(BaseModel):
    """A validated set of fields served by one Modbus device."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: The map's name (a built-in profile's name, or the file's).
    name: str
    #: What the map is, for people.
    description: str = ""
    #: Modbus unit id ("slave id") of the device.
    device_id: Annotated[int, Field(ge=0, le=255)] = 1
    #: A read may span this many unused addresses to fetch two blocks in one request.
    max_read_gap: Annotated[int, Field(ge=0, le=100)] = 0
    #: Every field, by name.
    fields: dict[str, RegisterField]

    @model_validator(mode="before")
    @classmethod
    def _names_from_keys(cls, data: Any) -> Any:
        if isinstance(data, dict) and isinstance(data.get("fields"), dict):
            fields = {
                key: {"name": key, **spec} if isinstance(spec, dict) else spec
                for key, spec in data["fields"].items()
            }
            data = {**data, "fields": fields}
        return data

    @model_validator(mode="after")
    def _check_layout(self) -> Self:
        for key, field in self.fields.items():
            if key != field.name:
                raise ValueError(f"field key {key!r} differs from its name {field.name!r}")
        for table in Table:
            ordered = sorted(
                (f for f in self.fields.values() if f.table is table), key=lambda f: f.address
            )
            for before, after in itertools.pairwise(ordered):
                if after.address <= before.end:
                    raise ValueError(
                        f"fields {before.name} ({before.address}..{before.end}) and"
                        f" {after.name} ({after.address}..{after.end}) overlap in the"
                        f" {table.value} table"
                    )
        return self

    def field(self, name: str) -> RegisterField:
        """The field called ``name``.

        Args:
            name: A field name.

        Returns:
            The field.

        Raises:
            RegisterMapError: The map has no such field (the message lists them).
        """
        try:
            return self.fields[name]
        except KeyError:
            raise UnknownNameError(
                f"register map {self.name!r} has no field {name!r}"
                f" (fields: {', '.join(sorted(self.fields))})"
            ) from None

    def has(self, name: str) -> bool:
        """True when the map defines a field called ``name``.

        Args:
            name: A field name.

        Returns:
            Whether the map has it.
        """
        return name in self.fields

    def role(self, role: Role) -> tuple[RegisterField, ...]:
        """Fields with this role, in table and address order.

        Args:
            role: The role to look for.

        Returns:
            The fields, possibly none.
        """
        return tuple(
            sorted(
                (f for f in self.fields.values() if f.role is role),
                key=lambda f: (f.table.value, f.address),
            )
        )

    def select(self, names: Iterable[str]) -> tuple[RegisterField, ...]:
        """The named fields, in the order given.

        Args:
            names: Field names.

        Returns:
            The fields.

        Raises:
            RegisterMapError: A name the map does not define.
        """
        return tuple(self.field(n) for n in names)

    def published(self, names: Iterable[str]) -> tuple[RegisterField, ...]:
        """The named fields where the map defines every one of them, else none.

        Args:
            names: Field names (a group that is published whole or not at all).

        Returns:
            The fields, in the order given, or ``()``.
        """
        return self.select(names) if all(self.has(n) for n in names) else ()


class Handshake(StrEnum):
    """How a robot profile tells the master that a command was taken and finished."""

    #: The article's contract: the slave sets motion status to moving, then clears the
    #: command register; done is "acknowledged, then motion status idle".
    CLEAR_ON_ACCEPT = "clear-on-accept"
    #: The tmflow contract: the master increments a sequence number; the robot program
    #: echoes it into ack_seq when it takes the command and into done_seq when finished.
    SEQUENCE = "sequence"


_POSE_NAMES = ("x", "y", "z", "rx", "ry", "rz")
TARGET_FIELDS = tuple(f"target_{n}" for n in _POSE_NAMES)
TCP_FIELDS = tuple(f"tcp_{n}" for n in _POSE_NAMES)
#: Optional fields (Techman's table, 7001-7024 and 7049-7060): the flange pose in the
#: current base, the joints J1..J6 in degrees, the TCP pose in the robot base.
FLANGE_FIELDS = tuple(f"flange_{n}" for n in _POSE_NAMES)
JOINT_FIELDS = tuple(f"joint_{i}" for i in range(1, 7))
#: The command block's optional extension (tmflow): a circle's via point, a TCP speed in
#: mm/s, and the number of the command they belong to.
VIA_FIELDS = tuple(f"via_{n}" for n in _POSE_NAMES)
EXTENSION_FIELDS = (*VIA_FIELDS, "speed_mm_s", "ext_seq")
#: The session of the master that wrote a command (tmflow): after the extension, so that
#: every command writes the whole block.
SESSION_FIELD = "command_session"
#: The program's start the master read (tmflow, ``boot_id``), after the session.
BOOT_FIELD = "command_boot"
ROBOT_BASE_TCP_FIELDS = tuple(f"robot_base_tcp_{n}" for n in _POSE_NAMES)
ROBOT_BASE_FLANGE_FIELDS = tuple(f"robot_base_flange_{n}" for n in _POSE_NAMES)

#: TMflow's user define area, holding registers a project may read and write (TMflow 2.24
#: Software Manual, appendix C, "User Define Area", p. 319): where a sequence profile's
#: feedback lives.
USER_AREA = (9000, 9999)

#: Optional fields that belong to the command block when a profile has them.
_OPTIONAL_BLOCK = ("accel_time", *EXTENSION_FIELDS, SESSION_FIELD, BOOT_FIELD)
#: Command labels that make the robot act; none may share the "none" code.
_ACTION_LABELS = frozenset(
    {"ptp", "line", "stop", "gripper_open", "gripper_close", "ptp_joints", "circle"}
)

_REQUIRED: dict[Handshake, tuple[str, ...]] = {
    Handshake.CLEAR_ON_ACCEPT: (
        *TCP_FIELDS,
        *TARGET_FIELDS,
        "robot_mode",
        "motion_status",
        "error_code",
        "speed",
        "command",
    ),
    Handshake.SEQUENCE: (
        *TCP_FIELDS,
        *TARGET_FIELDS,
        "error",
        "project_running",
        "estop",
        "last_error_code",
        "speed",
        "command",
        "seq",
        "ack_seq",
        "done_seq",
        "robot_state",
        "result_code",
    ),
}


class DigitalIOModule(BaseModel):
    """One module's digital outputs (coils) and inputs (discrete inputs), numbered from 0.

    DO ``n`` is the coil at ``do_address + n`` (read FC 01, written FC 05), DI ``n`` the
    discrete input at ``di_address + n`` (read FC 02). A profile lists its modules under
    ``[digital_io.NAME]``; ``Robot.io`` reads and writes them (docs/robot-api.md).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: The coil of DO 0.
    do_address: Annotated[int, Field(ge=0, le=65535)] = 0
    #: How many DOs the module has (0: none).
    do_count: Annotated[int, Field(ge=0, le=2000)] = 0
    #: The discrete input of DI 0.
    di_address: Annotated[int, Field(ge=0, le=65535)] = 0
    #: How many DIs the module has (0: none).
    di_count: Annotated[int, Field(ge=0, le=2000)] = 0
    #: Where the addresses come from (a manual's section and page), for people.
    source: str = ""

    @model_validator(mode="after")
    def _check_span(self) -> Self:
        for table, address, count in self.spans():
            if address + count > 65536:
                kind = "do" if table is Table.COIL else "di"
                raise ValueError(f"{kind}_address + {kind}_count runs past address 65535")
        if not self.spans():
            raise ValueError("a digital I/O module needs do_count or di_count above 0")
        return self

    def spans(self) -> tuple[tuple[Table, int, int], ...]:
        """The module's addresses as ``(table, first address, count)``, DOs then DIs.

        Returns:
            One entry per non-empty kind: ``(Table.COIL, do_address, do_count)`` and
            ``(Table.DISCRETE_INPUT, di_address, di_count)``.
        """
        out = []
        if self.do_count:
            out.append((Table.COIL, self.do_address, self.do_count))
        if self.di_count:
            out.append((Table.DISCRETE_INPUT, self.di_address, self.di_count))
        return tuple(out)


class RobotProfile(RegisterMap):
    """A robot's register map plus the handshake that its command block follows."""

    #: Always "robot" (a profile file's ``kind``).
    kind: Literal["robot"] = "robot"
    #: How the robot acknowledges and finishes a command.
    handshake: Handshake
    #: Value of ``robot_mode`` (clear-on-accept profiles) that means ready.
    mode_auto: int = 5
    #: Value of ``robot_mode`` (clear-on-accept profiles) that means error.
    mode_error: int = 7
    #: The robot's digital I/O modules by name (``control_box``, ``end_module`` on a TM
    #: robot); none: the robot has no digital I/O the master may reach.
    digital_io: dict[str, DigitalIOModule] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _check_digital_io(self) -> Self:
        # A module's address is nothing else's: not another module's, not a field's.
        owners: dict[tuple[Table, int], str] = {}
        for field in self.fields.values():
            for address in range(field.address, field.end + 1):
                owners[(field.table, address)] = f"field {field.name}"
        for name, module in sorted(self.digital_io.items()):
            if not _NAME.match(name):
                raise ValueError(
                    f"profile {self.name!r}: digital I/O module name {name!r} must be"
                    " lower-case letters, digits and underscores"
                )
            for table, first, count in module.spans():
                for address in range(first, first + count):
                    other = owners.setdefault((table, address), f"digital I/O module {name}")
                    if other != f"digital I/O module {name}":
                        raise ValueError(
                            f"profile {self.name!r}: digital I/O module {name}"
                            f" ({table.value} {address}) overlaps {other}"
                        )
        return self

    @model_validator(mode="after")
    def _check_roles(self) -> Self:
        if missing := [n for n in _REQUIRED[self.handshake] if n not in self.fields]:
            raise ValueError(
                f"profile {self.name!r} ({self.handshake.value} handshake) lacks fields: "
                + ", ".join(missing)
            )
        command = self.fields["command"]
        for label in ("ptp", "line"):
            if label not in command.values.values():
                raise ValueError(f"profile {self.name!r}: field command needs a value {label!r}")
        writable = {*TARGET_FIELDS, "speed", "command"}
        if self.handshake is Handshake.SEQUENCE:
            writable.add("seq")
        for name in sorted(writable):
            if not self.fields[name].access.writable:
                raise ValueError(f"profile {self.name!r}: field {name} must be writable")
        self._check_command_codes()
        self._check_command_block()
        if self.handshake is Handshake.SEQUENCE:
            self._check_feedback_area()
        return self

    @property
    def seq_max(self) -> int:
        """Largest sequence number (sequence handshake): the ``seq`` field's maximum.

        Without a declared maximum, 32767: what TMflow's ``modbus_read_int16`` reads as a
        positive number (docs/tmflow-program.md).
        """
        top = self.fields["seq"].maximum if "seq" in self.fields else None
        return int(top) if top is not None else 2**15 - 1

    def next_seq(self, seq: int) -> int:
        """The sequence number after ``seq``: 1, 2, ... ``seq_max``, then 1 again; never 0.

        Args:
            seq: The last sequence number (0 before the first).

        Returns:
            The next one.
        """
        return seq % self.seq_max + 1

    def command_block(self) -> tuple[RegisterField, ...]:
        """Fields of the command block (targets, speed, accel_time, command, seq...), by address.

        Where the profile has them, the extension's fields (``via_*``, ``speed_mm_s``,
        ``ext_seq``) and ``command_session`` follow ``seq``.

        Returns:
            The fields, contiguous in one table: written in one request.
        """
        names = [*TARGET_FIELDS, "speed", *_OPTIONAL_BLOCK, "command", "seq"]
        return tuple(
            sorted((self.fields[n] for n in names if n in self.fields), key=lambda f: f.address)
        )

    def _check_feedback_area(self) -> None:
        # A maximum of 1: the block the program just ran is numbered ack_seq % 1 + 1 still,
        # and it would run it again, for ever (0: no number at all).
        if self.seq_max < 2:
            raise ValueError(f"profile {self.name!r}: field seq needs a maximum of 2 or more")
        # The robot program reads ack_seq and done_seq in one request (two registers),
        # and it can write only TMflow's user define area: holding registers 9000-9999
        # (TMflow 2.24 Software Manual, appendix C, "User Define Area", p. 319).
        ack, done = self.fields["ack_seq"], self.fields["done_seq"]
        pair = (done.table, done.address, ack.dtype.width, done.dtype.width)
        if pair != (ack.table, ack.address + 1, 1, 1):
            raise ValueError(
                f"profile {self.name!r}: field done_seq ({done.table.value} {done.address})"
                f" must be the one-register field right after ack_seq ({ack.table.value}"
                f" {ack.address}): the robot program reads both in one request"
            )
        written = [*self.role(Role.FEEDBACK)]
        if "grasp_status" in self.fields:  # written by the program's gripper function
            written.append(self.fields["grasp_status"])
        for field in written:
            if field.table is not Table.HOLDING or not (
                USER_AREA[0] <= field.address and field.end <= USER_AREA[1]
            ):
                raise ValueError(
                    f"profile {self.name!r}: feedback field {field.name} ({field.table.value}"
                    f" {field.address}) must lie in the holding registers"
                    f" {USER_AREA[0]}-{USER_AREA[1]}, TMflow's user define area, which the"
                    " robot program writes"
                )

    def _check_command_codes(self) -> None:
        # A command code equal to "none" (or to 0, what a withdraw writes) would be
        # indistinguishable from "no command": refuse it.
        command = self.fields["command"]
        none_codes = {0} | {c for c, label in command.values.items() if label == "none"}
        for code, label in sorted(command.values.items()):
            if label in _ACTION_LABELS and code in none_codes:
                raise ValueError(
                    f"profile {self.name!r}: field command: code {code} of {label!r} collides"
                    " with the 'none' value (0 / label 'none'); give it a non-zero code"
                )

    def _check_command_block(self) -> None:
        # One block in one table, no gaps: the whole command goes out as one FC16
        # request, so the robot can never see the trigger before the target.
        block = self.command_block()
        names = ", ".join(f"{f.name} ({f.table.value} {f.address})" for f in block)
        tables = {f.table for f in block}
        gaps = [
            f"{a.name}..{b.name}" for a, b in itertools.pairwise(block) if b.address != a.end + 1
        ]
        if len(tables) > 1 or gaps:
            why = "spans several tables" if len(tables) > 1 else "has gaps at " + ", ".join(gaps)
            raise ValueError(
                f"profile {self.name!r}: the command block must be one contiguous run of"
                f" addresses in one table so that it is written in one request; it {why}:"
                f" {names}"
            )
        size = block[-1].end - block[0].address + 1
        if size > 123:  # one FC16 request (Modbus application protocol spec, 6.12)
            raise ValueError(
                f"profile {self.name!r}: the command block spans {size} registers;"
                " one write request holds at most 123"
            )


#: Unit ids of an OnRobot Compute Box: single gripper, Dual Quick Changer primary, secondary.
ONROBOT_UNIT_IDS = (65, 66, 67)


#: The gripper protocols a :class:`GripperProfile` may name: each has exactly one driver
#: (``tmmaster._gripper.GRIPPER_DRIVERS``) and one simulated device
#: (``tmmaster.sim._grippers.GRIPPER_DEVICES``), both keyed by these names.
GripperDriverName = Literal["blog-2fg7", "onrobot-2fg7"]


class GripperProfile(RegisterMap):
    """A gripper's register map; ``driver`` names the protocol spoken over it."""

    #: Always "gripper" (a profile file's ``kind``).
    kind: Literal["gripper"] = "gripper"
    #: The protocol spoken over the map: ``"blog-2fg7"`` or ``"onrobot-2fg7"``.
    driver: GripperDriverName
    #: At most this many TCP connections at once (the OnRobot Compute Box allows one).
    max_connections: Annotated[int, Field(ge=1)] | None = None

    @model_validator(mode="after")
    def _check_unit_id(self) -> Self:
        # The Compute Box answers 65 for a single gripper, 66 / 67 for the primary /
        # secondary gripper on a Dual Quick Changer; any other id is never answered.
        if self.driver == "onrobot-2fg7" and self.device_id not in ONROBOT_UNIT_IDS:
            raise ValueError(
                f"profile {self.name!r}: an OnRobot Compute Box answers unit id 65, 66 or 67,"
                f" not {self.device_id}"
            )
        return self

    @property
    def own_unit_id_only(self) -> bool:
        """True when the device answers its own unit id only (the OnRobot Compute Box)."""
        return self.driver == "onrobot-2fg7"
