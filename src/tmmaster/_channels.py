"""Command channels: how a command reaches the robot and how its fate is observed.

One class per handshake in a profile:

* :class:`ClearOnAcceptChannel` (the ``article`` contract): the master writes target,
  speed and command in one request; the robot sets motion status to moving and then
  clears the command register. Cleared command = acknowledged; acknowledged and then
  idle = done.
* :class:`SequenceChannel` (the ``tmflow`` contract): the master writes the block with
  a new sequence number; the robot program echoes it into ``ack_seq`` when it takes the
  command and into ``done_seq`` when finished, or reports an error state.

A channel reads and writes through a :class:`~tmmaster._transport.Transport` and raises tmmaster's
errors; it never sleeps and never decides how long to wait: that is :mod:`._robot`'s job.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from types import MappingProxyType
from typing import TypeVar

from ._codec import Value
from ._exceptions import (
    CommandRejectedError,
    ConfigError,
    EmergencyStopError,
    ProjectPausedError,
    RobotError,
    RobotFaultError,
)
from ._logging import get_logger
from ._pose import _POSE_FIELDS, MotionType, Pose
from ._registers import (
    BOOT_FIELD,
    EXTENSION_FIELDS,
    FLANGE_FIELDS,
    JOINT_FIELDS,
    ROBOT_BASE_FLANGE_FIELDS,
    ROBOT_BASE_TCP_FIELDS,
    SESSION_FIELD,
    TARGET_FIELDS,
    TCP_FIELDS,
    VIA_FIELDS,
    Handshake,
    RegisterField,
    RobotProfile,
    Role,
    Table,
)
from ._status import PROJECT_PAUSED, PROJECT_STOPPED, RobotStatus
from ._transport import Block, ConnectionState, Encoded, Transport, encode_writes, group_writes

_log = get_logger("tmmaster.robot")


class CommandKind(StrEnum):
    """What a command asks for; values match the labels of the profile's command field."""

    PTP = "ptp"
    LINE = "line"
    STOP = "stop"
    GRIPPER_OPEN = "gripper_open"
    GRIPPER_CLOSE = "gripper_close"
    #: A PTP to joint angles (TMscript ``PTP("JPP", ...)``): the target registers carry J1..J6.
    PTP_JOINTS = "ptp_joints"
    #: A circular arc through a via point (TMscript ``Circle``).
    CIRCLE = "circle"

    @classmethod
    def of(cls, motion: MotionType) -> CommandKind:
        """The command kind for a motion type.

        Args:
            motion: PTP or LINE.

        Returns:
            ``CommandKind.PTP`` or ``CommandKind.LINE``.
        """
        return cls.PTP if motion is MotionType.PTP else cls.LINE


#: The results of a number the robot program consumed without running its command.
_UNRUN = ("cancelled", "another_master")
#: How long a Stop this master wrote may take to show on the robot, s (a judgement: TMflow
#: takes it at its next cycle, 20 ms on the simulator; not measured on a TM5).
STOP_SHOWS_S = 1.0
#: Per robot (``Transport.endpoint``): until when a Stop a Robot of this process wrote may
#: not show yet on it, and the program's start (``boot_id``) it was written in if known: a
#: new start since shows it taken. A Robot made after the one that wrote it waits too.
STOP_SHOWS_BY: dict[tuple[str, int, int], tuple[float, Value | None]] = {}

#: The command kinds that write the command block's extension (via, speed_mm_s, ext_seq).
_EXTENDED = frozenset({CommandKind.LINE, CommandKind.CIRCLE})


@dataclass(frozen=True)
class Command:
    """A command as the user asked for it, before encoding."""

    #: What it asks for.
    kind: CommandKind
    #: The TCP target of a move (None for a gripper command or a stop); for a
    #: ``ptp_joints`` command, the TCP the joints put the arm at.
    target: Pose | None = None
    #: The move's speed, % (a TCP speed in mm/s: the percent of the arm's top TCP speed it
    #: is, rounded up).
    speed: int | None = None
    #: The move's acceleration time, ms (None: the robot's default).
    accel_time_ms: int | None = None
    #: A ``ptp_joints`` command's joint angles J1..J6, deg (what the target registers carry).
    joints: tuple[float, ...] | None = None
    #: A ``circle`` command's point on the arc.
    via: Pose | None = None
    #: A Line's or a Circle's TCP speed, mm/s (None: ``speed`` in %).
    speed_mm_s: int | None = None


@dataclass
class Ticket:
    """A command that was written, with what is needed to follow it."""

    command: Command
    words: list[tuple[RegisterField, Value]]
    sent_at: float
    #: Sequence number (sequence handshake only).
    seq: int = 0
    #: Target registers before the write (clear-on-accept only): tells a lost write apart.
    previous_target: tuple[float, ...] | None = None
    #: TCP pose read while preparing, when the check read it anyway (saves a request).
    start_pose: Pose | None = None
    #: The joints (deg) read with ``start_pose``, where the profile publishes them.
    start_joints: tuple[float, ...] | None = None
    #: Every field read with ``start_pose`` (the frames, where the plan read carries them).
    start_values: dict[str, Value] | None = None
    acknowledged: bool = False
    acknowledged_at: float | None = None
    #: ``time.monotonic()`` before the last poll that saw the command not yet taken (the
    #: robot took it after this, and by ``acknowledged_at``).
    pending_seen_at: float | None = None
    #: Set by the wait's schedule: the next poll also reads the TCP pose, where the
    #: profile's poll does not carry it (one request), to gauge the move's progress.
    observe_pose: bool = False
    #: True once a poll saw the robot report the command finished (before that poll's
    #: last read: a failure of that read leaves nothing to stop); False again when the
    #: reads after it saw the arm still moving (a failed move is then stopped).
    finished: bool = False
    #: True once the command was taken back (it can no longer start).
    withdrawn: bool = False
    #: True once a write of the command block was attempted (it may have landed even if
    #: the write failed); a command never written has nothing to withdraw or stop.
    written: bool = False
    #: True once a second copy of the block was written: the first may still land.
    resent: bool = False
    #: True once the robot program was seen started again since the command was
    #: written (tmflow's ``boot_id``): it never runs from then on, and needs no Stop.
    restarted: bool = False
    extra: dict[str, Value] = field(default_factory=dict)
    #: ``words`` encoded and grouped into write blocks while preparing (encoded once).
    plan: list[tuple[Block, list[int]]] = field(default_factory=list)


