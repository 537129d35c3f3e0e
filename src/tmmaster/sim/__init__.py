"""The tmmaster simulator: a TM robot (and gripper) served over Modbus TCP, in-process.

Like python-can's virtual bus, the simulator is part of the library: the same master
code runs against it and against a real robot. Start one with
``with Simulator() as sim:`` (a free loopback port) or ``python -m tmmaster.sim``;
``Simulator(listen=False)`` opens no socket and is reached in-process at ``sim.url``
(``Robot(sim.url)``, or ``Robot(..., transport=MemoryTransport(sim))``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING as _TYPE_CHECKING
from typing import Any as _Any

from .._address import register_scheme as _register_scheme
from .._lazy import lazy_attributes as _lazy_attributes

if _TYPE_CHECKING:
    from .._pose import DEFAULT_HOME
    from .._transport import Transport as _Transport
    from ._backend import (
        BackendFault,
        GripperState,
        MotionRejectedError,
        ObjectState,
        PathBackend,
        PhysicsBackend,
        PhysicsUnavailableError,
    )
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
    from ._kinematic import KinematicBackend
    from ._memory import MemoryTransport
    from ._scene import Scene, SceneTable, load_scene
    from ._server import RequestRecord
    from ._simulator import Simulator
    from ._world import (
        DEFAULT_GRIPPER,
        DEFAULT_PART_POSE,
        Fixture,
        GraspFit,
        GraspMode,
        GripperGeometry,
        TableObject,
        World,
    )

#: Public name -> the private module that defines it (imported on first use).
_EXPORTS = {
    "BackendFault": "._backend",
    "DEFAULT_GRIPPER": "._world",
    "DEFAULT_HOME": "tmmaster._pose",
    "DEFAULT_PART_POSE": "._world",
    "DropConnectionsFault": "._faults",
    "EstopFault": "._faults",
    "FAULT_KINDS": "._faults",
    "Fault": "._faults",
    "Fixture": "._world",
    "GraspFit": "._world",
    "GraspMissFault": "._faults",
    "GraspMode": "._world",
    "GripperGeometry": "._world",
    "GripperState": "._backend",
    "KinematicBackend": "._kinematic",
    "LateAckFault": "._faults",
    "MemoryTransport": "._memory",
    "MotionRejectedError": "._backend",
    "ModbusExceptionFault": "._faults",
    "MotionRecord": "._controller",
    "ObjectState": "._backend",
    "PathBackend": "._backend",
    "PhysicsBackend": "._backend",
    "PhysicsUnavailableError": "._backend",
    "RequestRecord": "._server",
    "RobotErrorFault": "._faults",
    "Scene": "._scene",
    "SceneTable": "._scene",
    "Simulator": "._simulator",
    "SlowResponsesFault": "._faults",
    "StallFault": "._faults",
    "StopListeningFault": "._faults",
    "TableObject": "._world",
    "World": "._world",
    "is_network_fault": "._faults",
    "load_scene": "._scene",
    "parse_fault": "._faults",
}

__getattr__, __dir__ = _lazy_attributes(__name__, globals(), _EXPORTS)


def _open_sim_url(url: str, **options: _Any) -> _Transport:
    """Open ``sim://name``: the running simulator of that name (ConnectError: none runs)."""
    # Imported here: ``import tmmaster.sim`` stays cheap; a started simulator loaded it.
    from ._memory import open_endpoint

    return open_endpoint(url, **options)


# The simulator is a plugin of the core: the core serves sim:// through this opener.
_register_scheme("sim", _open_sim_url)

__all__ = [
    "DEFAULT_GRIPPER",
    "DEFAULT_HOME",
    "DEFAULT_PART_POSE",
    "FAULT_KINDS",
    "BackendFault",
    "DropConnectionsFault",
    "EstopFault",
    "Fault",
    "Fixture",
    "GraspFit",
    "GraspMissFault",
    "GraspMode",
    "GripperGeometry",
    "GripperState",
    "KinematicBackend",
    "LateAckFault",
    "MemoryTransport",
    "ModbusExceptionFault",
    "MotionRecord",
    "MotionRejectedError",
    "ObjectState",
    "PathBackend",
    "PhysicsBackend",
    "PhysicsUnavailableError",
    "RequestRecord",
    "RobotErrorFault",
    "Scene",
    "SceneTable",
    "Simulator",
    "SlowResponsesFault",
    "StallFault",
    "StopListeningFault",
    "TableObject",
    "World",
    "is_network_fault",
    "load_scene",
    "parse_fault",
]
