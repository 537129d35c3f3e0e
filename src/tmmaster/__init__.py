"""tmmaster: drive a Techman (TM) robot arm and its gripper over Modbus TCP.

The same code runs against the built-in simulator (``python -m tmmaster.sim``) and
against a real robot: only the host changes. Everything public is importable from
here; modules starting with an underscore are private.
"""

from __future__ import annotations

from importlib import metadata as _metadata

from ._codec import Value, allowed_range, decode, encode
from ._exceptions import (
    AcknowledgeTimeoutError,
    CommandRejectedError,
    CommandStateUnknownError,
    ConfigError,
    ConnectError,
    ConnectionLostError,
    DeviceBusyError,
    DeviceFailureError,
    EmergencyStopError,
    GraspFailedError,
    GripperError,
    GripperTimeoutError,
    IllegalAddressError,
    IllegalFunctionError,
    IllegalValueError,
    ModbusExceptionError,
    MotionTimeoutError,
    RegisterMapError,
    ResponseTimeoutError,
    RobotError,
    RobotFaultError,
    StopRequestedError,
    TMMasterError,
    TransportError,
    ValueOutOfRangeError,
)
from ._gripper import (
    Blog2FG7Gripper,
    Gripper,
    GripperStatus,
    NoGripper,
    OnRobot2FG7Gripper,
    RegisterGripper,
    SequenceGripper,
)
from ._logging import configure_logging
from ._poller import Poller, PollPolicy
from ._pose import MotionType, Pose
from ._profiles import (
    builtin_profile_names,
    gripper_profile,
    load_profile,
    profile_markdown,
    robot_profile,
)
from ._registers import (
    Access,
    DataType,
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
from ._robot_models import ROBOT_MODELS, RobotModel, robot_model
from ._status import MovePhase, MoveProgress, RobotStatus
from ._transport import ConnectionState, ModbusTransport, Transport, TransportStats

try:
    __version__ = _metadata.version("tmmaster")
except _metadata.PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0.0.0"

__all__ = [
    "ROBOT_MODELS",
    "Access",
    "AcknowledgeTimeoutError",
    "Blog2FG7Gripper",
    "CommandRejectedError",
    "CommandStateUnknownError",
    "ConfigError",
    "ConnectError",
    "ConnectionLostError",
    "ConnectionState",
    "DataType",
    "DeviceBusyError",
    "DeviceFailureError",
    "EmergencyStopError",
    "GraspFailedError",
    "Gripper",
    "GripperError",
    "GripperProfile",
    "GripperStatus",
    "GripperTimeoutError",
    "Handshake",
    "IllegalAddressError",
    "IllegalFunctionError",
    "IllegalValueError",
    "ModbusExceptionError",
    "ModbusTransport",
    "Motion",
    "MotionTimeoutError",
    "MotionType",
    "MovePhase",
    "MoveProgress",
    "NoGripper",
    "OnRobot2FG7Gripper",
    "PollPolicy",
    "Poller",
    "Pose",
    "RegisterField",
    "RegisterGripper",
    "RegisterMap",
    "RegisterMapError",
    "ResponseTimeoutError",
    "RetryPolicy",
    "Robot",
    "RobotError",
    "RobotFaultError",
    "RobotModel",
    "RobotProfile",
    "RobotStatus",
    "Role",
    "SequenceGripper",
    "StopRequestedError",
    "TMMasterError",
    "Table",
    "TimeoutPolicy",
    "Transport",
    "TransportError",
    "TransportStats",
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
    "profile_markdown",
    "robot_model",
    "robot_profile",
]