def link_mark(transport: Transport) -> int | None:
    """The link's epoch while it is connected (None: not connected).

    Two equal marks mean: the same connection, and not one write, failed request, retry
    or reconnect on it in between (:attr:`Transport.epoch`).
    """
    return None if transport.state is not ConnectionState.CONNECTED else transport.epoch


#: How old (s) the read of the poll that saw a command finished may be for the next
#: command's checks to use it instead of reading again: one TM control tick (50 Hz).
REUSE_DONE_READ_S = 0.02


@dataclass
class StateAfterDone:
    """The registers read by the poll that saw a command finished, and right after it.

    The next command's checks may use them instead of reading the same registers again
    (:meth:`CommandChannel.prepare`, ``reuse_s``): only once, only on the same
    connection with nothing written (and no error, retry or reconnect) since the poll
    began, and only while ``read_at`` is at most ``reuse_s`` old.
    """

    #: Every field the poll read (the read that saw the command done, and after it).
    values: dict[str, Value]
    #: ``time.monotonic()`` just before the poll's first request (the age counts from here).
    read_at: float
    #: :func:`link_mark` just before the poll's first request.
    link: int
    #: The TCP pose, when it was read after the done (the final at-target check).
    pose: Pose | None = None
    #: The joints (deg) read with ``pose``, where the profile publishes them.
    joints: tuple[float, ...] | None = None
    #: Every field read with ``pose`` and ``joints`` (the frames, where published).
    plan_values: dict[str, Value] | None = None


@dataclass(frozen=True)
class Observation:
    """What one poll saw about a ticket."""

    acknowledged: bool
    done: bool
    #: Set when the robot reported a failure; the wait must end with it.
    failure: RobotError | None
    pose: Pose | None
    #: The joints (deg) read with ``pose``, where the poll read them.
    joints: tuple[float, ...] | None = None


#: A poll without I/O (:meth:`CommandChannel.poll_steps`): yields the fields to read
#: next, is sent their values, returns what the poll saw.
PollSteps = Generator[tuple[RegisterField, ...], dict[str, Value], Observation]

R = TypeVar("R")


def _address(field: RegisterField) -> int:
    return field.address


def pose_from(values: dict[str, Value], names: tuple[str, ...]) -> Pose:
    """The pose in ``values`` under the six field ``names`` (x, y, z, rx, ry, rz, in order).

    Six finite floats need none of pydantic's validation, whose first call after a sleep
    cost a poll 20-40 us: the pose is filled in directly. Anything else is validated
    (and refused) as any Pose is.
    """
    coordinates = [float(values[name]) for name in names]
    if not all(map(math.isfinite, coordinates)):
        return Pose(*coordinates)
    pose = object.__new__(Pose)
    pose.__dict__.update(zip(_POSE_FIELDS, coordinates, strict=True))
    return pose


