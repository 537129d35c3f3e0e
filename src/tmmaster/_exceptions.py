"""Every error tmmaster raises derives from :class:`TMMasterError`.

Errors are split by the phase in which they happen, and each also inherits the
builtin a caller would naturally catch (a timeout is also a ``TimeoutError``)::

    TMMasterError
    ├── ConfigError (ValueError)                  before any I/O: nothing was sent
    │   ├── RegisterMapError                      a register map or profile is inconsistent
    │   │   └── UnknownNameError (KeyError)       no field / value / model of that name
    │   ├── ValueOutOfRangeError                  a value does not fit its field
    │   └── UnreachablePoseError                  out of reach, past a joint limit, or singular
    ├── TransportError                            talking Modbus failed
    │   ├── ConnectError (ConnectionError)        could not open the connection
    │   │   ├── ConnectRefusedError               nothing listens at host:port (refused)
    │   │   ├── HostNotFoundError                 the host name does not resolve
    │   │   ├── TransportClosedError              the link is closed, or not opened yet
    │   │   └── NotModbusError                    host:port answers, but not in Modbus TCP
    │   ├── ConnectionLostError (ConnectionError) the connection broke during a request
    │   ├── ResponseTimeoutError (TimeoutError)   no answer in time (or Modbus exception 5, 11)
    │   └── ModbusExceptionError                  the device answered with an exception code
    │       ├── IllegalFunctionError              code 1
    │       ├── IllegalAddressError               code 2
    │       │   └── ProfileMismatchError (ConfigError) the device speaks another profile
    │       ├── IllegalValueError                 code 3
    │       ├── DeviceFailureError                code 4
    │       └── DeviceBusyError                   code 6
    ├── RobotError                                the robot refused or failed a command
    │   ├── RobotFaultError                       robot in error, with its error code
    │   ├── EmergencyStopError                    e-stop pressed
    │   ├── CommandRejectedError                  robot rejected the command (e.g. unreachable)
    │   └── CommandStateUnknownError              cannot prove whether a command was taken
    ├── MotionTimeoutError (TimeoutError)         a wait on the robot ran out of time
    │   └── AcknowledgeTimeoutError               the robot never picked the command up
    ├── GripperError                              the gripper failed
    │   ├── GripperTimeoutError (TimeoutError)    gripper still busy after its timeout
    │   └── GraspFailedError                      closed, but no object detected
    └── StopRequestedError                        a wait gave up because a stop was requested

Foreign errors (pymodbus, socket, pydantic) are mapped to these at one boundary
each, always with ``raise ... from exc`` so the original stays visible.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

# The root and ConfigError live in _error_root.py so that data modules (_pose.py) can
# raise them without importing this module, which needs Pose for its annotations.
from ._checks import shown
from ._error_root import ConfigError as ConfigError
from ._error_root import TMMasterError as TMMasterError
from ._tm_errors import TMErrorCode, code_hex, describe, lookup_tm_error

if TYPE_CHECKING:
    from ._pose import Pose


class RegisterMapError(ConfigError):
    """A register map or profile is inconsistent."""


class UnknownNameError(RegisterMapError, KeyError):
    """A field, value label, profile or model name that does not exist (choices listed)."""

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0]) if self.args else ""


class ValueOutOfRangeError(ConfigError):
    """A value cannot be encoded into its field.

    Args:
        field: The field's name.
        value: The value refused.
        allowed: The allowed range, in words (``"-327.68..327.67 mm, int16 x100"``).
    """

    def __init__(self, field: str, value: object, allowed: str) -> None:
        #: The field's name.
        self.field = field
        #: The value refused.
        self.value = value
        #: The allowed range, in words.
        self.allowed = allowed
        super().__init__(f"{field}: value {shown(value)} is out of range (allowed {allowed})")


class UnreachablePoseError(ConfigError):
    """The arm cannot take a pose: out of reach, past a joint limit, or at a singularity.

    Args:
        message: What is wrong, naming the pose.
        reason: ``"reach"``, ``"joint_limit"``, ``"singularity"`` or ``"configuration"``
            (reachable only in another pose configuration than the arm's).
        pose: The pose refused.
    """

    #: Why: ``"reach"``, ``"joint_limit"``, ``"singularity"`` or ``"configuration"``.
    reason: str

    def __init__(self, message: str, *, reason: str, pose: Pose | None = None) -> None:
        self.reason = reason
        #: The pose refused.
        self.pose = pose
        super().__init__(message)


class TransportError(TMMasterError):
    """A Modbus request failed."""


class ConnectError(TransportError, ConnectionError):
    """The connection could not be opened.

    Attributes:
        retryable: False when another attempt cannot help, so the
            :class:`~tmmaster.RetryPolicy` raises it at once: a closed link, or a first
            connection refused or to a name that does not resolve
            (docs/robot-api.md, "When a connection fails").
    """

    #: Whether the retry policy may try again (an outage: a timeout, a reset, an
    #: unreachable network); False raises at once.
    retryable: bool = True


class ConnectRefusedError(ConnectError, ConnectionRefusedError):
    """Nothing accepts connections at the host and port (the host answered: refused).

    On a link never connected it is raised at once (``retryable`` False): a wrong port,
    the Modbus slave switched off, the simulator not started. Once the link has been
    up, a refused reconnect is an outage (a server restarting) and is retried.
    """


class HostNotFoundError(ConnectError):
    """The host name does not resolve (DNS or the hosts file): ``cannot resolve host 'x'``.

    On a link never connected it is raised at once (``retryable`` False); once the
    link has been up, a failed look-up while reconnecting is retried like an outage.
    """


class TransportClosedError(ConnectError):
    """The link is not open: nothing was sent.

    Closed by its owner (``close()``, its Fleet closing), or never opened: a
    :class:`~tmmaster.Robot` used before :meth:`~tmmaster.Robot.connect` (the message
    names the fix: ``robot.connect()``, or ``with tmmaster.connect(...) as robot:``).
    Never retried: no later attempt can succeed on a link its owner has not opened.
    """

    retryable = False


class NotModbusError(ConnectError):
    """Something answers at the host and port, but not in Modbus TCP: the wrong port.

    An HTTP server, a device speaking another protocol, garbage: a frame whose protocol
    id is not 0, whose length no Modbus TCP frame has, or answers under a transaction id
    never sent. Raised within one request timeout and never retried (``retryable``
    False): a device that speaks another protocol will not start speaking Modbus. A
    :class:`ConnectError`, so code that handles a failed connection handles it too.

    Args:
        message: What was received, naming host and port.
        host: The device's address.
        port: Its port.
    """

    retryable = False

    def __init__(self, message: str, *, host: str = "", port: int = 0) -> None:
        #: The device's address.
        self.host = host
        #: Its port.
        self.port = port
        super().__init__(message)


class ConnectionLostError(TransportError, ConnectionError):
    """The connection broke while a request was in flight."""


class ResponseTimeoutError(TransportError, TimeoutError):
    """The device did not answer within the request timeout.

    Attributes:
        retryable: False on a link whose device has never answered a request (it
            accepted the connection, then said nothing): the
            :class:`~tmmaster.RetryPolicy` raises it at once (docs/robot-api.md, "When
            a connection fails").
    """

    #: Whether the retry policy may try again; False raises at once.
    retryable: bool = True


class ModbusExceptionError(TransportError):
    """The device answered with a Modbus exception response.

    Args:
        message: The request that was refused.
        code: The Modbus exception code (a subclass has its own).
    """

    #: The Modbus exception code.
    code: int = 0

    def __init__(self, message: str, *, code: int | None = None) -> None:
        if code is not None:
            self.code = code
        super().__init__(f"{message} (Modbus exception code {self.code})")


class IllegalFunctionError(ModbusExceptionError):
    """Modbus exception 1: the device does not support this function."""

    code = 1


class IllegalAddressError(ModbusExceptionError):
    """Modbus exception 2: the address range is not served by the device."""

    code = 2


class ProfileMismatchError(IllegalAddressError, ConfigError):
    """The device refused the profile's registers and answers another built-in profile's.

    The robot (or simulator) runs another register contract than the one the Robot was
    given: a configuration error (also a :class:`ConfigError`), found by reading before
    anything was commanded. The message names both profiles.

    Args:
        message: What was refused, naming both profiles.
        profile: The profile this Robot speaks.
        device_profile: The built-in profile whose status registers the device answers.

    Attributes:
        profile: The profile this Robot speaks.
        device_profile: The built-in profile whose status registers the device answers.
    """

    def __init__(self, message: str, *, profile: str, device_profile: str) -> None:
        self.profile = profile
        self.device_profile = device_profile
        # The message quotes the refused read, which already names the Modbus code.
        Exception.__init__(self, message)


class IllegalValueError(ModbusExceptionError):
    """Modbus exception 3: the device refused a value in the request."""

    code = 3


class DeviceFailureError(ModbusExceptionError):
    """Modbus exception 4: the device failed while handling the request."""

    code = 4


class DeviceBusyError(ModbusExceptionError):
    """Modbus exception 6: the device is busy."""

    code = 6


class RobotError(TMMasterError):
    """The robot refused or failed a command.

    Args:
        message: What happened.
        error_code: The robot's error code (0: none reported).
        pose: Where the arm was, when known.
    """

    def __init__(self, message: str, *, error_code: int = 0, pose: Pose | None = None) -> None:
        #: The robot's error code (0: none reported).
        self.error_code = error_code
        #: Where the arm was, when known.
        self.pose = pose
        super().__init__(message)


class _TMCodedError(RobotError):
    """A robot error whose code is Techman's (TMflow 2.24 Appendix J): the message says it.

    A non-zero ``error_code`` is appended to the message with its meaning and, where
    short, what to do: ``robot error: 0x0022 Force or Torque Over Range; what to do
    (TMflow 2.24 manual p. 409): ...``; a code the manual does not list reads ``0x1234
    (not in TMflow 2.24 Appendix J)``.

    Args:
        message: What happened.
        error_code: The robot's error code (0: none reported).
        pose: Where the arm was, when known.
    """

    def __init__(self, message: str, *, error_code: int = 0, pose: Pose | None = None) -> None:
        if error_code and code_hex(error_code) not in message:
            message = f"{message}: {describe(error_code, hint=True)}"
        super().__init__(message, error_code=error_code, pose=pose)

    @property
    def code(self) -> int | None:
        """The robot's error code, None when none was reported."""
        return self.error_code or None

    @property
    def tm_error(self) -> TMErrorCode | None:
        """The code's entry in TMflow 2.24 Appendix J (text, pages, what to do), if listed."""
        if not self.error_code:
            return None
        try:
            return lookup_tm_error(self.error_code)
        except ConfigError:  # a broken install: the message already said so
            return None


class RobotFaultError(_TMCodedError):
    """The robot reported an error (error mode or error flag) with its code.

    ``code`` is the code (None: none reported), ``tm_error`` its entry of TMflow 2.24
    Appendix J (:class:`~tmmaster.TMErrorCode`), and the message names both.
    """


class EmergencyStopError(_TMCodedError):
    """The emergency stop is pressed (``code``/``tm_error`` as for RobotFaultError)."""


class ProjectPausedError(RobotFaultError):
    """The robot program is paused: the move was interrupted, and Play would resume it.

    The master gives such a move up and presses Stop, so it can never resume later.
    """


class CommandRejectedError(RobotError):
    """The robot acknowledged the command but refused to execute it."""


class CommandStateUnknownError(RobotError):
    """It cannot be proven whether the robot took a command; nothing was resent."""


class MotionTimeoutError(TMMasterError, TimeoutError):
    """A wait on the robot ran out of time.

    Args:
        message: What was waited for, and how long.
        pose: Where the arm was, when known.
    """

    def __init__(self, message: str, *, pose: Pose | None = None) -> None:
        #: Where the arm was, when known.
        self.pose = pose
        super().__init__(message)


class AcknowledgeTimeoutError(MotionTimeoutError):
    """The robot never picked the command up."""


class GripperError(TMMasterError):
    """The gripper failed."""


class GripperTimeoutError(GripperError, TimeoutError):
    """The gripper was still busy when its timeout ran out."""


class GraspFailedError(GripperError):
    """The gripper closed but no object was detected."""


class StopRequestedError(TMMasterError):
    """A wait gave up because a stop was requested (Ctrl-C, ``Robot.interrupt()``, a runner stop).

    Raised within one poll of the request. A command the wait was following has been
    withdrawn (or the arm stopped, if it had started) before this propagates.

    Args:
        message: What was given up.
        pose: Where the arm was, when known.
    """

    def __init__(self, message: str = "stop requested", *, pose: Pose | None = None) -> None:
        #: Where the arm was, when known.
        self.pose = pose
        super().__init__(message)


#: The error of each Modbus exception code: one subclass of ModbusExceptionError per code.
MODBUS_EXCEPTIONS: dict[int, type[ModbusExceptionError]] = {
    cls.code: cls for cls in ModbusExceptionError.__subclasses__()
}


class TMScriptError(TMMasterError):
    """A TMscript program is wrong or failed (``tmmaster.tmscript``).

    ``line`` and ``column`` (1-based) say where in the script; the message starts with them.

    Args:
        message: What is wrong (``reason``).
        line: The line, 1-based.
        column: The column, 1-based.
    """

    def __init__(self, message: str, *, line: int, column: int) -> None:
        #: The line, 1-based.
        self.line = line
        #: The column, 1-based.
        self.column = column
        #: The message without the position.
        self.reason = message
        super().__init__(f"line {line}, column {column}: {message}")


class TMScriptSyntaxError(TMScriptError):
    """The script cannot run: a syntax error, an unknown or unsupported function, a type error."""


class TMScriptRuntimeError(TMScriptError):
    """A statement of the script failed while it ran (division by zero, a bad conversion...)."""
