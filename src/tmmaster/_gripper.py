"""Grippers behind one interface: open, close, grip, status, holding.

* :class:`RegisterGripper`: the article profile's gripper register and grasp status on
  the robot's own connection. The map has no busy flag, so a close ends when an object
  is detected or a configured settle time has passed: the weaker option, documented.
* :class:`SequenceGripper`: the tmflow profile: gripper commands go through the robot
  program's sequence handshake like motions; the program reports the grasp.
* :class:`Blog2FG7Gripper`: the second article's map on its own connection: control
  16 executes, the device clears control to acknowledge, gOBJ reports the outcome.
* :class:`OnRobot2FG7Gripper`: the real OnRobot 2FG7 / 2FG14 on its own connection
  (unit id 65; 66 / 67 on a Dual Quick Changer): width in mm, force in N (0 = the
  device's minimum, the ceiling read from the device), speed 1-100 %, busy and
  grip-detected bits; product code, width limits and force ceiling read at connect.

No driver sleeps a fixed time to "let the gripper finish": each polls status. Every
gripper wait also watches the robot: an e-stop or robot error ends it at once with the
robot's typed error, no gripper command is written while the robot is in e-stop or
error, and a stop request (``Robot.interrupt()``, Ctrl-C) ends it within one poll.
"""

from __future__ import annotations

import operator
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from ._channels import CommandKind
from ._checks import require_positive
from ._codec import Value
from ._exceptions import (
    AcknowledgeTimeoutError,
    ConfigError,
    ConnectError,
    ConnectionLostError,
    GraspFailedError,
    GripperError,
    GripperTimeoutError,
    ResponseTimeoutError,
    RobotError,
    TransportError,
)
from ._fleet import open_transport
from ._io import LevelOutput
from ._logging import get_logger
from ._poller import Poller
from ._registers import GripperDriverName, GripperProfile, RegisterField, RobotProfile
from ._retry import RetryPolicy
from ._status import RobotStatus
from ._transport import Transport

_log = get_logger("tmmaster.gripper")


class GripperMount(Protocol):
    """What a gripper driver gets from the robot it is mounted on (not the whole Robot).

    :class:`~tmmaster.Robot` hands one to :meth:`Gripper.attach`: the robot's name,
    register map and link (for grippers wired through the robot), its fault check, the
    stop event that ends every wait, its poll interval and gripper timeouts, and a way
    to run a gripper command through the robot program's handshake.
    """

    @property
    def name(self) -> str:
        """The robot's name: every log event of its gripper carries it (``robot=``)."""

    @property
    def profile(self) -> RobotProfile:
        """The robot's register map."""

    @property
    def transport(self) -> Transport:
        """The robot's link (TransportClosedError before the robot is connected)."""

    @property
    def stop_event(self) -> threading.Event:
        """Set when a stop is requested: every gripper wait ends with StopRequestedError."""

    @property
    def poll_interval_s(self) -> float:
        """Interval of every gripper poll, s."""

    @property
    def gripper_timeout_s(self) -> float:
        """Default bound of a gripper move, s."""

    @property
    def ack_timeout_s(self) -> float:
        """A gripper with its own handshake must take a command within this time, s."""

    def check_fault(self) -> None:
        """Raise the robot's typed error when it is in e-stop or error."""

    def checked_status(self) -> RobotStatus:
        """One robot status read; raises the typed error in e-stop or error.

        Returns:
            The robot's status.
        """

    def gated(self, write: Callable[[], None]) -> None:
        """Make a gripper command write through the robot's command gate.

        Args:
            write: The write (one request).

        Raises:
            StopRequestedError: The robot is closing or a stop is requested: not written.
        """

    def run_command(self, kind: CommandKind, timeout_s: float | None) -> None:
        """Send a gripper command through the robot program's handshake and wait for it.

        Args:
            kind: ``CommandKind.GRIPPER_OPEN`` or ``CommandKind.GRIPPER_CLOSE``.
            timeout_s: How long the command may take, s; None: the robot's gripper
                timeout.
        """


@dataclass(frozen=True)
class GripperStatus:
    """One snapshot of the gripper."""

    #: True while the fingers move; None when the device does not say.
    busy: bool | None
    #: True when an object is detected between the fingers.
    holding: bool
    #: Finger width in mm; None when the device does not report it.
    width_mm: float | None