class CommandChannel(ABC):
    """Sends commands and interprets the robot's answers for one handshake."""

    def __init__(self, profile: RobotProfile, transport: Transport) -> None:
        self.profile, self.transport = profile, transport
        command = profile.field("command")
        # The block's extension (a circle's via, a TCP speed in mm/s), where the profile
        # has all of it: it is tied to a command by the sequence number (ext_seq).
        self.extension_fields = (
            profile.published(EXTENSION_FIELDS) if profile.handshake is Handshake.SEQUENCE else ()
        )
        self.supported = frozenset(
            CommandKind(v)
            for v in command.values.values()
            if v in set(CommandKind) and (v != CommandKind.CIRCLE or self.extension_fields)
        )
        # Optional sets of Techman's table, empty where the profile lacks them: read at
        # connect and before a plan; the joints also with the status (they come in the
        # same request as the TCP pose, Techman's 7013-7036).
        self.joint_fields = profile.published(JOINT_FIELDS)
        self.status_fields: tuple[RegisterField, ...] = (
            *profile.role(Role.STATUS),
            *self.joint_fields,
            *profile.role(Role.POSE),
            *profile.role(Role.FEEDBACK),
            *(f for f in profile.role(Role.GRIPPER) if not f.access.writable),  # readable
        )
        # Field sets read on every command, built once (their read plans are cached by
        # the tuple's identity).
        self.tcp_fields = profile.select(TCP_FIELDS)
        self.flange_fields = profile.published(FLANGE_FIELDS)
        self.robot_base_tcp_fields = profile.published(ROBOT_BASE_TCP_FIELDS)
        # Before a plan: the TCP pose with the joints, where published (Techman's
        # 7013-7036: one request), and with the frames where the profile publishes all of
        # 7001-7060 (flange, joints, TCP, both in the robot base): still one request, so
        # the frame check runs before every move at no request more.
        robot_base_flange = profile.published(ROBOT_BASE_FLANGE_FIELDS)
        #: True when the plan read carries the frames (the flange, both bases).
        self.frames_in_plan = bool(self.flange_fields and robot_base_flange)
        self.plan_fields = (
            *(self.flange_fields if self.frames_in_plan else ()),
            *self.joint_fields,
            *self.tcp_fields,
            *((*robot_base_flange, *self.robot_base_tcp_fields) if self.frames_in_plan else ()),
        )
        self.command_fields = (command,)
        # The command block's fields, looked up once (the map does not change under a
        # channel: the field sets above are built once too).
        self._target_fields = profile.select(TARGET_FIELDS)
        self.target_block = (*self._target_fields, command)
        self._speed_field = profile.field("speed")
        self._accel_field = profile.field("accel_time") if profile.has("accel_time") else None
        self._via_fields = self.extension_fields[: len(VIA_FIELDS)]
        self._speed_mm_s_field = profile.field("speed_mm_s") if self.extension_fields else None
        # The master's session after the extension (tmflow: SequenceChannel).
        self._session_field: RegisterField | None = None
        #: This master's session, written with every command that has the field (its
        #: heartbeat's, set when it claims the robot: :meth:`Heartbeat.claim`).
        self.session = 0
        self._command_field = command
        # Each command's block as encoded (:meth:`_encode_command`), by the command.
        self._encoded: dict[Command, tuple[list[tuple[RegisterField, Value]], list[Encoded]]] = {}
        #: What the last poll that saw a command finished read (see :class:`StateAfterDone`).
        self.after_done: StateAfterDone | None = None

    # -- reading ---------------------------------------------------------

    def read(
        self, fields: Sequence[RegisterField], *, retry: bool = True, interruptible: bool = True
    ) -> dict[str, Value]:
        """Read fields, one request per contiguous block, retrying transient failures
        (``retry=False``: once, a failure raised at once); ``interruptible=False``: even
        after a stop request."""
        return self.transport.read_fields(
            fields, max_gap=self.profile.max_read_gap, retry=retry, interruptible=interruptible
        )

    def _read_regardless(self, fields: tuple[RegisterField, ...]) -> dict[str, Value]:
        """:meth:`read`, even after a stop request (a withdraw or a stop's own reads)."""
        return self.read(fields, interruptible=False)

    def read_status(self) -> RobotStatus:
        """A full status snapshot."""
        return self.status_from(self.read(self.status_fields))

    def read_pose(self, retry: bool = True) -> Pose:
        """The current TCP pose (one request; ``retry=False``: made once, as :meth:`poll`)."""
        pose = pose_from(self.read(self.tcp_fields, retry=retry), TCP_FIELDS)
        if self.after_done is not None:
            # Read after the done poll: the next command may start its plan from it.
            self.after_done.pose = pose
        return pose

    def read_plan(self) -> tuple[Pose, tuple[float, ...] | None, dict[str, Value]]:
        """The plan's read: the TCP pose, the joints (deg; None where the profile does not
        publish them) and every field read, the frames with them where published.

        One request where they are contiguous (Techman's 7001-7060). Read after the poll
        that saw a command done, the next command may start its plan from it.
        """
        values = self.read(self.plan_fields)
        return (*self._note_plan_read(values), values)

    def _note_plan_read(self, values: dict[str, Value]) -> tuple[Pose, tuple[float, ...] | None]:
        """The pose and joints in a plan read; kept for the next command's plan when the
        read follows the poll that saw a command done."""
        pose, joints = pose_from(values, TCP_FIELDS), self.joints_from(values)
        if self.after_done is not None:
            self.after_done.pose, self.after_done.joints = pose, joints
            self.after_done.plan_values = values
        return pose, joints

    def joints_from(self, values: dict[str, Value]) -> tuple[float, ...] | None:
        """The joints J1..J6 (deg) in ``values``; None where the profile does not publish them."""
        return tuple(float(values[f.name]) for f in self.joint_fields) or None

    def _poll_mark(self) -> tuple[float, int | None]:
        """Before a poll's first request: forget the last done state; the time and link mark."""
        self.after_done = None
        return time.monotonic(), link_mark(self.transport)

    @staticmethod
    def _note_ack(ticket: Ticket, taken: bool, mark: tuple[float, int | None]) -> None:
        """Note what a poll saw of a command not yet acknowledged: taken now, or pending."""
        if taken:
            ticket.acknowledged = True
            ticket.acknowledged_at = time.monotonic()
        else:
            ticket.pending_seen_at = mark[0]

    def _remember_done(
        self, ticket: Ticket, values: dict[str, Value], mark: tuple[float, int | None]
    ) -> None:
        """The poll saw ``ticket`` finished: note it, keep what it read for the next command."""
        ticket.finished = True
        read_at, link = mark
        if link is not None:
            self.after_done = StateAfterDone(values, read_at, link)

    def take_after_done(self, reuse_s: float) -> StateAfterDone | None:
        """The state read when the last command was seen finished, if it may stand in for a read.

        Used at most once: it is forgotten whatever the answer. None when there is none,
        when it is older than ``reuse_s`` (0: never reused), or when the link wrote,
        failed, retried or reconnected since the poll that read it began.
        """
        state, self.after_done = self.after_done, None
        if state is None or reuse_s <= 0 or time.monotonic() - state.read_at > reuse_s:
            return None
        return None if link_mark(self.transport) != state.link else state

    @abstractmethod
    def status_from(self, values: dict[str, Value]) -> RobotStatus:
        """Interpret raw field values as a status snapshot."""

    def status_failure(self, status: RobotStatus) -> RobotError | None:
        """The typed error a status snapshot stands for (e-stop, error), or None."""
        if status.estop:
            return EmergencyStopError(
                "emergency stop is pressed", error_code=status.error_code, pose=status.pose
            )
        if status.error:
            return RobotFaultError(
                f"robot in error (mode {status.mode})",  # the error adds the code's meaning
                error_code=status.error_code,
                pose=status.pose,
            )
        return None

    # -- commands --------------------------------------------------------

    def supports(self, kind: CommandKind) -> bool:
        """True when the profile's command field has a value for ``kind``."""
        return kind in self.supported

    def _encode_command(
        self, command: Command
    ) -> tuple[list[tuple[RegisterField, Value]], list[Encoded]]:
        """The command block's field values and their words (raises naming the field).

        A command given again (a cycle's) takes the words of its first encoding, and is
        refused alike (a refused command is not kept); the words are never changed in
        place. Kept in a dict of the channel's own (a cache around a bound method would
        put the channel in a reference cycle, its link freed only by a collection).
        """
        if (known := self._encoded.get(command)) is not None:
            return known
        self._refuse_unsupported(command)
        words: list[tuple[RegisterField, Value]] = []
        if command.target is not None:
            words += zip(self._target_fields, self._target_values(command), strict=True)
        if command.speed is not None:
            words.append((self._speed_field, command.speed))
        if command.target is not None and self._accel_field is not None:
            # Always written (0 = the program's default) so the block stays contiguous
            # and goes out as one atomic request.
            words.append((self._accel_field, command.accel_time_ms or 0))
        if self._speed_mm_s_field is not None and (
            command.kind in _EXTENDED or self._session_field is not None
        ):
            # Every Line and Circle writes the extension (in the same request; ext_seq
            # follows with the number): one left from an earlier command never applies.
            # Every other command too (zero, ext_seq 0) where the session follows it.
            via = command.via.as_list() if command.via is not None else [0.0] * 6
            words += zip(self._via_fields, via, strict=True)
            words.append((self._speed_mm_s_field, command.speed_mm_s or 0))
        words.append((self._command_field, self._command_field.code_of(command.kind.value)))
        # Every value encoded now: ValueOutOfRangeError naming the field, before any I/O;
        # the words are kept, so the write does not encode them again (nor a repeat).
        if len(self._encoded) >= 64:  # bounded: ad-hoc commands are not kept forever
            self._encoded.clear()
        self._encoded[command] = known = (words, encode_writes(words))
        return known

    def _refuse_unsupported(self, command: Command) -> None:
        """A command this profile cannot carry: ConfigError naming what is missing."""
        if not self.supports(command.kind):
            raise ConfigError(
                f"profile {self.profile.name!r} has no {command.kind.value!r} command"
            )
        if command.speed_mm_s is not None and (
            self._speed_mm_s_field is None or command.kind not in _EXTENDED
        ):
            raise ConfigError(
                f"profile {self.profile.name!r} has no TCP speed in mm/s for a"
                f" {command.kind.value!r} command"
                + ("" if self._speed_mm_s_field is None else " (only line and circle have one)")
            )
        if command.kind is CommandKind.CIRCLE and command.via is None:
            raise ConfigError("a circle command needs a via point")

    @staticmethod
    def _target_values(command: Command) -> list[float]:
        """The target's six values: the joints of a ptp_joints command, else the pose."""
        if command.kind is CommandKind.PTP_JOINTS:
            if command.joints is None or len(command.joints) != 6:
                raise ConfigError("a ptp_joints command needs six joint angles")
            return list(command.joints)
        assert command.target is not None
        return command.target.as_list()

    @abstractmethod
    def prepare(self, command: Command, *, reuse_s: float = 0.0) -> Ticket:
        """Check the robot can take the command and build the ticket; writes nothing.

        ``reuse_s`` > 0: the registers the poll that saw the previous command finished
        read (and only those) stand in for reading them again, when that poll began at
        most ``reuse_s`` ago on the same connection with nothing written since
        (:meth:`take_after_done`). Every check is the same either way.
        """

    def poll(self, ticket: Ticket, retry: bool = True) -> Observation:
        """Read the robot's state once and say what happened to the ticket
        (``retry=False``: each read made once, as :meth:`Motion.cancel`'s first look)."""
        return self._drive(self.poll_steps(ticket), retry)

    def _drive(
        self, steps: Generator[tuple[RegisterField, ...], dict[str, Value], R], retry: bool = True
    ) -> R:
        """Run steps without I/O here: read each field set they yield through the transport."""
        try:
            fields = next(steps)  # steps that need no read end here
            while True:
                fields = steps.send(self.read(fields, retry=retry))
        except StopIteration as finished:
            result: R = finished.value
            return result

    @abstractmethod
    def poll_steps(self, ticket: Ticket) -> PollSteps:
        """One poll without I/O: yields each field set to read, is sent its values, returns.

        The one implementation of a poll: :meth:`poll` reads each set through the
        transport (blocking); a :class:`~tmmaster.Fleet` reads them on its event loop.
        The reads are in order, one after the other (the order carries meaning: the
        article's status block is read after the command register).
        """

    @abstractmethod
    def withdraw(self, ticket: Ticket) -> bool | None:
        """Take back a command the robot has not acknowledged; True if it had taken it after all.

        Written with retries and regardless of a stop request: a withdraw is idempotent.
        None: the withdraw is written but the robot has not answered it yet; ask
        :meth:`withdraw_outcome` until it does.
        """

    def withdraw_outcome(self, ticket: Ticket) -> bool | None:
        """After :meth:`withdraw` returned None: True taken, False withdrawn, None not yet."""
        return False

    def cancel(self, ticket: Ticket) -> None:  # noqa: B027 (none, where no handshake says it)
        """Tell the robot a command it took is given up, where the handshake can say so."""

    def may_resume(self, flags: dict[str, Value] | None = None) -> bool:
        """True when a move the robot stopped itself could still be resumed (Play).

        Read after a fault ends a running move: such a move is stopped for good (the
        master presses Stop) where the robot could otherwise resume it. ``flags``: the
        project's flags a read has just found (None: read them).
        """
        return False

    @abstractmethod
    def write_landed(self, ticket: Ticket) -> bool:
        """After a failed command write: True when the registers show the write arrived.

        False means "not seen yet", never "provably lost": a delayed frame may still land.
        """

    #: True when writing the same command block twice cannot make the robot run it twice.
    duplicate_safe: bool = False

    def send(self, ticket: Ticket) -> None:
        """Write the command block in one request, exactly once (never retried)."""
        ticket.sent_at = time.monotonic()
        ticket.written = True
        if not ticket.plan:
            self.transport.write_fields(ticket.words, retry=False)
            return
        for block, words in ticket.plan:  # the command block: one block, one request
            self.transport.write_block(block.table, block.address, words, retry=False)

    def read_failure(self) -> RobotError | None:
        """Read the fewest registers that tell whether the robot is in e-stop or error."""
        return self.status_failure(self.read_status())

    def stop_words(self) -> list[tuple[RegisterField, Value]] | None:
        """Field values that stop the robot at once, or None if the profile has no stop."""
        return None

    @property
    def can_stop(self) -> bool:
        """True when the profile defines a way to stop the arm (:meth:`stop`)."""
        return self.stop_words() is not None

    def stop(self, boot: Value | None = None) -> None:
        """Stop the arm now; :class:`ConfigError` when the profile defines no stop.

        A stop is idempotent: it is written with retries, even after a stop request.
        ``boot``: the program's start (``boot_id``) the Stop is written in, if known.
        """
        words = self.stop_words()
        if words is None:
            raise ConfigError(f"profile {self.profile.name!r} defines no way to stop the robot")
        self.transport.write_fields(words, retry=True, interruptible=False)
        STOP_SHOWS_BY[self.transport.endpoint] = (time.monotonic() + STOP_SHOWS_S, boot)

    def check_command(self, command: Command) -> None:
        """Encode any command's block without sending it (raises naming the field)."""
        self._encode_command(command)


