"""Digital I/O of the robot's modules (control box, end module): ``Robot.io``.

The addresses come from the profile (``[digital_io.NAME]``, :class:`DigitalIOModule`);
the ``tmflow`` profile lists Techman's own table (TMflow 2.24 manual, appendix C "Modbus
List": control box DO/DI 0-15 at coils / discrete inputs 0000-0015, pp. 306-307; end
module DO/DI 0-3 at 0800-0803, p. 307). Everything is checked before a byte is sent: the
module, the channel (in range for that module), the value (a bool).

A DO write sets an absolute value, so writing it twice is harmless: it goes through the
transport's retry policy like a read (docs/safety.md). A write whose frame may still be
on its way (no answer came) is remembered; a later write of the other value to the same
output reads the output back until that frame has landed and been undone, or until the
retry policy's total time since it was sent has passed (:meth:`RobotIO.set_do`). It
passes the robot's command gate, so no DO is written once ``close()`` began or while a
stop is requested. The
end-module output that the robot program's gripper uses is refused unless the user
releases it (:attr:`RobotIO.gripper_output`): writing it behind the program's back would
open or close the gripper outside any command the master follows.
"""

from __future__ import annotations

import functools
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from ._checks import shown
from ._codec import Value
from ._exceptions import ConfigError, ConnectError, ModbusExceptionError, StopRequestedError
from ._gate import CommandGate
from ._poller import Poller
from ._registers import DigitalIOModule, Handshake, RobotProfile, Table
from ._transport import Transport

#: The module ``RobotIO``'s calls address when none is named.
DEFAULT_MODULE = "control_box"
#: The module whose output the robot program's gripper uses.
END_MODULE = "end_module"

Kind = Literal["do", "di"]

#: The end module's DO 0 (coil) and DI 0 (discrete input) in Techman's Modbus table.
END_MODULE_DO = 800
END_MODULE_DI = 800


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


#: How often an output is read back while a late write of the other value may land, s.
WATCH_INTERVAL_S = 0.02

#: Failures after which a write's frame is not on its way: never sent (no connection, the
#: gate refused it, a bad argument) or answered (a Modbus exception).
SETTLED_FAILURES = (ConnectError, ModbusExceptionError, StopRequestedError, ConfigError)

#: Per output (``Transport.endpoint``, table, address): the lock of its ``set`` and the writes
#: left unanswered, kept for the process, whichever Robot's :class:`LevelOutput` sent them.
_WATCHED: dict[tuple[object, ...], tuple[threading.Lock, list[tuple[Value, float]]]] = {}


