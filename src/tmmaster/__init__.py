"""tmmaster: drive a Techman (TM) robot arm and its gripper over Modbus TCP.

The same code runs against the built-in simulator (``python -m tmmaster.sim``) and
against a real robot: only the host changes. Everything public is importable from
here; modules starting with an underscore are private. ``tmmaster.__version__`` is the
installed version. The simulator is a plugin: ``import tmmaster`` does not load it
(``tmmaster.sim`` does).
"""

# isort: off
# First: while a command of tmmaster's loads, Ctrl-C is one line and exit 130 (it acts
# only when this process is one of the commands; see _startup).
from . import _startup as _startup
# isort: on

from types import FunctionType as _FunctionType

from ._channels import Command, CommandKind
from ._codec import Value, allowed_range, decode, encode
from ._exceptions import (
    AcknowledgeTimeoutError,
    CommandRejectedError,
    CommandStateUnknownError,
    ConfigError,
    ConnectError,
    ConnectionLostError,
    ConnectRefusedError,
    DeviceBusyError,
    DeviceFailureError,
    EmergencyStopError,
    GraspFailedError,
    GripperError,
    GripperTimeoutError,
    HostNotFoundError,
    IllegalAddressError,
    IllegalFunctionError,
    IllegalValueError,
    ModbusExceptionError,
    MotionTimeoutError,
    NotModbusError,
    ProfileMismatchError,
    ProjectPausedError,
    RegisterMapError,
    ResponseTimeoutError,
    RobotError,
    RobotFaultError,
    StopRequestedError,
    TMMasterError,
    TMScriptError,
    TMScriptRuntimeError,
    TMScriptSyntaxError,
    TransportClosedError,
    TransportError,
    UnknownNameError,
    UnreachablePoseError,
    ValueOutOfRangeError,
)
from ._fleet import Fleet, ModbusTransport
from ._gripper import (
    Blog2FG7Gripper,
    Gripper,
    GripperLink,
    GripperMount,
    GripperStatus,
    NoGripper,
    OnRobot2FG7Gripper,
    RegisterGripper,
    SequenceGripper,
)
from ._io import RobotIO
from ._logging import configure_logging
from ._loop import EventLoopName, MonitoredStatus
from ._monitor import StatusMonitor
from ._options import Checks, FrameCheck, GripperDevice
from ._poller import Poller, PollPolicy
from ._pose import DEFAULT_HOME, MotionType, Pose, UnitsError
from ._profiles import (
    DEFAULT_PROFILE,
    builtin_profile_names,
    gripper_profile,
    load_profile,
    profile_markdown,
    robot_profile,
)
from ._registers import (
    Access,
    DataType,
    DigitalIOModule,
    GripperProfile,
    Handshake,
    RegisterField,
    RegisterMap,
    RobotProfile,
    Role,
    Table,
    WordOrder,
)
from ._retry import RetryPolicy
from ._robot import Motion, Robot, TimeoutPolicy, Workspace, connect
from ._robot_models import ROBOT_MODELS, JointSpec, RobotModel, robot_model
from ._status import MovePhase, MoveProgress, ProjectState, RobotStatus
from ._tm_errors import TMErrorCode, lookup_tm_error
from ._tool import Tool, ToolMismatchError
from ._transport import ConnectionState, Transport, TransportStats
from ._version import version as _version

__version__ = _version()

__all__ = [
    "DEFAULT_HOME",
    "DEFAULT_PROFILE",
    "ROBOT_MODELS",
    "Access",
    "AcknowledgeTimeoutError",
    "Blog2FG7Gripper",
    "Checks",
    "Command",
    "CommandKind",
    "CommandRejectedError",
    "CommandStateUnknownError",
    "ConfigError",
    "ConnectError",
    "ConnectRefusedError",
    "ConnectionLostError",
    "ConnectionState",
    "DataType",
    "DeviceBusyError",
    "DeviceFailureError",
    "DigitalIOModule",
    "EmergencyStopError",
    "EventLoopName",
    "Fleet",
    "FrameCheck",
    "GraspFailedError",
    "Gripper",
    "GripperDevice",
    "GripperError",
    "GripperLink",
    "GripperMount",
    "GripperProfile",
    "GripperStatus",
    "GripperTimeoutError",
    "Handshake",
    "HostNotFoundError",
    "IllegalAddressError",
    "IllegalFunctionError",
    "IllegalValueError",
    "JointSpec",
    "ModbusExceptionError",
    "ModbusTransport",
    "MonitoredStatus",
    "Motion",
    "MotionTimeoutError",
    "MotionType",
    "MovePhase",
    "MoveProgress",
    "NoGripper",
    "NotModbusError",
    "OnRobot2FG7Gripper",
    "PollPolicy",
    "Poller",
    "Pose",
    "ProfileMismatchError",
    "ProjectPausedError",
    "ProjectState",
    "RegisterField",
    "RegisterGripper",
    "RegisterMap",
    "RegisterMapError",
    "ResponseTimeoutError",
    "RetryPolicy",
    "Robot",
    "RobotError",
    "RobotFaultError",
    "RobotIO",
    "RobotModel",
    "RobotProfile",
    "RobotStatus",
    "Role",
    "SequenceGripper",
    "StatusMonitor",
    "StopRequestedError",
    "TMErrorCode",
    "TMMasterError",
    "TMScriptError",
    "TMScriptRuntimeError",
    "TMScriptSyntaxError",
    "Table",
    "TimeoutPolicy",
    "Tool",
    "ToolMismatchError",
    "Transport",
    "TransportClosedError",
    "TransportError",
    "TransportStats",
    "UnitsError",
    "UnknownNameError",
    "UnreachablePoseError",
    "Value",
    "ValueOutOfRangeError",
    "WordOrder",
    "Workspace",
    "__version__",
    "allowed_range",
    "builtin_profile_names",
    "configure_logging",
    "connect",
    "decode",
    "encode",
    "gripper_profile",
    "load_profile",
    "lookup_tm_error",
    "profile_markdown",
    "robot_model",
    "robot_profile",
]

# Shown as tmmaster.Name where they are used (tracebacks, reprs, the docs), not as the
# private module that defines them.
for _name in __all__:
    _value = globals()[_name]
    if isinstance(_value, type | _FunctionType) and _value.__module__.startswith("tmmaster._"):
        _value.__module__ = __name__
del _name, _value