class ClearOnAcceptChannel(CommandChannel):
    """The article's contract: the robot clears the command register when it takes a command."""

    def status_from(self, values: dict[str, Value]) -> RobotStatus:
        """Interpret robot_mode / motion_status / error_code / grasp_status."""
        p = self.profile
        mode_value, error_code = int(values["robot_mode"]), int(values["error_code"])
        return RobotStatus(
            mode=p.field("robot_mode").label(mode_value),
            moving=int(values["motion_status"]) == 1,
            error=mode_value == p.mode_error or error_code != 0,
            error_code=error_code,
            estop=False,
            holding=bool(values["grasp_status"]) if "grasp_status" in values else None,
            pose=pose_from(values, TCP_FIELDS),
            raw=MappingProxyType(dict(values)),
            timestamp=time.monotonic(),
        )

    def prepare(self, command: Command, *, reuse_s: float = 0.0) -> Ticket:
        """Refuse when the robot is in error, not in auto mode, moving, or has a command pending."""
        words, encoded = self._encode_command(command)
        p, after_done = self.profile, self.take_after_done(reuse_s)
        block = self.read(self.target_block)
        # The status block the poll that saw the last command finished read (after the
        # cleared command register, idle), where it may stand in: the same checks run on it.
        status = self.read_status() if after_done is None else self.status_from(after_done.values)
        if (failure := self.status_failure(status)) is not None:
            raise failure
        if command.kind is not CommandKind.STOP:
            if int(status.raw["robot_mode"]) != p.mode_auto:
                raise RobotError(f"robot not ready: mode {status.mode}", pose=status.pose)
            if status.moving:
                raise RobotError("robot is still moving", pose=status.pose)
            if int(block["command"]) != 0:
                raise RobotError(
                    f"a command ({p.field('command').label(int(block['command']))}) is still"
                    " pending in the command register",
                    pose=status.pose,
                )
        previous = tuple(float(block[n]) for n in TARGET_FIELDS)
        return Ticket(
            command,
            words,
            time.monotonic(),
            previous_target=previous,
            start_pose=status.pose,
            plan=group_writes(encoded),
        )

    def poll_steps(self, ticket: Ticket) -> PollSteps:
        """Before acknowledgement read the command register first, then the status block."""
        mark = self._poll_mark()
        if not ticket.acknowledged:
            pending = int((yield self.command_fields)["command"])
            self._note_ack(ticket, pending == 0, mark)
        # Read after the command register: the robot sets "moving" before it clears the
        # command, so idle here, after seeing the command cleared, means finished.
        status = self.status_from((yield self.status_fields))
        failure = self.status_failure(status)
        done = ticket.acknowledged and not status.moving and failure is None
        if done:
            self._remember_done(ticket, dict(status.raw), mark)
        return Observation(ticket.acknowledged, done, failure, status.pose, status.joints)

    def withdraw(self, ticket: Ticket) -> bool:
        """Write command = none, then check whether the robot had started the move meanwhile
        (``motion_status``: moving, as :meth:`status_from` reads it).

        That check is read once, not retried: one that fails (reads lost, writes passing)
        raises, and the caller presses Stop at once, harmless if the robot did not take the
        command, instead of after the retry policy's whole budget while the arm, had it
        taken it, runs on (``tests/test_lostreads_giveup.py``). The Stop is idempotent and
        owed until delivered; the command itself is never written again.
        """
        self.transport.write_fields([(self._command_field, 0)], retry=True, interruptible=False)
        field = self.profile.field("motion_status")
        return int(self.read([field], retry=False)[field.name]) == 1

    def write_landed(self, ticket: Ticket) -> bool:
        """Our targets in the registers (pending or taken), or the arm moving: the write arrived.

        The robot was idle with no command pending when the write was sent, so motion now
        can only be ours. Old targets prove nothing: the frame may still be on its way.
        """
        block, ours = self.read(self.target_block), {f.name: v for f, v in ticket.words}
        targets_match = all(
            abs(float(block[n]) - float(ours[n])) < 1e-6 for n in TARGET_FIELDS if n in ours
        )
        if targets_match and int(block["command"]) == int(ours["command"]):
            return True  # landed, not yet picked up
        if (
            targets_match
            and ticket.previous_target is not None
            and any(
                abs(a - float(ours[n])) >= 1e-6
                for a, n in zip(ticket.previous_target, TARGET_FIELDS, strict=True)
                if n in ours
            )
        ):
            return True  # our targets are there and the command was cleared: taken
        return self.read_status().moving

    def stop_words(self) -> list[tuple[RegisterField, Value]] | None:
        """command = stop, when the profile defines it."""
        field = self._command_field
        return [(field, field.code_of("stop"))] if self.supports(CommandKind.STOP) else None