class LevelOutput:
    """An output that holds the last value written to it (a DO coil, the article's
    gripper register), written once per call and watched for a late frame of ours.

    Writing the same value twice is harmless, so a write goes through the retry policy.
    An attempt left unanswered (a timeout, a lost connection) may still reach the robot
    later, from a connection the master has given up: it is remembered, and a later
    :meth:`set` of another value reads the output back every ``WATCH_INTERVAL_S`` until
    that frame has landed and been undone, or until the retry policy's ``total_time_s``
    since it was sent has passed. One :meth:`set` at a time writes and watches it; a stop
    request (the link's ``interrupt``) ends its retries and its watch.

    Args:
        what: The output, as messages name it (``"control_box DO 3"``).
        table: Its Modbus table (a coil, a holding register: one bit or word).
        address: Its address there.
        transport: The robot's link (its retry policy and counters).
        gated: Runs one attempt at a write through the robot's command gate.
        on_late: Told ``found=`` and ``wanted=`` before a late frame is undone (it
            logs); may raise to leave the frame (a robot in error).
    """

    def __init__(
        self,
        what: str,
        table: Table,
        address: int,
        transport: Transport,
        gated: Callable[[Callable[[], None]], None],
        on_late: Callable[..., object],
    ) -> None:
        self.what = what
        self._at = (table, address)
        self._transport = transport
        self._gated, self._on_late = gated, on_late
        # Our writes that got no answer (their frames may still land): value, sent at.
        # Shared with every LevelOutput of this process on the same output (a Robot made
        # after another was closed), so that one's late frame is watched for by the next.
        where = (*transport.endpoint, table, address)
        self._lock, self._doubts = _WATCHED.setdefault(where, (threading.Lock(), []))

    def set(self, value: Value) -> None:
        """Write ``value``, then watch for a late frame of another value (see the class).

        Args:
            value: The value.

        Raises:
            StopRequestedError: A stop was requested: not written, or (the message says
                so) written but no longer watched for an earlier write that could land.
            TransportError: The write, or a read-back, failed after its retries.
        """
        # Another Robot's set of this output may hold its lock while it watches, up to the
        # retry policy's total time: a stop request ends the wait behind it at once.
        while not self._lock.acquire(timeout=WATCH_INTERVAL_S):
            if (stop := self._transport.interrupt) is not None and stop.is_set():
                raise StopRequestedError(f"{self.what} not written: a stop was requested")
        try:
            self._write(value)
            self._settle(value)
        finally:
            self._lock.release()

    def _write(self, value: Value) -> None:
        """Write ``value`` (retried); remember each attempt left unanswered."""
        transport = self._transport
        in_doubt = False

        def once() -> None:
            nonlocal in_doubt
            sent_at = time.monotonic()
            try:
                self._gated(lambda: transport.write_block(*self._at, [int(value)], retry=False))
            except SETTLED_FAILURES:
                raise
            except BaseException:
                self._doubts.append((value, sent_at))
                in_doubt = True
                raise

        def counted(_error: BaseException) -> None:
            transport.stats.retries += 1

        try:
            transport.retry.call(
                f"write {self.what}", once, on_retry=counted, interrupt=transport.interrupt
            )
        except StopRequestedError as exc:
            done = "not confirmed (an attempt may still land)" if in_doubt else "not written"
            raise StopRequestedError(f"{self.what} {done}: {exc}") from exc

    def _settle(self, value: Value) -> None:
        """Read the output back until no earlier write of another value can land unseen.

        Each read that finds another value counts one late frame landed, and ``value`` is
        written back at once. The watch ends when the read shows ``value`` and as many
        landings were seen as frames were in doubt, or at the horizon: the retry policy's
        total time after the newest of them was sent.
        """
        horizon = self._transport.retry.total_time_s
        self._doubts[:] = [d for d in self._doubts if d[1] + horizon > time.monotonic()]
        against = [d for d in self._doubts if d[0] != value]
        if not against:
            return
        until = max(sent_at for _, sent_at in against) + horizon
        poller = Poller(WATCH_INTERVAL_S, self._transport.interrupt, deadline=until)
        seen = 0
        try:
            while True:
                found = self._transport.read_block(*self._at, 1)[0]
                if found != value:
                    seen += 1
                    self._on_late(found=found, wanted=value)
                    self._write(value)  # answered: the output holds value
                elif seen >= len(against):
                    break
                if time.monotonic() >= until:
                    break
                poller.sleep()
        except StopRequestedError as exc:
            raise StopRequestedError(
                f"{self.what} set to {value}, but an earlier write of another value could"
                f" still land: no longer watched ({exc})"
            ) from exc
        self._doubts[:] = [d for d in self._doubts if d[0] == value]


def io_module(profile: RobotProfile, module: object) -> DigitalIOModule:
    """The module called ``module`` (``ConfigError`` listing the profile's modules).

    Args:
        profile: The robot profile.
        module: The module's name, e.g. ``"control_box"`` or ``"end_module"``.

    Returns:
        The module.

    Raises:
        ConfigError: The profile has no digital I/O, or no module of that name.
    """
    if not (modules := profile.digital_io):
        raise ConfigError(
            f"profile {profile.name!r} declares no digital I/O (a [digital_io.NAME] table,"
            " docs/register-maps.md)"
        )
    found = modules.get(module) if isinstance(module, str) else None
    if found is None:
        raise ConfigError(
            f"module {module!r} is not a digital I/O module of profile {profile.name!r}"
            f" (modules: {', '.join(sorted(modules))})"
        )
    return found


def io_address(profile: RobotProfile, module: object, kind: Kind, channel: object) -> int:
    """The coil (``kind`` "do") or discrete input ("di") of ``channel`` of ``module``.

    Args:
        profile: The robot profile.
        module: The module's name.
        kind: ``"do"`` or ``"di"``.
        channel: The DO or DI number, an int from 0.

    Returns:
        The Modbus address.

    Raises:
        ConfigError: An unknown module, a channel that is not an int (a bool, a float,
            NaN) or out of the module's range; the message names the module.
    """
    found, label = io_module(profile, module), kind.upper()
    first, count = (
        (found.do_address, found.do_count) if kind == "do" else (found.di_address, found.di_count)
    )
    if count == 0:
        raise ConfigError(f"module {module} has no {label}")
    if isinstance(channel, bool) or not isinstance(channel, int):
        text = "NaN" if isinstance(channel, float) and math.isnan(channel) else shown(channel)
        raise ConfigError(
            f"{module} {label}: the channel must be an int (0..{count - 1}), got {text}"
            f" ({type(channel).__name__})"
        )
    if not 0 <= channel < count:
        raise ConfigError(
            f"{module} {label} {shown(channel)} does not exist: module {module} has"
            f" {label} 0-{count - 1}"
        )
    return first + channel


