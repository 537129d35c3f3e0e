"""tmmaster: drive a Techman (TM) robot arm and its gripper over Modbus TCP.

The same code runs against the built-in simulator (``python -m tmmaster.sim``) and
against a real robot: only the host changes. Everything public is importable from
here; modules starting with an underscore are private. Names are imported on first
use, so ``import tmmaster`` stays cheap.
"""

from __future__ import annotations

# isort: off
# First: under ``python -m tmmaster.<command>`` a Ctrl-C while the package loads exits
# 130 in one line (a library user's program is left alone, see _sigint).
from . import _sigint as _sigint
# isort: on

from typing import TYPE_CHECKING as _TYPE_CHECKING

from ._lazy import lazy_attributes as _lazy_attributes
from ._version import version as _version_of_package

if _TYPE_CHECKING:
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
        UnreachablePoseError,
        ValueOutOfRangeError,
    )
    from ._fleet import Fleet
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
    from ._logging import configure_logging
    from ._monitor import MonitoredStatus, StatusMonitor
    from ._poller import Poller, PollPolicy
    from ._pose import DEFAULT_HOME, MotionType, Pose
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
    from ._status import MovePhase, MoveProgress, RobotStatus
    from ._transport import ConnectionState, ModbusTransport, Transport, TransportStats

#: Public name -> the private module that defines it.
_EXPORTS = {
    "Access": "._registers",
    "AcknowledgeTimeoutError": "._exceptions",
    "Blog2FG7Gripper": "._gripper",
    "CommandRejectedError": "._exceptions",
    "CommandStateUnknownError": "._exceptions",
    "ConfigError": "._exceptions",
    "ConnectError": "._exceptions",
    "ConnectionLostError": "._exceptions",
    "ConnectionState": "._transport",
    "DEFAULT_HOME": "._pose",
    "DEFAULT_PROFILE": "._profiles",
    "DataType": "._registers",
    "DeviceBusyError": "._exceptions",
    "DeviceFailureError": "._exceptions",
    "EmergencyStopError": "._exceptions",
    "Fleet": "._fleet",
    "GraspFailedError": "._exceptions",
    "Gripper": "._gripper",
    "GripperError": "._exceptions",
    "GripperProfile": "._registers",
    "GripperLink": "._gripper",
    "GripperMount": "._gripper",
    "GripperStatus": "._gripper",
    "GripperTimeoutError": "._exceptions",
    "Handshake": "._registers",
    "IllegalAddressError": "._exceptions",
    "IllegalFunctionError": "._exceptions",
    "IllegalValueError": "._exceptions",
    "ModbusExceptionError": "._exceptions",
    "ModbusTransport": "._transport",
    "MonitoredStatus": "._monitor",
    "JointSpec": "._robot_models",
    "Motion": "._robot",
    "MotionTimeoutError": "._exceptions",
    "MotionType": "._pose",
    "MovePhase": "._status",
    "MoveProgress": "._status",
    "NoGripper": "._gripper",
    "OnRobot2FG7Gripper": "._gripper",
    "PollPolicy": "._poller",
    "Poller": "._poller",
    "Pose": "._pose",
    "ROBOT_MODELS": "._robot_models",
    "RegisterField": "._registers",
    "RegisterGripper": "._gripper",
    "RegisterMap": "._registers",
    "RegisterMapError": "._exceptions",
    "ResponseTimeoutError": "._exceptions",
    "RetryPolicy": "._retry",
    "Robot": "._robot",
    "RobotError": "._exceptions",
    "RobotFaultError": "._exceptions",
    "RobotModel": "._robot_models",
    "RobotProfile": "._registers",
    "RobotStatus": "._status",
    "Role": "._registers",
    "SequenceGripper": "._gripper",
    "StatusMonitor": "._monitor",
    "StopRequestedError": "._exceptions",
    "TMMasterError": "._exceptions",
    "Table": "._registers",
    "TimeoutPolicy": "._robot",
    "Transport": "._transport",
    "TransportError": "._exceptions",
    "TransportStats": "._transport",
    "UnreachablePoseError": "._exceptions",
    "Value": "._codec",
    "ValueOutOfRangeError": "._exceptions",
    "WordOrder": "._registers",
    "Workspace": "._robot",
    "allowed_range": "._codec",
    "builtin_profile_names": "._profiles",
    "configure_logging": "._logging",
    "connect": "._robot",
    "decode": "._codec",
    "encode": "._codec",
    "gripper_profile": "._profiles",
    "load_profile": "._profiles",
    "profile_markdown": "._profiles",
    "robot_model": "._robot_models",
    "robot_profile": "._profiles",
}


__getattr__, __dir__ = _lazy_attributes(
    __name__, globals(), _EXPORTS, computed={"__version__": _version_of_package}
)

__all__ = [
    "DEFAULT_HOME",
    "DEFAULT_PROFILE",
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
    "Fleet",
    "GraspFailedError",
    "Gripper",
    "GripperError",
    "GripperLink",
    "GripperMount",
    "GripperProfile",
    "GripperStatus",
    "GripperTimeoutError",
    "Handshake",
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
    "StatusMonitor",
    "StopRequestedError",
    "TMMasterError",
    "Table",
    "TimeoutPolicy",
    "Transport",
    "TransportError",
    "TransportStats",
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
    "profile_markdown",
    "robot_model",
    "robot_profile",
]