class SequenceChannel(CommandChannel):
    """The tmflow contract: sequence number, acknowledge and done registers."""

    def __init__(self, profile: RobotProfile, transport: Transport) -> None:
        super().__init__(profile, transport)
        p = profile
        # The program's feedback block, grasp_status (9105) with it: one request, 9100-9107.
        self.feedback_fields = tuple(
            sorted((*p.role(Role.FEEDBACK), *p.published(("grasp_status",))), key=_address)
        )
        # All of Techman's status bits, not just the three the handshake needs: together
        # they are one contiguous block (7201-7208), so one request instead of two.
        needed = p.select(("error", "estop", "project_running"))
        self.flag_fields = needed + tuple(
            f for f in p.role(Role.STATUS) if f.table is Table.DISCRETE_INPUT and f not in needed
        )
        self.feedback_and_seq = (*self.feedback_fields, p.field("seq"))
        self.error_code_fields = (p.field("last_error_code"),)
        self.seq_fields = (p.field("seq"), p.field("ack_seq"))
        self.seq_only = (p.field("seq"),)
        if self.extension_fields and p.has(SESSION_FIELD):
            self._session_field = p.field(SESSION_FIELD)  # every command carries it
        # The program's start the command was written in (tmflow: after the session).
        self._boot_field = p.field(BOOT_FIELD) if p.has(BOOT_FIELD) else None
        #: The project's flags the last withdraw_outcome() read ({}: none yet), for the
        #: may_resume() that follows it: a second read would only delay a Stop.
        self._flags: dict[str, Value] = {}

    def status_from(self, values: dict[str, Value]) -> RobotStatus:
        """Interpret the TM discrete inputs and the robot program's feedback registers."""
        estop = bool(values["estop"])
        error, running = bool(values["error"]) or estop, bool(values["project_running"])
        # The most severe first: an e-stop is an error too.
        mode = "estop" if estop else "error" if error else "running" if running else "stopped"
        state = self.profile.field("robot_state").label(int(values["robot_state"]))
        return RobotStatus(
            mode=mode,
            moving=state == "busy",
            error=error,
            error_code=int(values["last_error_code"]),
            estop=estop,
            holding=bool(values["grasp_status"]) if "grasp_status" in values else None,
            pose=pose_from(values, TCP_FIELDS),
            raw=MappingProxyType(dict(values)),
            timestamp=time.monotonic(),
            joints=self.joints_from(values) if "joint_1" in values else None,
        )

    def _flags_failure_steps(
        self, flags: dict[str, Value]
    ) -> Generator[tuple[RegisterField, ...], dict[str, Value], RobotError | None]:
        """The failure Techman's status bits show; an e-stop or an error reads (by
        yielding it) the last error code, which the error's message names."""
        if bool(flags["estop"]) or bool(flags["error"]):
            code = int((yield self.error_code_fields)["last_error_code"])
            if bool(flags["estop"]):
                return EmergencyStopError("emergency stop is pressed", error_code=code)
            return RobotFaultError("robot error", error_code=code)  # + code, meaning
        if bool(flags.get("paused", False)):
            return ProjectPausedError(PROJECT_PAUSED)
        return None if bool(flags["project_running"]) else RobotFaultError(PROJECT_STOPPED)

    def prepare(self, command: Command, *, reuse_s: float = 0.0) -> Ticket:
        """Refuse unless the project runs, nothing failed, and the last command is finished."""
        words, encoded = self._encode_command(command)
        p, after_done = self.profile, self.take_after_done(reuse_s)
        # The feedback block that showed the last command done and the flags read after
        # it (the poll that saw it finished), where they may stand in: the same checks
        # run on them. ``seq`` is not part of a poll: it is read now.
        flags = self.read(self.flag_fields) if after_done is None else after_done.values
        if (failure := self._drive(self._flags_failure_steps(flags))) is not None:
            raise failure
        if after_done is None:
            feedback = self.read(self.feedback_and_seq)
        else:
            feedback = {**after_done.values, **self.read(self.seq_only)}
        seq_now, ack, done = (int(feedback[n]) for n in ("seq", "ack_seq", "done_seq"))
        state = p.field("robot_state").label(int(feedback["robot_state"]))
        if not 0 <= ack <= p.seq_max:
            raise RobotError(f"the robot program reports ack_seq {ack}, outside 0..{p.seq_max}")
        if seq_now == p.next_seq(ack):
            raise RobotError(f"command {seq_now} is still waiting to be acknowledged")
        if state == "busy":
            raise RobotError(f"the robot program is still executing command {ack}")
        if ack != done and state != "error":
            # Abandoned (project stopped mid-command): the program is idle, so a new
            # command is safe; say so, since the old one never finished.
            _log.warning("robot.previous_command_unfinished", seq=ack, done_seq=done)
        # The program takes only ack_seq + 1 (1..seq_max, skipping 0), so a seq that was
        # put back to withdraw a command can never be mistaken for a new one.
        seq = p.next_seq(ack)
        boot = feedback.get("boot_id", 0)  # the program's start this command belongs to
        numbered = self._numbered(command, seq, boot)
        words = [*words, *numbered]  # the encoded words stay as they are
        ticket = Ticket(
            command,
            words,
            time.monotonic(),
            seq=seq,
            extra={"heartbeat": feedback.get("heartbeat", 0), "boot": boot},
            plan=group_writes([*encoded, *encode_writes(numbered)]),
        )
        if after_done is not None:  # what the poll read after the done: the plan's start
            ticket.start_pose, ticket.start_joints = after_done.pose, after_done.joints
            ticket.start_values = after_done.plan_values
        return ticket

    def _numbered(
        self, command: Command, seq: int, boot: Value
    ) -> list[tuple[RegisterField, Value]]:
        """The words that tie a block to its number, its master and the program's start."""
        numbered: list[tuple[RegisterField, Value]] = [(self.profile.field("seq"), seq)]
        if command.kind in _EXTENDED and self.extension_fields:
            numbered.append((self.extension_fields[-1], seq))  # the extension's command
        elif self._session_field is not None:
            numbered.append((self.extension_fields[-1], 0))  # the extension is no one's
        for stamp, value in ((self._session_field, self.session), (self._boot_field, boot)):
            if stamp is not None:
                numbered.append((stamp, value))
        return numbered

    def poll_steps(self, ticket: Ticket) -> PollSteps:
        """One read of the feedback block, then the status flags (two reads when split)."""
        mark = self._poll_mark()
        feedback = yield self.feedback_fields
        flags = yield self.flag_fields
        ticket.extra["last_heartbeat"] = feedback.get("heartbeat", 0)
        failure = yield from self._flags_failure_steps(flags)
        # Whose command took the number: ack_session as the acknowledgement is first seen
        # (later it may name the next number's taker, written before that number's ack).
        if fresh := not (ticket.acknowledged or self._new_runs(ticket, feedback)):
            self._note_ack(ticket, int(feedback["ack_seq"]) == ticket.seq, mark)
        if fresh and ticket.acknowledged and failure is None and self._taken_for_another(feedback):
            failure = CommandRejectedError(
                f"the robot program took command {ticket.seq} from another master (session"
                f" {feedback['ack_session']}): this one was never read and never runs"
            )
        done = False
        if failure is None:
            done, failure = self._outcome(ticket, feedback)
        pose: Pose | None = None
        joints: tuple[float, ...] | None = None
        if done:
            self._remember_done(ticket, {**feedback, **flags}, mark)
            if ticket.command.target is not None:
                # The final at-target check's read, in the same poll (on a driver's loop,
                # no hand-over more); the next command's plan may start from it.
                pose, joints = self._note_plan_read((yield self.plan_fields))
        elif ticket.observe_pose and failure is None:
            ticket.observe_pose = False
            pose = pose_from((yield self.tcp_fields), TCP_FIELDS)
        return Observation(ticket.acknowledged, done, failure, pose, joints)

    def _outcome(
        self, ticket: Ticket, feedback: dict[str, Value]
    ) -> tuple[bool, RobotError | None]:
        """Whether the feedback shows ``ticket`` done, or the failure it shows."""
        if ticket.acknowledged and not self._new_runs(ticket, feedback):
            if int(feedback["done_seq"]) == ticket.seq:
                return True, None
            if self.profile.field("robot_state").label(int(feedback["robot_state"])) == "error":
                result = self.profile.field("result_code").label(int(feedback["result_code"]))
                return False, CommandRejectedError(
                    f"robot program rejected command {ticket.seq}: {result}",
                    error_code=int(feedback["result_code"]),
                )
        if self._restarted(ticket, feedback):
            return False, CommandRejectedError(
                f"the robot program started again under command {ticket.seq}: it never runs"
                " from now on (it may have moved before)"
            )
        return False, None

    duplicate_safe = True  # the program takes a sequence number at most once

    def withdraw(self, ticket: Ticket) -> bool | None:
        """Cancel our sequence number; True if the program had taken the command itself.

        The cancel is the same sequence number with command = none, written as one
        request: the program consumes it as a no-op (result "cancelled"), so the number
        is used up and a late copy of the original frame can never be taken afterwards.
        If the project is not running, the program consumes it at its next start.

        The cancel is withdrawn only once the program has answered it: the program may
        have read the block just before the cancel landed, and it acknowledges the
        number it read (then reads the block again and finds the cancel, or runs the
        command if the cancel came later still). So this returns None until the answer
        (:meth:`withdraw_outcome`): ``ack_seq`` at our number, with our session in
        ``ack_session`` or ``done_seq`` at our number (taken) or not (withdrawn); or the
        project not running (withdrawn). On a stopped project the cancel is written all
        the same, and the start-up rule consumes it: a copy of the command frame still in
        the network, not landed yet, would otherwise find its number free after Play. On
        a running one, a number already taken is left alone (another master's move).
        """
        # The flags withdraw_outcome() just read say whether the project may resume: a
        # second read would only delay the Stop that follows a command found taken.
        if (outcome := self.withdraw_outcome(ticket)) is None or not self.may_resume(self._flags):
            self.cancel(ticket)
            outcome = self.withdraw_outcome(ticket)
        return outcome

    def cancel(self, ticket: Ticket) -> None:
        """Write the cancel record: our sequence number with command = none, one request.

        Not yet taken, the program consumes the number as a no-op; taken (running, or
        paused), its watchdog stops the project, even where the robot refuses the
        master's Stop (Manual mode, the Robot Stick in local control).
        """
        command = self._command_field
        self.transport.write_fields(
            [(command, command.code_of("none")), (self.profile.field("seq"), ticket.seq)],
            retry=True,
            interruptible=False,
        )

    def withdraw_outcome(self, ticket: Ticket) -> bool | None:
        """What the program did with our number: True taken, False cancelled or not running.

        None: it has not answered yet (``ack_seq`` is not our number and the project runs).
        """
        p = self.profile
        # The flags first: a project seen stopped before the feedback is read cannot have
        # taken the number after that read (read the other way, it may in between).
        flags = self._flags = self._read_regardless(self.flag_fields)
        values = self._read_regardless(self.feedback_fields)
        if self._restarted(ticket, values):
            return True  # the project started again since: the command may have run before
        if int(values["ack_seq"]) == ticket.seq:  # consumed unrun, or taken (whose?)
            if self.session and "ack_session" in values:
                # The program names the command it took (0: none ran), so a command the
                # watchdog stopped after it moved, reported "cancelled", counts as taken.
                # Done at our number: it ran (the 0 is the next number's, used up unrun).
                taker = int(values["ack_session"])
                return taker == self.session or (
                    not taker and int(values["done_seq"]) == ticket.seq
                )
            return p.field("result_code").label(int(values["result_code"])) not in _UNRUN
        if not bool(flags["project_running"]) and not bool(flags.get("paused", False)):
            return False  # not running: nothing takes it before the start-up rule consumes it
        return None

    @staticmethod
    def _restarted(ticket: Ticket, feedback: dict[str, Value]) -> bool:
        """True (noted on ``ticket``) once the project started since ``ticket`` was
        prepared: another boot_id."""
        boot = ticket.extra.get("boot")
        ticket.restarted = ticket.restarted or (bool(boot) and feedback.get("boot_id") != boot)
        return ticket.restarted

    def _new_runs(self, ticket: Ticket, feedback: dict[str, Value]) -> bool:
        """True when the project started again since ``ticket`` (a controller restart puts
        the numbers back at 0) and ``ack_seq`` shows another command than ``ticket``'s:
        another master's that took its number, or any other number (one used up unrun
        after another master's command of ``ticket``'s number ran: its ``done_seq``)."""
        ours = int(feedback["ack_seq"]) == ticket.seq and not self._taken_for_another(feedback)
        return self._restarted(ticket, feedback) and not ours

    def _taken_for_another(self, feedback: dict[str, Value]) -> bool:
        """True when the command at ``ack_seq`` is another master's (its session, not ours)."""
        return bool(self.session) and int(feedback.get("ack_session", 0)) not in (0, self.session)

    def may_resume(self, flags: dict[str, Value] | None = None) -> bool:
        """True while the project is paused or still running: Play could resume a move."""
        flags = flags or self._read_regardless(self.flag_fields)
        return bool(flags.get("paused", False)) or bool(flags["project_running"])

    def write_landed(self, ticket: Ticket) -> bool:
        """seq is written in the same request as the block: if it is ours, the write landed."""
        values = self.read(self.seq_fields)
        return ticket.seq in (int(values["seq"]), int(values["ack_seq"]))

    def read_failure(self) -> RobotError | None:
        """One read of Techman's status bits (e-stop, error, project running)."""
        return self._drive(self._flags_failure_steps(self.read(self.flag_fields)))

    def stop_words(self) -> list[tuple[RegisterField, Value]] | None:
        """Press the TM Stop button (coil 7105): the project stops and the arm halts."""
        p = self.profile
        return [(p.field("stop_project"), True)] if p.has("stop_project") else None


def channel_for(profile: RobotProfile, transport: Transport) -> CommandChannel:
    """The channel implementing ``profile``'s handshake."""
    clears = profile.handshake is Handshake.CLEAR_ON_ACCEPT
    return (ClearOnAcceptChannel if clears else SequenceChannel)(profile, transport)


def heartbeat_stalled(ticket: Ticket) -> bool:
    """True when the robot program's heartbeat did not move since the command was prepared."""
    return (
        "heartbeat" in ticket.extra
        and ticket.extra.get("last_heartbeat") == ticket.extra["heartbeat"]
    )
