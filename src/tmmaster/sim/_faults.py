"""Faults the simulator can inject, as validated data, and the CLI syntax that names them.

Device faults (robot_error, stall, estop, grasp_miss, late_ack) are played by the simulated
controller and grippers in simulated time; their exact effect per profile is described
in ``docs/simulator-model.md``. Network faults (drop_connections, stop_listening,
slow_responses, modbus_exception) are played by the Modbus server in wall time.

On the command line a fault is written ``kind:key=value,key=value``, for example
``robot_error:at_move=3,code=0x1F4`` or ``late_ack:delay_s=0.5``; see :func:`parse_fault`.
"""

from __future__ import annotations

from typing import Annotated, Literal, Self

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    NonNegativeFloat,
    PositiveFloat,
    PositiveInt,
    TypeAdapter,
    ValidationError,
    model_validator,
)

from .._exceptions import ConfigError
from .._registers import Table

#: Default code of an injected robot error (0x1F4 = 500): a stand-in, not a Techman code.
DEFAULT_ROBOT_ERROR_CODE = 0x1F4

#: A robot error code: fits the int32 ``last_error_code`` of the TM table.
ErrorCode = Annotated[int, Field(ge=1, le=2**31 - 1)]


class _FaultBase(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class RobotErrorFault(_FaultBase):
    """The robot goes to error with ``code`` during the ``at_move``-th motion it starts."""

    #: Always ``"robot_error"`` (the fault's name in ``--fault robot_error:...``).
    kind: Literal["robot_error"] = "robot_error"
    #: The motion (1 = the first one started) during which the error comes.
    at_move: PositiveInt
    #: The robot's error code (default 0x1F4: a stand-in, not a Techman code).
    code: ErrorCode = DEFAULT_ROBOT_ERROR_CODE


class StallFault(_FaultBase):
    """The ``at_move``-th motion stops halfway and never completes: the robot stays busy."""

    #: Always ``"stall"`` (the fault's name in ``--fault stall:...``).
    kind: Literal["stall"] = "stall"
    #: The motion (1 = the first one started) that stalls.
    at_move: PositiveInt


class EstopFault(_FaultBase):
    """The emergency stop is pressed during the ``at_move``-th motion or at ``after_s``."""

    #: Always ``"estop"`` (the fault's name in ``--fault estop:...``).
    kind: Literal["estop"] = "estop"
    #: The motion during which the stop is pressed (or ``after_s``).
    at_move: PositiveInt | None = None
    #: Simulated seconds after the simulation started.
    after_s: NonNegativeFloat | None = None

    @model_validator(mode="after")
    def _one_trigger(self) -> Self:
        if (self.at_move is None) == (self.after_s is None):
            raise ValueError("estop needs exactly one of at_move or after_s")
        return self


class GraspMissFault(_FaultBase):
    """The ``at_grasp``-th gripper close detects no object (it slipped)."""

    #: Always ``"grasp_miss"`` (the fault's name in ``--fault grasp_miss:...``).
    kind: Literal["grasp_miss"] = "grasp_miss"
    #: The gripper close (1 = the first) that misses.
    at_grasp: PositiveInt = 1


class LateAckFault(_FaultBase):
    """A command is taken ``delay_s`` simulated seconds late (every command, or move N)."""

    #: Always ``"late_ack"`` (the fault's name in ``--fault late_ack:...``).
    kind: Literal["late_ack"] = "late_ack"
    #: How late a command is taken, simulated seconds.
    delay_s: PositiveFloat
    #: Only the at_move-th motion command; None delays every command (stop excepted).
    at_move: PositiveInt | None = None


class DropConnectionsFault(_FaultBase):
    """The server closes every connection after ``after_requests`` requests (once or each time)."""

    #: Always ``"drop_connections"`` (the fault's name in ``--fault drop_connections:...``).
    kind: Literal["drop_connections"] = "drop_connections"
    #: Drop after this many requests (counted as ``on_write_to`` says).
    after_requests: PositiveInt = 1
    #: Drop once; False: again after each further ``after_requests`` requests.
    once: bool = True
    #: Count only writes touching this address (e.g. a command register) instead of all
    #: requests: the way to break the link exactly while a command is in flight.
    on_write_to: Annotated[int, Field(ge=0, le=65535)] | None = None
    #: What the drop destroys: nothing in flight ("none": the trigger is answered first),
    #: the trigger "request" (never executed), or its "answer" (executed, reply lost).
    lose: Literal["none", "request", "answer"] = "none"


class StopListeningFault(_FaultBase):
    """After ``after_requests`` requests the server closes and refuses connections for a while."""

    #: Always ``"stop_listening"`` (the fault's name in ``--fault stop_listening:...``).
    kind: Literal["stop_listening"] = "stop_listening"
    #: Stop after this many requests.
    after_requests: PositiveInt
    #: Wall-clock seconds without a listening socket.
    duration_s: PositiveFloat


class SlowResponsesFault(_FaultBase):
    """Every response is sent ``delay_s`` wall-clock seconds late."""

    #: Always ``"slow_responses"`` (the fault's name in ``--fault slow_responses:...``).
    kind: Literal["slow_responses"] = "slow_responses"
    #: Delay of every response, wall-clock seconds.
    delay_s: PositiveFloat


class ModbusExceptionFault(_FaultBase):
    """Requests touching ``table`` addresses ``start``..``end`` get exception ``code``."""

    #: Always ``"modbus_exception"`` (the fault's name in ``--fault modbus_exception:...``).
    kind: Literal["modbus_exception"] = "modbus_exception"
    #: The table whose addresses are refused.
    table: Table
    #: First refused address.
    start: Annotated[int, Field(ge=0, le=65535)]
    #: Last refused address.
    end: Annotated[int, Field(ge=0, le=65535)]
    #: The Modbus exception code (2: illegal data address).
    code: Annotated[int, Field(ge=1, le=11)] = 2

    @model_validator(mode="after")
    def _ordered(self) -> Self:
        if self.end < self.start:
            raise ValueError(f"end {self.end} is before start {self.start}")
        return self


#: A fault the simulated devices play in simulated time.
DeviceFault = RobotErrorFault | StallFault | EstopFault | GraspMissFault | LateAckFault
#: A fault the Modbus server plays in wall time.
NetworkFault = DropConnectionsFault | StopListeningFault | SlowResponsesFault | ModbusExceptionFault

#: Any fault, told apart by its ``kind``.
Fault = Annotated[DeviceFault | NetworkFault, Field(discriminator="kind")]

FAULT_ADAPTER: TypeAdapter[Fault] = TypeAdapter(Fault)

_MODELS: dict[str, type[_FaultBase]] = {
    model.model_fields["kind"].default: model
    for model in (
        RobotErrorFault,
        StallFault,
        EstopFault,
        GraspMissFault,
        LateAckFault,
        DropConnectionsFault,
        StopListeningFault,
        SlowResponsesFault,
        ModbusExceptionFault,
    )
}

#: Every fault kind, in documentation order.
#: The name (``kind``) of every fault.
FAULT_KINDS: tuple[str, ...] = tuple(_MODELS)


def is_network_fault(fault: Fault) -> bool:
    """True for faults the Modbus server plays, False for device faults.

    Args:
        fault: A fault.

    Returns:
        Whether the server plays it (in wall time); device faults play in simulated time.
    """
    return isinstance(
        fault, DropConnectionsFault | StopListeningFault | SlowResponsesFault | ModbusExceptionFault
    )


def _scalar(text: str) -> object:
    """CLI value: None for none/null, an int (also 0x.. / 0b..) where it parses, else text."""
    if text.lower() in ("none", "null"):
        return None
    try:
        # Base 0 accepts 0x1F4, 0o17, 0b101 and plain decimals; pydantic does the rest.
        return int(text, 0)
    except ValueError:
        return text


def parse_fault(text: str) -> Fault:
    """Parse ``kind:key=value,...`` (e.g. ``robot_error:at_move=3,code=0x1F4``) into a fault.

    The text of ``python -m tmmaster.sim --fault``.

    Args:
        text: The fault's kind, then its keys and values.

    Returns:
        The fault.

    Raises:
        ConfigError: An unknown kind or key, a key given twice, or a bad value (the
            message names it).
    """
    kind, _, rest = text.strip().partition(":")
    kind = kind.strip()
    model = _MODELS.get(kind)
    if model is None:
        raise ConfigError(
            f"fault {text!r}: unknown kind {kind!r} (known: {', '.join(FAULT_KINDS)})"
        )
    known = [name for name in model.model_fields if name != "kind"]
    data: dict[str, object] = {"kind": kind}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not value.strip():
            raise ConfigError(f"fault {text!r}: expected key=value, got {item!r}")
        if key not in known:
            raise ConfigError(
                f"fault {text!r}: unknown key {key!r} for {kind} (known: {', '.join(known)})"
            )
        if key in data:
            raise ConfigError(f"fault {text!r}: key {key!r} given twice")
        data[key] = _scalar(value.strip())
    try:
        return FAULT_ADAPTER.validate_python(data)
    except ValidationError as exc:
        problems = []
        for error in exc.errors():
            # loc is (kind, key) for a field error, (kind,) for a cross-field check.
            keys = [str(part) for part in error["loc"] if part != kind]
            where = f"key {keys[0]!r}" if keys else kind
            problems.append(f"{where}: {error['msg']}")
        raise ConfigError(f"fault {text!r}: " + "; ".join(problems)) from exc
