"""The tmmaster simulator: a TM robot (and gripper) served over Modbus TCP, in-process.

Like python-can's virtual bus, the simulator is part of the library: the same master
code runs against it and against a real robot. Start one with
``with Simulator() as sim:`` (a free loopback port) or ``python -m tmmaster.sim``;
``Simulator(listen=False)`` opens no socket and is reached in-process at ``sim.url``
(``Robot(sim.url)``, or ``Robot(..., transport=MemoryTransport(sim))``).
"""

from __future__ import annotations

from ._backend import GripperState, ObjectState, PhysicsBackend
from ._controller import MotionRecord
from ._faults import (
    FAULT_KINDS,
    DropConnectionsFault,
    EstopFault,
    Fault,
    GraspMissFault,
    LateAckFault,
    ModbusExceptionFault,
    RobotErrorFault,
    SlowResponsesFault,
    StallFault,
    StopListeningFault,
    is_network_fault,
    parse_fault,
)
from ._kinematic import DEFAULT_HOME, KinematicBackend
from ._memory import MemoryTransport
from ._server import RequestRecord
from ._simulator import Simulator
from ._world import DEFAULT_PART_POSE, TableObject, World

__all__ = [
    "DEFAULT_HOME",
    "DEFAULT_PART_POSE",
    "FAULT_KINDS",
    "DropConnectionsFault",
    "EstopFault",
    "Fault",
    "GraspMissFault",
    "GripperState",
    "KinematicBackend",
    "LateAckFault",
    "MemoryTransport",
    "ModbusExceptionFault",
    "MotionRecord",
    "ObjectState",
    "PhysicsBackend",
    "RequestRecord",
    "RobotErrorFault",
    "Simulator",
    "SlowResponsesFault",
    "StallFault",
    "StopListeningFault",
    "TableObject",
    "World",
    "is_network_fault",
    "parse_fault",
]