def io_value(value: object, what: str) -> bool:
    """``value`` if it is a bool, else ``ConfigError`` naming ``what``.

    Args:
        value: The value to write.
        what: What is written, for the message (``"control_box DO 3"``).

    Returns:
        The value.

    Raises:
        ConfigError: Anything but True or False (1, 0, "on", None...).
    """
    if not isinstance(value, bool):
        raise ConfigError(
            f"{what}: the value must be True or False, got {value!r} ({type(value).__name__})"
        )
    return value


class RobotIO:
    """A robot's digital I/O: control-box and end-module DOs and DIs (``robot.io``).

    Every call names a ``module`` (``"control_box"``, the default, or ``"end_module"`` on
    the ``tmflow`` profile) and a channel number from 0. Inputs and outputs are read in
    one request each (``dis()``, ``dos()``); an output is written on its own (FC 05).
    Arguments are checked before any byte is sent (:class:`ConfigError` naming the
    module). A write is refused with :class:`StopRequestedError` once ``close()`` began
    or while a stop is requested, and the end-module output the robot program's gripper
    uses (:attr:`gripper_output`) is refused unless released.

    Example:
        Against the simulator (``python -m tmmaster.sim --port 5020``):

        ```python
        from tmmaster import connect

        with connect("127.0.0.1", 5020) as robot:
            robot.io.set_do(3, True)                    # control box DO 3 high
            print(robot.io.do(3), robot.io.di(0))       # True False
            print(robot.io.dis())                       # 16 control box DIs, one read
            print(robot.io.di(1, module="end_module"))  # end module DI 1
        ```
    """

    def __init__(
        self,
        profile: RobotProfile,
        transport: Transport,
        gate: CommandGate,
        log: Any,
        require_connection: Callable[[], None],
    ) -> None:
        """Made by :class:`~tmmaster.Robot` (``robot.io``), never by a user.

        Args:
            profile: The robot's profile (its ``digital_io`` modules).
            transport: The robot's link.
            gate: The robot's command gate.
            log: The robot's logger.
            require_connection: Raises before any request while the robot is not
                connected (after the arguments are checked).
        """
        self._profile = profile
        self._link = transport
        self._require_connection = require_connection
        self._gate = gate
        self._log = log
        # A sequence-handshake profile is served by a robot program; the one ``tmmaster
        # robot-program`` writes drives its gripper with end-module DO 0 unless told
        # otherwise (``--gripper io:do=N``, ``--gripper none``).
        sequence = profile.handshake is Handshake.SEQUENCE
        self._gripper_output = GripperWiring().output if sequence else None
        # Per coil address, the output written and watched (made at its first set_do).
        self._outputs: dict[int, LevelOutput] = {}
        self._outputs_lock = threading.Lock()

    @property
    def _transport(self) -> Transport:
        """The robot's link; refused while the robot is not connected (no I/O connects)."""
        self._require_connection()
        return self._link

    @property
    def modules(self) -> tuple[str, ...]:
        """The names of the robot's digital I/O modules (empty when the profile has none)."""
        return tuple(sorted(self._profile.digital_io))

    @property
    def gripper_output(self) -> int | None:
        """The end-module DO the robot program's gripper uses; writing it is refused.

        With a sequence-handshake profile (``tmflow``) it is DO 0, the output of the
        program ``tmmaster robot-program`` writes by default. Set it to the program's
        ``--gripper io:do=N``, or to None when no program drives a gripper output
        (``--gripper none``) and the output is yours.

        Raises:
            ConfigError: (setting) neither None nor an end-module DO number.
        """
        return self._gripper_output

    @gripper_output.setter
    def gripper_output(self, output: int | None) -> None:
        if output is not None:
            io_address(self._profile, END_MODULE, "do", output)
        self._gripper_output = output
        self._log.info("robot.io_gripper_output", output=output)

    def set_do(self, channel: int, value: bool, *, module: str = DEFAULT_MODULE) -> None:
        """Set digital output ``channel`` of ``module`` high (True) or low (False).

        Checked before any byte: the module, the channel, the value, and that the output
        is not the robot program's gripper output. One FC 05 request, retried per the
        robot's retry policy when its answer is lost (setting a DO to the same value
        twice is harmless); logged as ``robot.io_set``.

        A write that got no answer (a timeout, a lost connection) may still reach the
        robot later, from a connection the master has given up. So when an earlier write
        of the other value to this output is in that doubt, the call reads the output
        back every ``WATCH_INTERVAL_S`` after writing: a late frame that lands is undone
        at once (logged as ``robot.io_late_write``), and the call returns once every such
        frame has been seen and undone, or once the retry policy's ``total_time_s`` has
        passed since the newest of them was sent. Without such a doubt, no read is made.

        Args:
            channel: The DO number, from 0 (control box 0-15, end module 0-3 on a TM).
            value: True: high; False: low.
            module: ``"control_box"`` or ``"end_module"`` (the profile's modules).

        Raises:
            ConfigError: An unknown module, a channel out of range or not an int, a
                value that is not a bool, or the gripper's output.
            StopRequestedError: The robot is closing or a stop is requested: not written
                (or, when the message says so, written but no longer watched for an
                earlier write that could still land).
            TransportError: The write, or a read-back, failed after its retries (a
                subclass says how).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        address = io_address(self._profile, module, "do", channel)
        what = f"{module} DO {channel}"
        value = io_value(value, what)
        gripper = self._gripper_output
        if gripper is not None and address == END_MODULE_DO + gripper:
            raise ConfigError(
                f"{what} (coil {address}) drives the gripper through the robot program (its"
                f" gripper wiring io:do={gripper}): writing it would open or close the"
                " gripper behind the program's back; use robot.gripper, or set"
                " robot.io.gripper_output = None if no program drives this output"
            )
        self._output(address, what).set(value)
        self._log.info("robot.io_set", module=module, do=channel, value=value)

    def _output(self, address: int, what: str) -> LevelOutput:
        """The coil at ``address`` as a :class:`LevelOutput` (one per coil)."""
        with self._outputs_lock:
            if address not in self._outputs:
                gated = functools.partial(self._gate.write, None)  # no command: none withdrawn
                late = functools.partial(self._log.warning, "robot.io_late_write", output=what)
                self._outputs[address] = LevelOutput(
                    what, Table.COIL, address, self._transport, gated, late
                )
            return self._outputs[address]

    def do(self, channel: int, *, module: str = DEFAULT_MODULE) -> bool:
        """Read digital output ``channel`` of ``module`` back (one FC 01 request).

        Args:
            channel: The DO number, from 0.
            module: ``"control_box"`` or ``"end_module"``.

        Returns:
            True when the output is high.

        Raises:
            ConfigError: An unknown module or a channel out of range or not an int.
            TransportError: The read failed (a subclass says how).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        address = io_address(self._profile, module, "do", channel)
        return bool(self._transport.read_block(Table.COIL, address, 1)[0])

    def di(self, channel: int, *, module: str = DEFAULT_MODULE) -> bool:
        """Read digital input ``channel`` of ``module`` (one FC 02 request).

        Args:
            channel: The DI number, from 0 (control box 0-15, end module 0-3 on a TM).
            module: ``"control_box"`` or ``"end_module"``.

        Returns:
            True when the input is high.

        Raises:
            ConfigError: An unknown module or a channel out of range or not an int.
            TransportError: The read failed (a subclass says how).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        address = io_address(self._profile, module, "di", channel)
        return bool(self._transport.read_block(Table.DISCRETE_INPUT, address, 1)[0])

    def dos(self, *, module: str = DEFAULT_MODULE) -> tuple[bool, ...]:
        """Read every digital output of ``module`` in one request (FC 01).

        Args:
            module: ``"control_box"`` or ``"end_module"``.

        Returns:
            One bool per DO, DO 0 first.

        Raises:
            ConfigError: An unknown module, or one without DOs.
            TransportError: The read failed (a subclass says how).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        return self._read_all(module, "do")

    def dis(self, *, module: str = DEFAULT_MODULE) -> tuple[bool, ...]:
        """Read every digital input of ``module`` in one request (FC 02).

        Args:
            module: ``"control_box"`` or ``"end_module"``.

        Returns:
            One bool per DI, DI 0 first.

        Raises:
            ConfigError: An unknown module, or one without DIs.
            TransportError: The read failed (a subclass says how).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        return self._read_all(module, "di")

    def _read_all(self, module: str, kind: Kind) -> tuple[bool, ...]:
        first = io_address(self._profile, module, kind, 0)
        found = io_module(self._profile, module)
        count = found.do_count if kind == "do" else found.di_count
        table = Table.COIL if kind == "do" else Table.DISCRETE_INPUT
        return tuple(bool(bit) for bit in self._transport.read_block(table, first, count))