class Gripper(ABC):
    """What every gripper driver offers: open, close, grip, status, holding.

    A :class:`~tmmaster.Robot` makes its gripper from ``Robot(gripper=...)`` ("auto":
    what the robot profile offers) and hands it out as ``robot.gripper``. Every wait
    polls the gripper and watches the robot: an e-stop or a robot error ends it at once
    with the robot's typed error, and a stop request (``Robot.interrupt()``) within one
    poll.

    Example:
        Against the simulator (``python -m tmmaster.sim --port 5020``), whose
        tmflow robot program drives the gripper:

        ```python
        from tmmaster import connect

        with connect("127.0.0.1", 5020) as robot:
            status = robot.gripper.open()
            print(robot.gripper.kind, status.holding)  # tmflow-program False
            status = robot.gripper.close()  # no part between the fingers here
            print(status.holding)  # False; grip() would raise GraspFailedError
        ```
    """

    #: The driver's name (a gripper profile's name for the stand-alone grippers).
    kind: str = "gripper"
    #: The gripper's own link (a stand-alone gripper's); None when it rides the robot's.
    transport: Transport | None = None
    _mount: GripperMount | None = None
    # Where the driver logs: once mounted, every event names the robot (``robot=``).
    _events: Any = _log

    def attach(self, mount: GripperMount) -> None:
        """Mount on a robot: its fault check and stop event guard every wait (Robot calls it).

        From then on every log event of the gripper names the robot (``robot=NAME``, as
        the robot's own events do) besides the driver (``gripper=KIND``).

        Args:
            mount: What the robot lends its gripper.
        """
        self._mount = mount
        self._events = _log.bind(robot=mount.name)

    def connect(self) -> None:  # noqa: B027 - most grippers share the robot's link
        """Open the gripper's own connection, if it has one."""

    def disconnect(self) -> bool:
        """Close the gripper's own connection, if it has one (safe twice).

        Returns:
            False when a move's stop was due and could not be delivered (logged as
            ``gripper.withdraw_failed``), else True.
        """
        return True

    @abstractmethod
    def status(self) -> GripperStatus:
        """Read the gripper's status once.

        Returns:
            The gripper's status now.
        """

    @abstractmethod
    def open(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Open the fingers fully; returns when they have stopped.

        Args:
            timeout_s: How long the fingers may take, s; None: the driver's default.

        Returns:
            The status once the fingers stopped.

        Raises:
            GripperTimeoutError: The fingers did not stop in time.
            StopRequestedError: A stop was requested meanwhile.
            RobotFaultError: The robot went into e-stop or error (a subclass of it).
        """

    @abstractmethod
    def close(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Close the fingers; returns when they stopped (on an object or fully closed).

        Args:
            timeout_s: How long the fingers may take, s; None: the driver's default.

        Returns:
            The status once the fingers stopped; ``holding`` says whether they hold
            an object.

        Raises:
            GripperTimeoutError: The fingers did not stop in time.
            StopRequestedError: A stop was requested meanwhile.
            RobotFaultError: The robot went into e-stop or error (a subclass of it).
        """

    def grip(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Close and require an object: raises :class:`GraspFailedError` when none is detected.

        Args:
            timeout_s: How long the fingers may take, s; None: the driver's default.

        Returns:
            The status, holding an object.

        Raises:
            GraspFailedError: The fingers closed on nothing.
            GripperTimeoutError: The fingers did not stop in time.
        """
        status = self.close(timeout_s=timeout_s)
        if not status.holding:
            self._events.warning("gripper.grasp_failed", gripper=self.kind)
            raise GraspFailedError(f"{self.kind}: closed but no object detected")
        return status

    @property
    def holding(self) -> bool:
        """True when the gripper currently detects an object."""
        return self.status().holding

    def _done(self, status: GripperStatus, started: float) -> GripperStatus:
        """Log the end of a command sent at ``started`` (``gripper.command_done``)."""
        self._events.info(
            "gripper.command_done",
            gripper=self.kind,
            holding=status.holding,
            width_mm=status.width_mm,
            duration_s=round(time.monotonic() - started, 4),
        )
        return status


class NoGripper(Gripper):
    """Stands in when no gripper is configured: every action is a configuration error."""

    kind = "none"
    """Always ``"none"``."""

    def status(self) -> GripperStatus:
        """Refuse: there is no gripper.

        Returns:
            Never.

        Raises:
            ConfigError: Always.
        """
        raise ConfigError("no gripper is configured for this robot")

    def open(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Refuse: there is no gripper.

        Args:
            timeout_s: Ignored.

        Returns:
            Never.

        Raises:
            ConfigError: Always.
        """
        return self.status()

    def close(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Refuse: there is no gripper.

        Args:
            timeout_s: Ignored.

        Returns:
            Never.

        Raises:
            ConfigError: Always.
        """
        return self.status()


#: Raises the robot's typed error when it is in e-stop or error (``Robot.check_fault``).
RobotGuard = Callable[[], None]


def _wait(
    what: str,
    poll: float,
    timeout_s: float,
    check: Callable[[], GripperStatus | None],
    *,
    guard: RobotGuard | None = None,
    stop_event: threading.Event | None = None,
) -> GripperStatus:
    """Poll ``check`` until it returns a status, bounded by ``timeout_s``.

    ``guard`` runs before every check (robot e-stop / error end the wait); a set
    ``stop_event`` ends it with :class:`StopRequestedError`.
    """
    deadline = time.monotonic() + timeout_s
    poller = Poller(poll, stop_event, deadline=deadline)
    while True:
        poller.check()
        if guard is not None:
            guard()
        if (result := check()) is not None:
            # A stop halts the fingers, which then read as a move that ended (blog-2fg7
            # has no width). Whoever stops them (close(), a Fleet's) sets the event first:
            # a status read after it is not taken as the move done.
            poller.check()
            return result
        if time.monotonic() >= deadline:
            raise GripperTimeoutError(f"{what} did not finish within {timeout_s:g} s")
        poller.sleep()


def _timeout(timeout_s: float | None, default: float) -> float:
    """``timeout_s`` when given (a finite number > 0, else ConfigError), else ``default``."""
    return default if timeout_s is None else require_positive("timeout_s", timeout_s)


class _RobotWiredGripper(Gripper):
    """A gripper wired through the robot: it works only once mounted on one."""

    def _robot(self) -> GripperMount:
        if self._mount is None:
            raise GripperError(
                f"{self.kind}: not mounted on a robot; pass it as Robot(gripper=...)"
            )
        return self._mount

    def status(self) -> GripperStatus:
        """The robot's grasp report (this map has neither busy flag nor width).

        Returns:
            ``holding`` from the robot's grasp status; ``busy`` and ``width_mm`` None.

        Raises:
            GripperError: The gripper is not mounted on a robot.
        """
        robot = self._robot()
        values = robot.transport.read_fields(
            [robot.profile.field("grasp_status")], max_gap=robot.profile.max_read_gap
        )
        return GripperStatus(busy=None, holding=bool(values["grasp_status"]), width_mm=None)


class RegisterGripper(_RobotWiredGripper):
    """The article profile's gripper register (0 open / 1 close) and grasp status.

    The map has no busy flag: a close ends when an object is detected or ``settle_s``
    has passed, an open after ``settle_s``. ``timeout_s`` bounds the whole wait
    (default: the settle time + 1 s).

    The register is level-triggered, so its write is retried when its answer is lost,
    as a digital output's is, and watched the same way: a write of the other value
    while an earlier one may still land reads the register back until that frame has
    landed and been undone, or until the retry policy's ``total_time_s`` since it was
    sent has passed (``docs/safety.md``, Digital outputs).

    Args:
        settle_s: How long an open or a close takes at most, s.
    """

    kind = "article-register"
    """Always ``"article-register"``."""

    def __init__(self, *, settle_s: float = 0.5) -> None:
        self._settle_s = _timeout(settle_s, 0.5)
        self._register: tuple[GripperMount, LevelOutput] | None = None

    def _output(self, robot: GripperMount, command: RegisterField) -> LevelOutput:
        """The register (``command``: one word, 0 open, 1 close) as a :class:`LevelOutput`
        on ``robot``'s link (one per mount)."""
        if self._register is None or self._register[0] is not robot:

            def late(**seen: Value) -> None:  # found=, wanted=
                self._events.warning("gripper.late_write", gripper=self.kind, **seen)
                robot.check_fault()  # no gripper write during an e-stop or error

            what = f"{self.kind}: gripper register"
            output = LevelOutput(
                what, command.table, command.address, robot.transport, robot.gated, late
            )
            self._register = (robot, output)
        return self._register[1]

    def _command_and_settle(
        self, label: str, timeout_s: float | None, *, stop_early_when_holding: bool
    ) -> GripperStatus:
        robot = self._robot()
        bound = _timeout(timeout_s, self._settle_s + 1.0)
        command = robot.profile.field("gripper_command")
        value = command.code_of(label)
        # One read: never a gripper command during an e-stop or robot error, nor while the
        # arm moves (on tmflow the robot program refuses it too: one command at a time).
        if robot.checked_status().moving:
            raise RobotError(f"{self.kind}: the arm is moving; a gripper command waits for it")
        # Writing the same open/close value again is harmless, so retrying is allowed.
        self._output(robot, command).set(value)
        # The settle time counts from the write that landed, not from the first attempt:
        # retries during a short outage must not eat the time the fingers need.
        started = time.monotonic()
        self._events.info("gripper.command_sent", gripper=self.kind, command=label)

        def check() -> GripperStatus | None:
            # One read: the article's status block holds the error state and the grasp.
            robot_status = robot.checked_status()
            status = GripperStatus(busy=None, holding=bool(robot_status.holding), width_mm=None)
            settled = time.monotonic() - started >= self._settle_s
            return status if settled or (stop_early_when_holding and status.holding) else None

        status = _wait(
            f"gripper {label}", robot.poll_interval_s, bound, check, stop_event=robot.stop_event
        )
        return self._done(status, started)

    def open(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Write open, then wait the settle time (no busy flag to watch).

        Args:
            timeout_s: Bound of the whole wait, s; None: the settle time + 1 s.

        Returns:
            The status after the settle time.
        """
        return self._command_and_settle("open", timeout_s, stop_early_when_holding=False)

    def close(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Write close; done when an object is detected or the settle time has passed.

        Args:
            timeout_s: Bound of the whole wait, s; None: the settle time + 1 s.

        Returns:
            The status: holding an object, or not once the settle time has passed.
        """
        return self._command_and_settle("close", timeout_s, stop_early_when_holding=True)


class SequenceGripper(_RobotWiredGripper):
    """Gripper commands through the tmflow profile's sequence handshake."""

    kind = "tmflow-program"
    """Always ``"tmflow-program"``."""

    def _run(self, kind: CommandKind, timeout_s: float | None) -> GripperStatus:
        robot = self._robot()
        _timeout(timeout_s, 0.0)  # checked here; the command's wait applies it
        self._events.info("gripper.command_sent", gripper=self.kind, command=kind.value)
        robot.run_command(kind, timeout_s)
        return self.status()

    def open(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Ask the robot program to open the gripper and wait for it to finish.

        Args:
            timeout_s: How long the program may take, s; None: the robot's gripper
                timeout.

        Returns:
            The status once the program reported the gripper done.
        """
        return self._run(CommandKind.GRIPPER_OPEN, timeout_s)

    def close(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Ask the robot program to close the gripper and wait for it to finish.

        Args:
            timeout_s: How long the program may take, s; None: the robot's gripper
                timeout.

        Returns:
            The status once the program reported the gripper done (with its grasp).
        """
        return self._run(CommandKind.GRIPPER_CLOSE, timeout_s)


@dataclass(frozen=True)
class GripperLink:
    """Where a stand-alone gripper listens and how patiently to talk to it."""

    #: The gripper's address (its Compute Box or the simulator).
    host: str
    #: Its Modbus TCP port.
    port: int
    #: How failed requests are retried; None: the default policy.
    retry: RetryPolicy | None = None
    #: Bound of one Modbus request, s.
    request_timeout_s: float = 1.0
    #: Interval of the gripper's polls, s.
    poll_interval_s: float = 0.05
    #: Default bound of a gripper move, s.
    timeout_s: float = 5.0
    #: A command must be taken within this time, s.
    ack_timeout_s: float = 2.0
    #: A ready transport (e.g. in-memory); None opens one to ``host:port``.
    transport: Transport | None = None
    #: Checks the robot before each gripper write and poll (None: a gripper on its own).
    guard: RobotGuard | None = None
    #: Ends gripper waits on a stop request (the robot's stop event).
    stop_event: threading.Event | None = None


#: Per stand-alone gripper (``Transport.endpoint``): until when a stop frame of this process left
#: unanswered may still land, whichever driver sent it (one list each, shared).
_STOP_DOUBTS: dict[tuple[str, int, int], list[float]] = {}


class _OwnConnectionGripper(Gripper):
    """A gripper with its own Modbus connection and register map."""

    #: The field whose "stop" value withdraws a command and stops the fingers.
    _STOP_FIELD = "command"
    # True from a move's write until it ended or its stop was delivered.
    _sent = False
    # When that write was sent (a command's acknowledgement is timed from it).
    _sent_at = 0.0

    def __init__(self, profile: GripperProfile, link: GripperLink) -> None:
        #: The gripper's register map.
        self.profile = profile
        #: The profile's name.
        self.kind = profile.name
        #: Interval of the gripper's polls, s.
        self.poll_interval_s = link.poll_interval_s
        #: Default bound of a gripper move, s.
        self.timeout_s = link.timeout_s
        #: A command must be taken within this time, s.
        self.ack_timeout_s = link.ack_timeout_s
        self._guard, self._stop_event = link.guard, link.stop_event
        self._busy = threading.Lock()  # held by the one move under way
        # The robot's command gate, once mounted (a gripper on its own writes directly).
        self._gated: Callable[[Callable[[], None]], None] = operator.call
        #: The gripper's own link.
        self.transport: Transport = link.transport or open_transport(
            link.host,
            link.port,
            role="gripper",
            device_id=profile.device_id,
            timeout=link.request_timeout_s,
            retry=link.retry,
            name=profile.name,
        )
        # Until [0] a stop frame left unanswered may still land (and halt a move): kept per
        # gripper for the process, so that a new driver (a new Robot's) waits for it too.
        self._stop_doubt = _STOP_DOUBTS.setdefault(self.transport.endpoint, [0.0])

    def attach(self, mount: GripperMount) -> None:
        """Mount on a robot: its fault check and stop event guard every wait.

        A guard or stop event given in the :class:`GripperLink` is kept.

        Args:
            mount: What the robot lends its gripper.
        """
        super().attach(mount)
        self._guard = self._guard or mount.check_fault
        self._stop_event = self._stop_event or mount.stop_event
        self._gated = mount.gated

    def connect(self) -> None:
        """Open the gripper's connection."""
        self.transport.connect()

    def disconnect(self) -> bool:
        """Close the gripper's connection (safe twice); a move under way is stopped first.

        Its retries end at the bound a :meth:`Robot.close(timeout_s=...)
        <tmmaster.Robot.close>` set on the link.

        Returns:
            False when the stop could not be delivered (logged), else True.
        """
        self._stop_fingers()  # Robot.close() on another thread (its gate closed first)
        self.transport.close()
        return not self._sent

    def _send_and_wait(
        self,
        values: list[tuple[RegisterField, Value]],
        width_mm: float,
        timeout_s: float | None,
        check: Callable[[], GripperStatus | None],
    ) -> GripperStatus:
        """Check the robot, write a move's command once (through the robot's gate), poll
        ``check`` until the move is over, then log its outcome.

        Whatever ends the call once the write was attempted (a lost answer, a timeout, a
        stop request, Ctrl-C, a robot e-stop) first writes the profile's stop, retried:
        the device may have taken the command, and a move given up must not go on (a
        command not taken yet is withdrawn, fingers at rest stay so).

        Args:
            values: The command's fields and values (one FC16, never retried).
            width_mm: The move's target width (for the messages).
            timeout_s: Bound of the wait, s; None: ``timeout_s`` of the link.
            check: Returns the final status once the move is over, else None.

        Returns:
            The final status.

        Raises:
            StopRequestedError: The robot is closing or a stop is requested (unsent), or
                a stop was requested meanwhile (the fingers were stopped).
            GripperTimeoutError: The move did not end in time (the fingers were stopped).
            RobotFaultError: The robot is in e-stop or error (before the write: unsent).
            ConfigError: A move is under way on another thread (unsent).
        """
        if not self._busy.acquire(blocking=False):
            raise ConfigError(f"{self.kind}: a move is under way on another thread")
        started = time.monotonic()

        def send() -> None:
            self._sent, self._sent_at = True, time.monotonic()
            self.transport.write_fields(values, retry=False)

        try:
            self.check_robot()
            self._wait_out_late_stop()
            self._gated(send)
            self._events.info("gripper.command_sent", gripper=self.kind, width_mm=width_mm)
            status = _wait(
                f"{self.kind} move to {width_mm:g} mm",
                self.poll_interval_s,
                timeout_s or self.timeout_s,
                check,
                guard=self._guard,
                stop_event=self._stop_event,
            )
            self._sent = False
        except BaseException:
            self._stop_fingers()  # one not delivered stays due: disconnect() tries again
            raise
        finally:
            self._busy.release()
        return self._done(status, started)

    def _stop_fingers(self) -> None:
        """Stop a move whose write was attempted and that neither ended nor was stopped."""
        if self._sent:
            field = self.profile.field(self._STOP_FIELD)
            stop = [(field, field.code_of("stop"))]
            doubt = False
            try:
                try:
                    self.transport.write_fields(stop, retry=False, interruptible=False)
                except TransportError:
                    doubt = True  # an attempt unanswered may still land, in a later move
                    self.transport.write_fields(stop, retry=True, interruptible=False)
                self._sent = False  # delivered: another thread need not write it again
            except TransportError as exc:
                self._events.error("gripper.withdraw_failed", gripper=self.kind, error=str(exc))
            finally:
                if doubt or self._sent:
                    # From the end of the write: its last attempt was sent before then.
                    self._stop_doubt[0] = time.monotonic() + self.transport.retry.total_time_s

    def _wait_out_late_stop(self) -> None:
        """Before a move's write: wait while a stop frame of ours left unanswered may still
        land (up to the retry policy's ``total_time_s`` after it was sent). Landing during
        the move, it would halt the fingers mid-way, and a halted move reads as one that
        ended (no width on blog-2fg7). A stop request ends the wait (nothing written)."""
        if (left := self._stop_doubt[0] - time.monotonic()) > 0:
            self._events.warning("gripper.stop_in_doubt", gripper=self.kind, wait_s=round(left, 3))
            Poller(self.poll_interval_s, self._stop_event).sleep_until(self._stop_doubt[0])

    def check_robot(self) -> None:
        """Raise the robot's typed error if it is in e-stop or error (no-op on its own)."""
        if self._guard is not None:
            self._guard()

    def read(self, *names: str) -> dict[str, Value]:
        """Read fields by name, one request per block.

        Args:
            *names: Field names of the gripper's profile.

        Returns:
            Each field's decoded value, by name.
        """
        return self.transport.read_fields(
            self.profile.select(names), max_gap=self.profile.max_read_gap
        )


class Blog2FG7Gripper(_OwnConnectionGripper):
    """The second article's map: force / width / control=16, gOBJ status from 258.

    Made by ``Robot(gripper=GripperDevice("blog-2fg7", port=...))`` (or
    ``Robot(gripper=Blog2FG7Gripper(...))``), on its own Modbus connection.

    Args:
        profile: The gripper's register map (``tmmaster.gripper_profile("blog-2fg7")``).
        link: Where it listens and how patiently to talk to it.
        force_n: Gripping force, N.
    """

    _STOP_FIELD = "control"

    def __init__(
        self, profile: GripperProfile, link: GripperLink, *, force_n: float = 40.0
    ) -> None:
        super().__init__(profile, link)
        #: Gripping force of every move, N.
        self.force_n = force_n

    def status(self) -> GripperStatus:
        """gOBJ: 0 moving, 1/2 stopped on an object, 3 at position without object.

        Returns:
            ``busy`` while moving and ``holding`` on an object; no width.
        """
        values = self.read("object_status", "motion_state")
        obj = self.profile.field("object_status").label(int(values["object_status"]))
        return GripperStatus(
            busy=obj == "moving", holding=obj in ("object_opening", "object_closing"), width_mm=None
        )

    def _move(self, width_mm: float, timeout_s: float | None) -> GripperStatus:
        p = self.profile
        # One FC16 of force, width and control; sent once: the acknowledgement tells.
        values = [
            (p.field("force"), self.force_n),
            (p.field("width"), width_mm),
            (p.field("control"), p.field("control").code_of("execute")),
        ]
        acknowledged = False

        def check() -> GripperStatus | None:
            nonlocal acknowledged
            if not acknowledged:
                if int(self.read("control")["control"]) != 0:
                    if time.monotonic() - self._sent_at > self.ack_timeout_s:
                        raise AcknowledgeTimeoutError(
                            f"{self.kind}: the gripper did not take the command within"
                            f" {self.ack_timeout_s:g} s; the command was withdrawn (control = 0)"
                        )
                    return None
                acknowledged = True
            status = self.status()
            return None if status.busy else status

        return self._send_and_wait(values, width_mm, timeout_s, check)

    def open(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Open to the map's maximum width.

        Args:
            timeout_s: How long the move may take, s; None: the link's ``timeout_s``.

        Returns:
            The status once the fingers stopped.

        Raises:
            AcknowledgeTimeoutError: The gripper did not take the command (withdrawn).
            GripperTimeoutError: The fingers did not stop in time.
            ConfigError: A move is under way on another thread (unsent).
        """
        return self._move(self.profile.field("width").maximum or 160.0, timeout_s)

    def close(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Close to width 0; the fingers stop on an object if there is one.

        Args:
            timeout_s: How long the move may take, s; None: the link's ``timeout_s``.

        Returns:
            The status once the fingers stopped.

        Raises:
            AcknowledgeTimeoutError: The gripper did not take the command (withdrawn).
            GripperTimeoutError: The fingers did not stop in time.
            ConfigError: A move is under way on another thread (unsent).
        """
        return self._move(0.0, timeout_s)


#: The 2FG7's smallest target force other than 0 (0 = "the device's minimum"); the
#: largest is read from the device (max_force, 0x0405): it follows the power setting.
ONROBOT_MIN_FORCE_N = 20.0
#: Products that speak the 2FG map (product code labels in the profile).
ONROBOT_2FG_PRODUCTS = ("2FG7", "2FG14")


def _check_force_speed(kind: str, force_n: float, speed_percent: int, ceiling_n: float) -> None:
    if force_n != 0 and not ONROBOT_MIN_FORCE_N <= force_n <= ceiling_n:
        raise ConfigError(
            f"{kind}: force {force_n:g} N must be 0 (the device's minimum) or"
            f" {ONROBOT_MIN_FORCE_N:g}..{ceiling_n:g} N"
        )
    if not 1 <= speed_percent <= 100:
        raise ConfigError(f"{kind}: speed {speed_percent} % is outside 1..100 %")


class OnRobot2FG7Gripper(_OwnConnectionGripper):
    """The real OnRobot 2FG7 or 2FG14 (Compute Box, unit id 65; 66 / 67 on a Dual Quick Changer).

    Made by ``Robot(gripper=GripperDevice("onrobot-2fg7", host=..., port=...))`` (or
    ``Robot(gripper=OnRobot2FG7Gripper(...))``), on its own Modbus connection. At
    :meth:`connect` it checks the product code and reads the width limits of the grip
    mode and the force ceiling.

    Args:
        profile: The gripper's register map (``tmmaster.gripper_profile("onrobot-2fg7")``).
        link: Where the Compute Box listens and how patiently to talk to it.
        force_n: Target force, N: 0 (the device's minimum) or 20 up to the device's
            ceiling.
        speed_percent: Finger speed, 1-100 %.
        grip: ``"external"`` (closing onto a part from outside) or ``"internal"``
            (opening into a part from inside).

    Raises:
        ConfigError: A force or speed out of range.
    """

    def __init__(
        self,
        profile: GripperProfile,
        link: GripperLink,
        *,
        force_n: float = 40.0,
        speed_percent: int = 50,
        grip: Literal["external", "internal"] = "external",
    ) -> None:
        super().__init__(profile, link)
        # Checked against the profile's static range now, against the live ceiling
        # (max_force, read at connect) before every move.
        _check_force_speed(
            self.kind, force_n, speed_percent, profile.field("target_force").maximum or 0
        )
        #: Target force, N (0: the device's minimum).
        self.force_n = force_n
        #: Finger speed, %.
        self.speed_percent = speed_percent
        #: ``"external"`` or ``"internal"``.
        self.grip_mode = grip
        #: The grip mode's (smallest, largest) width, mm, read at connect; None before.
        self.limits: tuple[float, float] | None = None
        #: Largest target force the device accepts now (register max_force, at connect).
        self.max_force_n: float | None = None
        #: "2FG7" or "2FG14", from the product code read at connect.
        self.product: str | None = None
        #: A move has arrived when the width is this close to its target, mm.
        self.width_tolerance_mm = 0.5

    def connect(self) -> None:
        """Connect; check the product code; read the width limits and the force ceiling.

        Raises:
            ConnectError: The Compute Box took the connection but does not answer
                (another master holds it).
            GripperError: The device is not a 2FG7 or 2FG14.
        """
        super().connect()
        names = (
            "min_external_width",
            "max_external_width",
            "min_internal_width",
            "max_internal_width",
        )
        try:
            values = self.read(*names)
        except (ConnectionLostError, ResponseTimeoutError) as exc:
            # The Compute Box completes the TCP connect, then drops a second client at
            # once: a bare "connection lost" would hide that another master holds it.
            self.transport.close()
            raise ConnectError(
                f"{self.kind}: {self.transport.host}:{self.transport.port} accepted the"
                " connection but did not answer: the OnRobot Compute Box serves one"
                " Modbus TCP connection at a time; is another master (or a TMflow"
                " OnRobot node) connected to it?"
            ) from exc
        identity = self.read("product_code", "max_force")
        code = int(identity["product_code"])
        product = self.profile.field("product_code").label(code)
        if product not in ONROBOT_2FG_PRODUCTS:
            self.transport.close()
            raise GripperError(
                f"{self.kind}: unit id {self.profile.device_id} reports product code"
                f" {code:#06x} ({product}), not a 2FG7 (0xc0) or 2FG14 (0xc1)"
            )
        self.product = product
        self.max_force_n = float(identity["max_force"])
        low, high = names[:2] if self.grip_mode == "external" else names[2:]
        self.limits = (float(values[low]), float(values[high]))
        self._events.info(
            "gripper.connected",
            gripper=self.kind,
            product=product,
            grip=self.grip_mode,
            min_width_mm=self.limits[0],
            max_width_mm=self.limits[1],
            max_force_n=self.max_force_n,
        )

    def _connected(self) -> tuple[float, float, float]:
        """The grip mode's smallest and largest width and the force ceiling, read at
        :meth:`connect`; GripperError before."""
        if self.limits is None or self.max_force_n is None:
            raise GripperError(f"{self.kind}: not connected")
        return (*self.limits, self.max_force_n)

    def status(self) -> GripperStatus:
        """Busy and grip-detected bits, and the current width.

        Returns:
            ``busy``, ``holding`` and ``width_mm`` (of the grip mode).
        """
        width = "external_width" if self.grip_mode == "external" else "internal_width"
        values = self.read("status", width)
        word = int(values["status"])
        status_field = self.profile.field("status")
        return GripperStatus(
            busy=status_field.bit(word, "busy"),
            holding=status_field.bit(word, "grip_detected"),
            width_mm=float(values[width]),
        )

    def move_to_width(
        self, width_mm: float, *, timeout_s: float | None = None, expect_object: bool = False
    ) -> GripperStatus:
        """Move the fingers to ``width_mm`` (inside the limits read at connect time).

        Args:
            width_mm: Target width, mm.
            timeout_s: How long the move may take, s; None: the link's ``timeout_s``.
            expect_object: Stopping on an object before the width ends the move too.

        Returns:
            The status once the fingers are at the width (or on an object).

        Raises:
            GripperError: Not connected.
            ConfigError: The width, force or speed is out of range, or a move is
                under way on another thread (unsent).
            GripperTimeoutError: The move did not end in time.
        """
        low, high, ceiling = self._connected()
        if not low <= width_mm <= high:
            raise ConfigError(f"{self.kind}: width {width_mm:g} mm outside {low:g}..{high:g} mm")
        _check_force_speed(self.kind, self.force_n, self.speed_percent, ceiling)
        p = self.profile
        command = p.field("command").code_of(f"grip_{self.grip_mode}")
        values = [
            (p.field("target_width"), width_mm),
            (p.field("target_force"), self.force_n),
            (p.field("target_speed"), self.speed_percent),
            (p.field("command"), command),
        ]

        def check() -> GripperStatus | None:
            status = self.status()
            if status.busy:
                return None
            # Not busy is not enough (it may not have started): the fingers must be at
            # the target, or stopped on an object when closing onto one.
            assert status.width_mm is not None
            arrived = abs(status.width_mm - width_mm) <= self.width_tolerance_mm
            return status if arrived or (expect_object and status.holding) else None

        return self._send_and_wait(values, width_mm, timeout_s, check)

    def open(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Open to the maximum width of the current grip mode.

        Args:
            timeout_s: How long the move may take, s; None: the link's ``timeout_s``.

        Returns:
            The status once the fingers are open.

        Raises:
            GripperError: Not connected.
        """
        return self.move_to_width(self._connected()[1], timeout_s=timeout_s)

    def close(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Close to the minimum width; stops on an object (grip detected) if there is one.

        Args:
            timeout_s: How long the move may take, s; None: the link's ``timeout_s``.

        Returns:
            The status once the fingers stopped.

        Raises:
            GripperError: Not connected.
        """
        return self.move_to_width(self._connected()[0], timeout_s=timeout_s, expect_object=True)


#: The driver of each gripper protocol a profile may name (``GripperProfile.driver``);
#: the simulated devices are keyed by the same names (``tmmaster.sim._grippers``).
GRIPPER_DRIVERS: Mapping[GripperDriverName, type[Blog2FG7Gripper | OnRobot2FG7Gripper]] = {
    "blog-2fg7": Blog2FG7Gripper,
    "onrobot-2fg7": OnRobot2FG7Gripper,
}


def auto_gripper(profile: RobotProfile, *, settle_s: float) -> Gripper:
    """What the robot profile itself offers: a gripper register, program commands, or none."""
    if profile.has("gripper_command"):
        return RegisterGripper(settle_s=settle_s)
    labels = set(profile.field("command").values.values()) if profile.has("command") else set()
    closes = CommandKind.GRIPPER_CLOSE.value in labels and profile.has("grasp_status")
    return SequenceGripper() if closes else NoGripper()
